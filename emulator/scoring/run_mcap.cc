#include "emulator/scoring/run_mcap.h"

#include <zlib.h>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdint>
#include <fstream>
#include <map>
#include <stdexcept>
#include <vector>

#include "bus/candump_log.h"

namespace wheelhil::emulator::scoring {
namespace {

using nlohmann::json;

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

std::int64_t Ns(double seconds) { return std::llround(seconds * 1e9); }

}  // namespace

void WriteRunMcap(const std::string& path, const RunRecord& run, const ReplayRobot& robot) {
  McapFile mcap;
  // Times since the motion start on can.log's clock.
  auto at = [&](double motion_s) { return run.motion0_ns + Ns(motion_s); };

  const std::uint16_t can_channel = mcap.Channel("/can", "wheelhil.CanFrame", CanSchema());
  for (const bus::CandumpRecord& r : run.bus_log) {
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

  const std::uint16_t truth_pose =
      mcap.Channel("/truth/pose", "foxglove.PoseInFrame", PoseSchema());
  const std::uint16_t truth_vel =
      mcap.Channel("/truth/velocity", "wheelhil.BodyVelocity", VelocitySchema());
  const std::uint16_t wheels = mcap.Channel("/truth/wheels", "wheelhil.WheelStates", WheelSchema());
  const auto& rows = run.truth.rows();
  const auto& states = run.truth.wheel_states();
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const TruthRow& r = rows[i];
    const std::int64_t t = at(r.t_s);
    mcap.Message(truth_pose, t, Pose(t, r.x_m, r.y_m, r.z_m, r.theta_rad));
    mcap.Message(truth_vel, t,
                 {{"timestamp", Stamp(t)},
                  {"vx_m_s", r.vx_m_s},
                  {"vy_m_s", r.vy_m_s},
                  {"omega_rad_s", r.omega_rad_s}});
    json list = json::array();
    for (std::size_t w = 0; w < states[i].size(); ++w) {
      const WheelState& st = states[i][w];
      list.push_back({{"name", w < robot.wheels.size() ? robot.wheels[w].name : std::to_string(w)},
                      {"omega_rad_s", st.omega_rad_s},
                      {"slip_speed_m_s", st.slip_speed_m_s},
                      {"normal_load_n", st.normal_load_n},
                      {"motor_torque_nm", st.motor_torque_nm},
                      {"in_contact", st.in_contact},
                      {"slipping", st.slipping}});
    }
    mcap.Message(wheels, t, {{"timestamp", Stamp(t)}, {"wheels", list}});
  }

  // The firmware's scored streams (from the motion start on).
  for (const auto& [stream, samples] : run.estimates.pose_streams()) {
    const std::uint16_t c =
        mcap.Channel("/estimate/" + stream + "/pose", "foxglove.PoseInFrame", PoseSchema());
    for (const PoseSample& p : samples) {
      mcap.Message(c, at(p.t_s), Pose(at(p.t_s), p.x_m, p.y_m, 0.0, p.theta_rad));
    }
  }
  for (const auto& [stream, samples] : run.estimates.velocity_streams()) {
    const std::uint16_t c = mcap.Channel("/estimate/" + stream + "/velocity",
                                         "wheelhil.BodyVelocity", VelocitySchema());
    for (const VelocitySample& v : samples) {
      const std::int64_t t = at(v.t_s);
      mcap.Message(c, t,
                   {{"timestamp", Stamp(t)},
                    {"vx_m_s", v.vx_m_s},
                    {"vy_m_s", v.vy_m_s},
                    {"omega_rad_s", v.omega_rad_s}});
    }
  }

  const std::uint16_t slip = mcap.Channel("/slip", "wheelhil.SlipInterval", SlipSchema());
  const std::uint16_t log = mcap.Channel("/events", "foxglove.Log", LogSchema());
  // Events before motion_start count their t_s from the run's start (sim::RunContext::
  // MotionSeconds).
  bool in_motion = false;
  for (const json& e : run.events) {
    const std::string kind = e.value("event", "");
    if (kind == "motion_start") in_motion = true;
    const double t_s = e.contains("t_s") && e["t_s"].is_number() ? e["t_s"].get<double>() : 0.0;
    const std::int64_t t = in_motion ? at(t_s) : Ns(t_s);
    if (kind == "slip" && e.contains("start_s") && e.contains("end_s")) {
      const double start = e["start_s"].get<double>(), end = e["end_s"].get<double>();
      mcap.Message(slip, t,
                   {{"timestamp", Stamp(t)},
                    {"start_s", start},
                    {"end_s", end},
                    {"duration_s", end - start}});
    }
    const int level = kind == "failure" ? 4 : 2;  // foxglove.Log: ERROR, INFO
    mcap.Message(log, t,
                 {{"timestamp", Stamp(t)},
                  {"level", level},
                  {"message", e.dump()},
                  {"name", "wheelhil"},
                  {"file", "events.jsonl"},
                  {"line", 0}});
  }

  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << mcap.Finish();
  if (!out.flush()) throw std::runtime_error(path + ": cannot be written");
}

}  // namespace wheelhil::emulator::scoring
