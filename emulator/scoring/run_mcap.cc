#include "emulator/scoring/run_mcap.h"

#include <zlib.h>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "bus/candump_log.h"

namespace wheelhil::emulator::scoring {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

// ---- MCAP records (https://mcap.dev/spec): little-endian, strings as u32 length + bytes ----

constexpr char kMagic[] = "\x89MCAP0\r\n";
enum Op : std::uint8_t {
  kHeader = 0x01,
  kFooter = 0x02,
  kSchema = 0x03,
  kChannel = 0x04,
  kMessage = 0x05,
  kDataEnd = 0x0F
};

void Put16(std::string& b, std::uint16_t v) { b.append(reinterpret_cast<const char*>(&v), 2); }
void Put32(std::string& b, std::uint32_t v) { b.append(reinterpret_cast<const char*>(&v), 4); }
void Put64(std::string& b, std::uint64_t v) { b.append(reinterpret_cast<const char*>(&v), 8); }
void PutString(std::string& b, const std::string& s) {
  Put32(b, static_cast<std::uint32_t>(s.size()));
  b += s;
}

class McapFile {
 public:
  McapFile() {
    out_.append(kMagic, 8);
    std::string h;
    PutString(h, "");  // no profile: plain JSON messages
    PutString(h, "wheelhil");
    Record(kHeader, h);
  }

  // A channel on `topic` with `schema` (a JSON Schema), made at its first use; its id.
  std::uint16_t Channel(const std::string& topic, const std::string& schema_name,
                        const json& schema) {
    const auto it = channels_.find(topic);
    if (it != channels_.end()) return it->second;
    std::uint16_t schema_id = 0;
    if (const auto s = schemas_.find(schema_name); s != schemas_.end()) {
      schema_id = s->second;
    } else {
      schema_id = static_cast<std::uint16_t>(schemas_.size() + 1);
      schemas_[schema_name] = schema_id;
      std::string r;
      Put16(r, schema_id);
      PutString(r, schema_name);
      PutString(r, "jsonschema");
      PutString(r, schema.dump());
      Record(kSchema, r);
    }
    const auto id = static_cast<std::uint16_t>(channels_.size() + 1);
    channels_[topic] = id;
    std::string r;
    Put16(r, id);
    Put16(r, schema_id);
    PutString(r, topic);
    PutString(r, "json");
    Put32(r, 0);  // no metadata
    Record(kChannel, r);
    return id;
  }

  void Message(std::uint16_t channel, std::int64_t t_ns, const json& message) {
    std::string r;
    Put16(r, channel);
    Put32(r, sequence_[channel]++);
    const auto t = static_cast<std::uint64_t>(std::max<std::int64_t>(0, t_ns));
    Put64(r, t);
    Put64(r, t);
    r += message.dump();
    Record(kMessage, r);
  }

  std::string Finish() {
    const auto crc = static_cast<std::uint32_t>(
        ::crc32(0L, reinterpret_cast<const Bytef*>(out_.data()), static_cast<uInt>(out_.size())));
    std::string d;
    Put32(d, crc);
    Record(kDataEnd, d);
    std::string f;
    Put64(f, 0);  // no summary section
    Put64(f, 0);
    Put32(f, 0);
    Record(kFooter, f);
    out_.append(kMagic, 8);
    return std::move(out_);
  }

 private:
  void Record(Op op, const std::string& content) {
    out_.push_back(static_cast<char>(op));
    Put64(out_, content.size());
    out_ += content;
  }

  std::string out_;
  std::map<std::string, std::uint16_t> schemas_;
  std::map<std::string, std::uint16_t> channels_;
  std::map<std::uint16_t, std::uint32_t> sequence_;
};

// ---- schemas ----

json Number() { return {{"type", "number"}}; }
json Time() {
  return {{"type", "object"},
          {"properties", {{"sec", {{"type", "integer"}}}, {"nsec", {{"type", "integer"}}}}}};
}
json Object(json properties) { return {{"type", "object"}, {"properties", std::move(properties)}}; }

const json& PoseSchema() {  // foxglove.PoseInFrame
  static const json s = Object(
      {{"timestamp", Time()},
       {"frame_id", {{"type", "string"}}},
       {"pose",
        Object({{"position", Object({{"x", Number()}, {"y", Number()}, {"z", Number()}})},
                {"orientation",
                 Object({{"x", Number()}, {"y", Number()}, {"z", Number()}, {"w", Number()}})}})}});
  return s;
}
const json& VelocitySchema() {
  static const json s = Object({{"timestamp", Time()},
                                {"vx_m_s", Number()},
                                {"vy_m_s", Number()},
                                {"omega_rad_s", Number()}});
  return s;
}
const json& LogSchema() {  // foxglove.Log
  static const json s = Object({{"timestamp", Time()},
                                {"level", {{"type", "integer"}}},
                                {"message", {{"type", "string"}}},
                                {"name", {{"type", "string"}}},
                                {"file", {{"type", "string"}}},
                                {"line", {{"type", "integer"}}}});
  return s;
}
const json& CanSchema() {
  static const json s = Object({{"timestamp", Time()},
                                {"interface", {{"type", "string"}}},
                                {"id", {{"type", "integer"}}},
                                {"extended", {{"type", "boolean"}}},
                                {"remote", {{"type", "boolean"}}},
                                {"fd", {{"type", "boolean"}}},
                                {"brs", {{"type", "boolean"}}},
                                {"esi", {{"type", "boolean"}}},
                                {"error", {{"type", "boolean"}}},
                                {"length", {{"type", "integer"}}},
                                {"data", {{"type", "string"}, {"description", "hex"}}}});
  return s;
}
const json& WheelSchema() {
  static const json wheel = Object({{"name", {{"type", "string"}}},
                                    {"omega_rad_s", Number()},
                                    {"slip_speed_m_s", Number()},
                                    {"normal_load_n", Number()},
                                    {"motor_torque_nm", Number()},
                                    {"in_contact", {{"type", "boolean"}}},
                                    {"slipping", {{"type", "boolean"}}}});
  static const json s =
      Object({{"timestamp", Time()}, {"wheels", {{"type", "array"}, {"items", wheel}}}});
  return s;
}
const json& SlipSchema() {
  static const json s = Object({{"timestamp", Time()},
                                {"start_s", Number()},
                                {"end_s", Number()},
                                {"duration_s", Number()}});
  return s;
}

json Stamp(std::int64_t ns) {
  ns = std::max<std::int64_t>(0, ns);
  return {{"sec", ns / 1'000'000'000}, {"nsec", ns % 1'000'000'000}};
}

json Pose(std::int64_t ns, double x, double y, double z, double yaw) {
  return {{"timestamp", Stamp(ns)},
          {"frame_id", "world"},
          {"pose",
           {{"position", {{"x", x}, {"y", y}, {"z", z}}},
            {"orientation",
             {{"x", 0.0}, {"y", 0.0}, {"z", std::sin(yaw / 2)}, {"w", std::cos(yaw / 2)}}}}}};
}

// ---- the artefacts ----

std::vector<std::vector<std::string>> ReadCsv(const fs::path& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path.string() + ": cannot be read");
  std::vector<std::vector<std::string>> rows;
  std::string line;
  std::getline(in, line);  // the header
  while (std::getline(in, line)) {
    std::vector<std::string> cells;
    std::stringstream s(line);
    for (std::string c; std::getline(s, c, ',');) cells.push_back(c);
    rows.push_back(std::move(cells));
  }
  return rows;
}

std::int64_t Ns(double seconds) { return std::llround(seconds * 1e9); }

}  // namespace

void WriteRunMcap(const std::string& out_dir, const ReplayRobot& robot,
                  const TruthRecorder& truth) {
  const fs::path dir(out_dir);
  McapFile mcap;
  // The motion's t = 0 on can.log's clock.
  std::int64_t motion_ns = 0;
  std::vector<json> events;
  {
    std::ifstream in(dir / "events.jsonl");
    if (!in) throw std::runtime_error((dir / "events.jsonl").string() + ": cannot be read");
    for (std::string line; std::getline(in, line);) {
      json e = json::parse(line, nullptr, false);
      if (e.is_discarded()) continue;
      if (e.value("event", "") == "motion_start" && e.contains("bus_time_s")) {
        motion_ns = Ns(e["bus_time_s"].get<double>());
      }
      events.push_back(std::move(e));
    }
  }
  auto at = [&](double motion_s) { return motion_ns + Ns(motion_s); };

  const bus::CandumpLog can = bus::LoadCandumpFile((dir / "can.log").string());
  const std::uint16_t can_channel = mcap.Channel("/can", "wheelhil.CanFrame", CanSchema());
  for (const bus::CandumpRecord& r : can.records) {
    std::string hex;
    for (const std::uint8_t b : r.frame.payload()) hex += fmt::format("{:02X}", b);
    mcap.Message(can_channel, r.timestamp_ns,
                 {{"timestamp", Stamp(r.timestamp_ns)},
                  {"interface", r.interface},
                  {"id", r.frame.id},
                  {"extended", r.frame.extended},
                  {"remote", r.frame.rtr},
                  {"fd", r.frame.fd},
                  {"brs", (r.frame.fd_flags & 0x01) != 0},
                  {"esi", (r.frame.fd_flags & 0x02) != 0},
                  {"error", r.frame.error},
                  {"length", r.frame.len},
                  {"data", hex}});
  }

  // truth.csv: t_s,x_m,y_m,z_m,theta_rad,vx_m_s,vy_m_s,omega_rad_s,slipping_wheels
  const std::uint16_t truth_pose =
      mcap.Channel("/truth/pose", "foxglove.PoseInFrame", PoseSchema());
  const std::uint16_t truth_vel =
      mcap.Channel("/truth/velocity", "wheelhil.BodyVelocity", VelocitySchema());
  const std::uint16_t wheels = mcap.Channel("/truth/wheels", "wheelhil.WheelStates", WheelSchema());
  const auto& states = truth.wheel_states();
  std::size_t row = 0;
  for (const auto& c : ReadCsv(dir / "truth.csv")) {
    if (c.size() < 9) continue;
    const std::int64_t t = at(std::stod(c[0]));
    mcap.Message(truth_pose, t,
                 Pose(t, std::stod(c[1]), std::stod(c[2]), std::stod(c[3]), std::stod(c[4])));
    mcap.Message(truth_vel, t,
                 {{"timestamp", Stamp(t)},
                  {"vx_m_s", std::stod(c[5])},
                  {"vy_m_s", std::stod(c[6])},
                  {"omega_rad_s", std::stod(c[7])}});
    if (row < states.size()) {
      json list = json::array();
      for (std::size_t w = 0; w < states[row].size(); ++w) {
        const WheelState& st = states[row][w];
        list.push_back(
            {{"name", w < robot.wheels.size() ? robot.wheels[w].name : std::to_string(w)},
             {"omega_rad_s", st.omega_rad_s},
             {"slip_speed_m_s", st.slip_speed_m_s},
             {"normal_load_n", st.normal_load_n},
             {"motor_torque_nm", st.motor_torque_nm},
             {"in_contact", st.in_contact},
             {"slipping", st.slipping}});
      }
      mcap.Message(wheels, t, {{"timestamp", Stamp(t)}, {"wheels", list}});
    }
    ++row;
  }

  // estimate.csv: t_s,cycle,stream,<x or vx>,<y or vy>,<theta or omega>; pose streams are the
  // ones with an estimate_<stream>.tum.
  for (const auto& c : ReadCsv(dir / "estimate.csv")) {
    if (c.size() < 6) continue;
    const double t_s = std::stod(c[0]);
    if (t_s < 0) continue;  // before the motion: not scored
    const std::int64_t t = at(t_s);
    const std::string& stream = c[2];
    const bool pose = fs::exists(dir / ("estimate_" + stream + ".tum"));
    const double a = std::stod(c[3]), b = std::stod(c[4]), h = std::stod(c[5]);
    if (pose) {
      mcap.Message(
          mcap.Channel("/estimate/" + stream + "/pose", "foxglove.PoseInFrame", PoseSchema()), t,
          Pose(t, a, b, 0.0, h));
    } else {
      mcap.Message(mcap.Channel("/estimate/" + stream + "/velocity", "wheelhil.BodyVelocity",
                                VelocitySchema()),
                   t, {{"timestamp", Stamp(t)}, {"vx_m_s", a}, {"vy_m_s", b}, {"omega_rad_s", h}});
    }
  }

  const std::uint16_t slip = mcap.Channel("/slip", "wheelhil.SlipInterval", SlipSchema());
  const std::uint16_t log = mcap.Channel("/events", "foxglove.Log", LogSchema());
  // Events before motion_start count their t_s from the run's start (scoring::MotionSeconds).
  bool in_motion = false;
  for (const json& e : events) {
    if (e.value("event", "") == "motion_start") in_motion = true;
    const double t_s = e.contains("t_s") && e["t_s"].is_number() ? e["t_s"].get<double>() : 0.0;
    const std::int64_t t = in_motion ? at(t_s) : Ns(t_s);
    if (e.value("event", "") == "slip" && e.contains("start_s") && e.contains("end_s")) {
      const double start = e["start_s"].get<double>(), end = e["end_s"].get<double>();
      mcap.Message(slip, t,
                   {{"timestamp", Stamp(t)},
                    {"start_s", start},
                    {"end_s", end},
                    {"duration_s", end - start}});
    }
    const std::string kind = e.value("event", "");
    const int level = kind == "failure" ? 4 : kind.find("warning") != std::string::npos ? 3 : 2;
    mcap.Message(log, t,
                 {{"timestamp", Stamp(t)},
                  {"level", level},
                  {"message", e.dump()},
                  {"name", "wheelhil"},
                  {"file", "events.jsonl"},
                  {"line", 0}});
  }

  const fs::path path = dir / "run.mcap";
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << mcap.Finish();
  if (!out.flush()) throw std::runtime_error(path.string() + ": cannot be written");
}

}  // namespace wheelhil::emulator::scoring
