#include "emulator/scenario/scenario.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <set>
#include <stdexcept>

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include "bus/dbc.h"
#include "bus/yaml_fields.h"
#include "emulator/scoring/metric_components.h"
#include "emulator/scoring/metrics.h"

namespace wheelhil::emulator::scenario {

namespace {

namespace fs = std::filesystem;

// Scenario fields; relative paths resolve against the scenario file's folder.
class Reader : public bus::yaml::FieldReader {
 public:
  explicit Reader(std::string file)
      : FieldReader(std::move(file)), base_dir_(fs::path(this->file()).parent_path()) {}

  std::string Path(const std::string& p) const {
    if (p.empty() || fs::path(p).is_absolute()) return p;
    return (base_dir_ / p).lexically_normal().string();
  }

 private:
  fs::path base_dir_;
};

Friction ReadFriction(const Reader& r, const YAML::Node& n, const std::string& field,
                      Friction def) {
  Friction f;
  f.mu_peak = r.Number(n, "mu_peak", field, 0, 10, def.mu_peak);
  f.mu_slide = r.Number(n, "mu_slide", field, 0, 10, std::min(def.mu_slide, f.mu_peak));
  if (f.mu_slide > f.mu_peak) {
    r.FailKey(n, "mu_slide", field + ".mu_slide", "must not exceed mu_peak");
  }
  return f;
}

std::vector<Eigen::Vector2d> ReadPolygon(const Reader& r, const YAML::Node& parent,
                                         const std::string& key, const std::string& prefix) {
  const std::string field = Reader::Join(prefix, key);
  const YAML::Node n = Reader::Get(parent, key);
  if (!n.IsSequence() || n.size() < 3) {
    r.FailKey(parent, key, field, "must be a list of >= 3 [x, y] points");
  }
  std::vector<Eigen::Vector2d> out;
  for (std::size_t i = 0; i < n.size(); ++i) {
    const YAML::Node p = n[i];
    const std::string f = fmt::format("{}[{}]", field, i);
    if (!p.IsSequence() || p.size() != 2) r.Fail(p, f, "must be [x, y]");
    out.emplace_back(r.ToNumber(p[0], f + "[0]"), r.ToNumber(p[1], f + "[1]"));
  }
  return out;
}

TerrainSpec ReadTerrain(const Reader& r, const YAML::Node& n) {
  TerrainSpec t;
  if (!n.IsDefined()) return t;
  r.CheckKeys(n, "terrain", {"friction", "meshes", "patches", "random_patches"});
  if (n["friction"]) t.friction = ReadFriction(r, n["friction"], "terrain.friction", Friction{});
  if (const auto m = n["meshes"]) {
    if (!m.IsSequence()) r.Fail(m, "terrain.meshes", "must be a list of files");
    for (std::size_t i = 0; i < m.size(); ++i) {
      const std::string p = r.Path(r.ToString(m[i], fmt::format("terrain.meshes[{}]", i)));
      if (!fs::exists(p)) r.Fail(m[i], fmt::format("terrain.meshes[{}]", i), p + " not found");
      t.meshes.push_back(p);
    }
  }
  if (const auto ps = n["patches"]) {
    if (!ps.IsSequence()) r.Fail(ps, "terrain.patches", "must be a list");
    for (std::size_t i = 0; i < ps.size(); ++i) {
      const std::string f = fmt::format("terrain.patches[{}]", i);
      r.CheckKeys(ps[i], f, {"name", "polygon_m", "mu_peak", "mu_slide"});
      PatchSpec p;
      p.name = r.String(ps[i], "name", f, fmt::format("patch{}", i));
      p.polygon_m = ReadPolygon(r, ps[i], "polygon_m", f);
      p.friction = ReadFriction(r, ps[i], f, Friction{0.1, 0.08});
      t.patches.push_back(std::move(p));
    }
  }
  if (const auto rp = n["random_patches"]) {
    const std::string f = "terrain.random_patches";
    r.CheckKeys(rp, f,
                {"count", "x_min_m", "x_max_m", "length_min_m", "length_max_m", "width_m",
                 "track_y_m", "mu_peak", "mu_slide", "placement"});
    auto& s = t.random_patches;
    s.count = static_cast<int>(r.Number(rp, "count", f, 0, 1000, std::nullopt));
    s.x_min_m = r.Number(rp, "x_min_m", f, -1e4, 1e4, std::nullopt);
    s.x_max_m = r.Number(rp, "x_max_m", f, s.x_min_m, 1e4, std::nullopt);
    s.length_min_m = r.Number(rp, "length_min_m", f, 1e-3, 100, 0.05);
    s.length_max_m = r.Number(rp, "length_max_m", f, s.length_min_m, 100, 0.2);
    s.width_m = r.Number(rp, "width_m", f, 1e-3, 10, 0.1);
    const YAML::Node ty = Reader::Get(rp, "track_y_m");
    if (!ty.IsDefined()) r.Fail(rp, f + ".track_y_m", "is required (a list of y)");
    if (!ty.IsSequence() || ty.size() == 0) r.Fail(ty, f + ".track_y_m", "must be a list of y");
    for (std::size_t i = 0; i < ty.size(); ++i) {
      s.track_y_m.push_back(r.ToNumber(ty[i], fmt::format("{}.track_y_m[{}]", f, i)));
    }
    s.friction = ReadFriction(r, rp, f, Friction{0.05, 0.03});
    const std::string placement = r.String(rp, "placement", f, "uniform");
    if (placement == "stratified") {
      s.placement = RandomPatchesSpec::Placement::kStratified;
      const double section = s.count > 0 ? (s.x_max_m - s.x_min_m) / s.count : 0.0;
      if (s.count > 0 && s.length_max_m > section) {
        r.FailKey(rp, "length_max_m", f + ".length_max_m",
                  fmt::format("({}) must be <= the section length (x_max_m - x_min_m) / count = {} "
                              "with placement: stratified",
                              s.length_max_m, section));
      }
    } else if (placement != "uniform") {
      r.Fail(rp["placement"], f + ".placement",
             fmt::format("must be uniform or stratified, not '{}'", placement));
    }
  }
  return t;
}

// Nominal planar pose (start frame: x forward, y left at the motion start) after `motion`, by
// integrating its commanded body twist at 1 ms with the midpoint heading. Segments of direct
// wheel speeds have no known path: returns false.
bool NominalPoseAfter(const std::vector<MotionSegment>& motion, Eigen::Vector3d* pose) {
  Eigen::Vector3d q = Eigen::Vector3d::Zero();
  for (const auto& m : motion) {
    if (m.kind == MotionSegment::Kind::kWheels) return false;
    if (m.kind == MotionSegment::Kind::kHold) continue;
    const std::vector<MotionSegment> one = {m};
    const int steps = std::max(1, static_cast<int>(std::ceil(m.duration_s / 1e-3)));
    const double dt = m.duration_s / steps;
    for (int k = 0; k < steps; ++k) {
      const platforms::BodyTwist v = TwistAt(one, (k + 0.5) * dt);
      const double mid = q.z() + 0.5 * v.wz_rad_s * dt;
      q.x() += (std::cos(mid) * v.vx_m_s - std::sin(mid) * v.vy_m_s) * dt;
      q.y() += (std::sin(mid) * v.vx_m_s + std::cos(mid) * v.vy_m_s) * dt;
      q.z() += v.wz_rad_s * dt;
    }
  }
  *pose = q;
  return true;
}

// A `waypoints` entry as trapezoid segments from the nominal pose after `before`: on a
// holonomic platform one straight segment per point (heading kept), on a differential drive a
// turn in place to face the point, then the straight.
void AppendWaypoints(const Reader& r, const YAML::Node& s, const std::string& f,
                     const platforms::Platform& platform, std::vector<MotionSegment>& out) {
  r.CheckKeys(s, f,
              {"type", "points_m", "speed", "accel", "turn_speed_rad_s", "turn_accel_rad_s2"});
  const double speed = r.Number(s, "speed", f, 1e-6, 50, std::nullopt);
  const double accel = r.Number(s, "accel", f, 1e-6, 1e3, std::nullopt);
  const double turn_speed = r.Number(s, "turn_speed_rad_s", f, 1e-6, 50, 0.5);
  const double turn_accel = r.Number(s, "turn_accel_rad_s2", f, 1e-6, 1e3, 1.0);
  const YAML::Node pts = Reader::Get(s, "points_m");
  if (!pts.IsSequence() || pts.size() == 0) {
    r.FailKey(s, "points_m", f + ".points_m", "must be a non-empty list of [x, y]");
  }
  Eigen::Vector3d pose;
  if (!NominalPoseAfter(out, &pose)) {
    r.Fail(s, f, "cannot follow a `wheels` segment (its path is not known in advance)");
  }
  const bool holonomic = platform.kinematics != platforms::KinematicsKind::kDiffDrive;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    const YAML::Node pt = pts[i];
    const std::string pf = fmt::format("{}.points_m[{}]", f, i);
    Eigen::Vector2d target = Eigen::Vector2d::Zero();
    try {
      if (!pt.IsSequence() || pt.size() != 2) throw YAML::Exception(pt.Mark(), "");
      target = {pt[0].as<double>(), pt[1].as<double>()};
    } catch (const YAML::Exception&) {
      r.Fail(pt, pf, "must be [x, y] in metres (start frame: x forward, y left)");
    }
    if (!target.allFinite()) r.Fail(pt, pf, "must be finite");
    const Eigen::Vector2d d_W = target - pose.head<2>();
    const double dist = d_W.norm();
    if (dist < 1e-9) continue;  // already there
    MotionSegment m;
    m.kind = MotionSegment::Kind::kTrapezoid;
    if (holonomic) {
      const double c = std::cos(pose.z()), sn = std::sin(pose.z());
      m.direction = Eigen::Vector3d(c * d_W.x() + sn * d_W.y(), -sn * d_W.x() + c * d_W.y(), 0);
    } else {
      const double turn = scoring::WrapAngle(std::atan2(d_W.y(), d_W.x()) - pose.z());
      if (std::abs(turn) > 1e-9) {
        MotionSegment t;
        t.kind = MotionSegment::Kind::kTrapezoid;
        t.direction = Eigen::Vector3d(0, 0, turn > 0 ? 1.0 : -1.0);
        t.distance = std::abs(turn);
        t.speed = turn_speed;
        t.accel = turn_accel;
        t.duration_s = TrapezoidDuration(t.distance, t.speed, t.accel);
        out.push_back(t);
        pose.z() += turn;
      }
      m.direction = Eigen::Vector3d::UnitX();
    }
    m.direction.normalize();
    m.distance = dist;
    m.speed = speed;
    m.accel = accel;
    m.duration_s = TrapezoidDuration(m.distance, m.speed, m.accel);
    out.push_back(m);
    pose.head<2>() = target;
  }
}

std::vector<MotionSegment> ReadMotion(const Reader& r, const YAML::Node& root,
                                      const platforms::Platform& platform) {
  const YAML::Node n = Reader::Get(root, "motion");
  if (!n.IsSequence() || n.size() == 0) {
    r.FailKey(root, "motion", "motion", "must be a non-empty list of segments");
  }
  std::vector<MotionSegment> out;
  for (std::size_t i = 0; i < n.size(); ++i) {
    const YAML::Node s = n[i];
    const std::string f = fmt::format("motion[{}]", i);
    const std::string type = r.String(s, "type", f, std::nullopt);
    if (type == "waypoints") {
      AppendWaypoints(r, s, f, platform, out);
      continue;
    }
    const std::size_t wheels = platform.vehicle.wheels.size();
    MotionSegment m;
    if (type == "twist") {
      r.CheckKeys(s, f, {"type", "duration_s", "vx_m_s", "vy_m_s", "wz_rad_s"});
      m.kind = MotionSegment::Kind::kTwist;
      m.duration_s = r.Number(s, "duration_s", f, 0, 1e6, std::nullopt);
      m.twist.vx_m_s = r.Number(s, "vx_m_s", f, -20, 20, 0.0);
      m.twist.vy_m_s = r.Number(s, "vy_m_s", f, -20, 20, 0.0);
      m.twist.wz_rad_s = r.Number(s, "wz_rad_s", f, -50, 50, 0.0);
    } else if (type == "hold") {
      r.CheckKeys(s, f, {"type", "duration_s"});
      m.kind = MotionSegment::Kind::kHold;
      m.duration_s = r.Number(s, "duration_s", f, 0, 1e6, std::nullopt);
    } else if (type == "trapezoid") {
      r.CheckKeys(s, f, {"type", "direction", "distance", "speed", "accel"});
      m.kind = MotionSegment::Kind::kTrapezoid;
      const YAML::Node d = Reader::Get(s, "direction");
      if (!d.IsSequence() || d.size() != 3) {
        r.FailKey(s, "direction", f + ".direction", "must be [vx, vy, wz]");
      }
      for (int k = 0; k < 3; ++k) {
        m.direction[k] = r.ToNumber(d[k], fmt::format("{}.direction[{}]", f, k));
      }
      if (!(m.direction.norm() > 0)) r.Fail(d, f + ".direction", "must not be zero");
      m.direction.normalize();
      m.distance = r.Number(s, "distance", f, 0, 1e5, std::nullopt);
      m.speed = r.Number(s, "speed", f, 1e-6, 50, std::nullopt);
      m.accel = r.Number(s, "accel", f, 1e-6, 1e3, std::nullopt);
      m.duration_s = TrapezoidDuration(m.distance, m.speed, m.accel);
    } else if (type == "wheels") {
      r.CheckKeys(s, f, {"type", "duration_s", "omega_rad_s"});
      m.kind = MotionSegment::Kind::kWheels;
      m.duration_s = r.Number(s, "duration_s", f, 0, 1e6, std::nullopt);
      const YAML::Node w = Reader::Get(s, "omega_rad_s");
      if (!w.IsSequence() || w.size() != wheels) {
        r.FailKey(s, "omega_rad_s", f + ".omega_rad_s",
                  fmt::format("must list {} wheel speeds (platform wheel order)", wheels));
      }
      for (std::size_t k = 0; k < w.size(); ++k) {
        m.wheel_speeds_rad_s.push_back(r.ToNumber(w[k], fmt::format("{}.omega_rad_s[{}]", f, k)));
      }
    } else {
      r.Fail(s["type"], f + ".type",
             fmt::format("'{}' is not one of twist, trapezoid, hold, wheels, waypoints", type));
    }
    out.push_back(std::move(m));
  }
  return out;
}

// sensors.dbc_imu: the file, the bindings and the noise; the node itself checks the bindings
// against the DBC (unknown messages or signals, units, cycle times), reported at this entry.
DbcImuSpec ReadDbcImu(const Reader& r, const YAML::Node& n) {
  const std::string f = "sensors.dbc_imu";
  r.CheckKeys(n, f, {"dbc", "mount_m", "channels", "messages", "gyro", "accel"});
  DbcImuSpec d;
  d.where = r.Where(n);
  d.dbc = r.Path(r.String(n, "dbc", f, std::nullopt));
  if (const YAML::Node m = Reader::Get(n, "mount_m"); Reader::Present(m)) {
    if (!m.IsSequence() || m.size() != 3) r.Fail(m, f + ".mount_m", "must be [x, y, z] in m");
    for (std::size_t i = 0; i < 3; ++i) {
      d.mount_m[static_cast<int>(i)] =
          r.ToNumber(m[i], fmt::format("{}.mount_m[{}]", f, i), -10, 10);
    }
  }
  const YAML::Node ch = Reader::Get(n, "channels");
  if (!ch.IsSequence() || ch.size() == 0) {
    r.FailKey(n, "channels", f + ".channels", "must list at least one {quantity, message, signal}");
  }
  for (std::size_t i = 0; i < ch.size(); ++i) {
    const std::string cf = fmt::format("{}.channels[{}]", f, i);
    r.CheckKeys(ch[i], cf, {"quantity", "message", "signal"});
    DbcImuChannel c;
    const std::string q = r.String(ch[i], "quantity", cf, std::nullopt);
    const auto quantity = ParseImuQuantity(q);
    if (!quantity) {
      r.FailKey(ch[i], "quantity", cf + ".quantity",
                fmt::format("'{}' is not one of rate_x, rate_y, rate_z, accel_x, accel_y, accel_z",
                            q));
    }
    c.quantity = *quantity;
    c.message = r.String(ch[i], "message", cf, std::nullopt);
    c.signal = r.String(ch[i], "signal", cf, std::nullopt);
    d.node.channels.push_back(c);
  }
  if (const YAML::Node ms = Reader::Get(n, "messages"); Reader::Present(ms)) {
    if (!ms.IsSequence()) r.Fail(ms, f + ".messages", "must be a list");
    for (std::size_t i = 0; i < ms.size(); ++i) {
      const std::string mf = fmt::format("{}.messages[{}]", f, i);
      r.CheckKeys(ms[i], mf, {"message", "counter", "checksum", "checksum_kind"});
      DbcImuMessageOptions o;
      o.message = r.String(ms[i], "message", mf, std::nullopt);
      o.counter_signal = r.String(ms[i], "counter", mf, std::string());
      o.checksum_signal = r.String(ms[i], "checksum", mf, std::string());
      const std::string kind = r.String(ms[i], "checksum_kind", mf, std::string("xor"));
      const auto k = ParseChecksumKind(kind);
      if (!k) {
        r.FailKey(ms[i], "checksum_kind", mf + ".checksum_kind",
                  fmt::format("'{}' is not one of xor, sum, crc8_sae_j1850", kind));
      }
      o.checksum = *k;
      d.node.message_options.push_back(o);
    }
  }
  if (const YAML::Node g = Reader::Get(n, "gyro"); Reader::Present(g)) {
    const std::string gf = f + ".gyro";
    r.CheckKeys(g, gf,
                {"noise_density_rad_s_sqrt_hz", "bias_rad_s", "bias_random_walk_rad_s_sqrt_s"});
    d.gyro_noise_density_rad_s_sqrt_hz = r.Number(g, "noise_density_rad_s_sqrt_hz", gf, 0, 1, 0.0);
    d.gyro_bias_rad_s = r.Number(g, "bias_rad_s", gf, -10, 10, 0.0);
    d.gyro_bias_random_walk_rad_s_sqrt_s =
        r.Number(g, "bias_random_walk_rad_s_sqrt_s", gf, 0, 1, 0.0);
  }
  if (const YAML::Node a = Reader::Get(n, "accel"); Reader::Present(a)) {
    const std::string af = f + ".accel";
    r.CheckKeys(a, af, {"noise_density_m_s2_sqrt_hz", "bias_m_s2"});
    d.accel_noise_density_m_s2_sqrt_hz = r.Number(a, "noise_density_m_s2_sqrt_hz", af, 0, 10, 0.0);
    d.accel_bias_m_s2 = r.Number(a, "bias_m_s2", af, -10, 10, 0.0);
  }
  std::shared_ptr<const bus::DbcDatabase> db;
  try {
    db = std::make_shared<const bus::DbcDatabase>(bus::DbcDatabase::LoadFile(d.dbc));
  } catch (const std::exception& e) {
    r.FailKey(n, "dbc", f + ".dbc", e.what());
  }
  try {
    (void)DbcImuNode(db, d.node, 0);
  } catch (const std::invalid_argument& e) {
    // "dbc_imu.channels[0].signal: problem" -> field "sensors.dbc_imu.channels[0].signal".
    const std::string what = e.what();
    const auto colon = what.find(": ");
    if (what.starts_with("dbc_imu.") && colon != std::string::npos) {
      r.Fail(n, "sensors." + what.substr(0, colon), what.substr(colon + 2));
    }
    r.Fail(n, f, what);
  }
  return d;
}

SensorsSpec ReadSensors(const Reader& r, const YAML::Node& root,
                        const platforms::Platform& platform) {
  SensorsSpec s;
  const YAML::Node n = Reader::Get(root, "sensors");
  if (!n.IsDefined()) r.Fail(root, "sensors", "is required (encoders at least)");
  r.CheckKeys(n, "sensors", {"encoders", "gyro", "bus", "accel4", "dbc_imu"});
  const YAML::Node e = Reader::Get(n, "encoders");
  if (!e.IsDefined()) r.Fail(n, "sensors.encoders", "is required");
  r.CheckKeys(e, "sensors.encoders",
              {"lines_per_rev", "quadrature_x4", "missed_count_prob", "glitch_prob", "nodes"});
  s.encoder_lines_per_rev =
      static_cast<int>(r.Number(e, "lines_per_rev", "sensors.encoders", 1, 1e7, 500.0));
  s.encoder_quadrature_x4 = r.Bool(e, "quadrature_x4", "sensors.encoders", true);
  s.encoder_missed_count_prob = r.Number(e, "missed_count_prob", "sensors.encoders", 0, 1, 0.0);
  s.encoder_glitch_prob = r.Number(e, "glitch_prob", "sensors.encoders", 0, 1, 0.0);
  const YAML::Node nodes = Reader::Get(e, "nodes");
  if (!nodes.IsSequence() || nodes.size() == 0) {
    r.FailKey(e, "nodes", "sensors.encoders.nodes",
              "must list the encoder nodes ({wheel, node_id})");
  }
  std::set<int> ids;
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    const std::string f = fmt::format("sensors.encoders.nodes[{}]", i);
    r.CheckKeys(nodes[i], f, {"wheel", "node_id", "direction"});
    EncoderDeviceSpec d;
    d.wheel = r.String(nodes[i], "wheel", f, std::nullopt);
    try {
      (void)platform.wheel_index(d.wheel);
    } catch (const std::exception&) {
      r.Fail(nodes[i]["wheel"], f + ".wheel",
             fmt::format("platform {} has no wheel '{}'", platform.name, d.wheel));
    }
    d.node_id = static_cast<int>(r.Number(nodes[i], "node_id", f, 1, 127, std::nullopt));
    if (!ids.insert(d.node_id).second) r.Fail(nodes[i]["node_id"], f + ".node_id", "repeated");
    const double dir = r.Number(nodes[i], "direction", f, -1, 1, 1.0);
    if (dir != 1.0 && dir != -1.0)
      r.Fail(nodes[i]["direction"], f + ".direction", "must be 1 or -1");
    d.direction = static_cast<int>(dir);
    s.encoders.push_back(d);
  }
  if (const auto g = n["gyro"]) {
    const std::string f = "sensors.gyro";
    r.CheckKeys(
        g, f,
        {"rate_hz", "noise_density_rad_s_sqrt_hz", "bias_rad_s", "bias_random_walk_rad_s_sqrt_s"});
    s.gyro = true;
    s.gyro_rate_hz = r.Number(g, "rate_hz", f, 1e-3, 1e4, 100.0);
    s.gyro_noise_density_rad_s_sqrt_hz = r.Number(g, "noise_density_rad_s_sqrt_hz", f, 0, 1, 0.0);
    s.gyro_bias_rad_s = r.Number(g, "bias_rad_s", f, -10, 10, 0.0);
    s.gyro_bias_random_walk_rad_s_sqrt_s =
        r.Number(g, "bias_random_walk_rad_s_sqrt_s", f, 0, 1, 0.0);
  }
  if (const auto a = n["accel4"]) {
    const std::string f = "sensors.accel4";
    r.CheckKeys(a, f,
                {"rate_hz", "radius_m", "noise_density_m_s2_sqrt_hz", "bias_m_s2", "scale_error"});
    s.accel4 = true;
    s.accel4_rate_hz = r.Number(a, "rate_hz", f, 1, 1e5, 1000.0);
    std::optional<double> radius_default;
    for (const auto& [k, v] : platform.parameters) {
      if (k == "accelerometer_radius_m") radius_default = v;
    }
    if (!a["radius_m"] && !radius_default) {
      r.Fail(a, f + ".radius_m",
             fmt::format("is required (platform {} has no kinematics.accelerometer_radius_m)",
                         platform.name));
    }
    s.accel4_radius_m = r.Number(a, "radius_m", f, 1e-3, 10, radius_default);
    s.accel4_noise_density_m_s2_sqrt_hz = r.Number(a, "noise_density_m_s2_sqrt_hz", f, 0, 10, 0.0);
    auto four = [&](const char* key, double lim) {
      std::vector<double> out;
      const auto v = a[key];
      if (!v) return out;
      if (!v.IsSequence() || v.size() != 4) {
        r.Fail(v, f + "." + key, "must list 4 values (accelerometers 1..4 of paper 002 eq 3)");
      }
      for (std::size_t i = 0; i < 4; ++i) {
        double x = 0;
        try {
          x = v[i].as<double>();
        } catch (const std::exception&) {
          r.Fail(v[i], fmt::format("{}.{}[{}]", f, key, i), "is not a number");
        }
        if (!std::isfinite(x) || std::abs(x) > lim) {
          r.Fail(v[i], fmt::format("{}.{}[{}]", f, key, i),
                 fmt::format("({}) must be within +-{}", x, lim));
        }
        out.push_back(x);
      }
      return out;
    };
    s.accel4_bias_m_s2 = four("bias_m_s2", 10.0);
    s.accel4_scale_error = four("scale_error", 0.5);
  }
  if (const YAML::Node d = Reader::Get(n, "dbc_imu"); Reader::Present(d)) {
    s.dbc_imu = ReadDbcImu(r, d);
  }
  if (const auto b = n["bus"]) {
    r.CheckKeys(b, "sensors.bus", {"bitrate_bps", "heartbeat_ms"});
    s.bitrate_bps = static_cast<std::uint32_t>(
        r.Number(b, "bitrate_bps", "sensors.bus", 125000, 1000000, 1000000.0));
    s.heartbeat_ms = static_cast<int>(r.Number(b, "heartbeat_ms", "sensors.bus", 0, 65535, 100.0));
  }
  return s;
}

// Integer field given as a number or a hex string ("0x170").
std::uint64_t ReadId(const Reader& r, const YAML::Node& parent, const std::string& key,
                     const std::string& field, std::uint64_t max, std::uint64_t def) {
  const YAML::Node n = parent[key];
  const std::string f = field + "." + key;
  if (!n.IsDefined() || n.IsNull()) return def;
  if (!n.IsScalar()) r.Fail(n, f, "must be a number (e.g. 0x170)");
  std::uint64_t v = 0;
  try {
    std::size_t used = 0;
    v = std::stoull(n.Scalar(), &used, 0);
    if (used != n.Scalar().size()) throw std::invalid_argument("trailing");
  } catch (const std::exception&) {
    r.Fail(n, f, fmt::format("'{}' is not a non-negative integer", n.Scalar()));
  }
  if (v > max) r.Fail(n, f, fmt::format("0x{:X} is beyond 0x{:X}", v, max));
  return v;
}

// The library's own validation (constructors throw "xxx_faults[0].field: problem"), reported at
// the entry with the scenario's field prefix.
template <typename Fn>
void LibraryCheck(const Reader& r, const YAML::Node& entry, const std::string& field, Fn&& fn) {
  try {
    fn();
  } catch (const std::invalid_argument& e) {
    // "frame_faults[0].probability: must be in [0, 1]" -> field "faults[i].probability".
    std::string what = e.what();
    const auto dot = what.find("].");
    if (dot != std::string::npos) what = what.substr(dot + 2);
    const auto colon = what.find(": ");
    const auto space = what.find(' ');
    if (colon != std::string::npos && colon <= space) {
      r.Fail(entry, field + "." + what.substr(0, colon), what.substr(colon + 2));
    }
    r.Fail(entry, field, what);
  }
}

const char* kFaultTypes =
    "encoder_emcy, encoder_silent, frame, bus, sensor, device, wheel_friction, "
    "torque_disturbance, bump";

std::vector<FaultSpec> ReadFaults(const Reader& r, const YAML::Node& n, const SensorsSpec& s,
                                  const platforms::Platform& platform) {
  std::vector<FaultSpec> out;
  if (!n.IsDefined()) return out;
  if (!n.IsSequence()) r.Fail(n, "faults", "must be a list");
  auto encoder_known = [&](int id) {
    return std::any_of(s.encoders.begin(), s.encoders.end(),
                       [&](const auto& e) { return e.node_id == id; });
  };
  for (std::size_t i = 0; i < n.size(); ++i) {
    const YAML::Node e = n[i];
    const std::string f = fmt::format("faults[{}]", i);
    if (!e.IsMap()) r.Fail(e, f, "must be a mapping");
    FaultSpec x;
    x.where = r.Where(e);
    const std::string type = r.String(e, "type", f, std::nullopt);
    // Window (all kinds but bump): start_s required, end_s optional (to the end of the run).
    auto window = [&](bool end_required) {
      x.start_s = r.Number(e, "start_s", f, 0, 1e6, std::nullopt);
      if (end_required || e["end_s"]) {
        x.end_s = r.Number(e, "end_s", f, x.start_s, 1e6, std::nullopt);
      }
    };
    auto lib_window = [&] {
      window(false);
      if (!(x.end_s > x.start_s)) r.Fail(e["end_s"], f + ".end_s", "must be after start_s");
      FaultWindow w;
      w.t0_ns = std::llround(x.start_s * 1e9);
      w.t1_ns = std::isfinite(x.end_s) ? std::llround(x.end_s * 1e9) : FaultWindow::kForever;
      return w;
    };
    auto kind_of = [&](auto parse, const char* names) {
      const std::string k = r.String(e, "kind", f, std::nullopt);
      const auto v = parse(k);
      if (!v) r.Fail(e["kind"], f + ".kind", fmt::format("'{}' is not one of {}", k, names));
      return *v;
    };
    // Encoder node by node_id, or "gyro"/"accel4" by node (when allowed).
    auto target_node = [&](bool named_ok) {
      if (e["node_id"] && e["node"])
        r.Fail(e["node"], f + ".node", "give node_id or node, not both");
      if (e["node_id"]) {
        x.node_id = static_cast<int>(r.Number(e, "node_id", f, 1, 127, std::nullopt));
        if (!encoder_known(x.node_id))
          r.Fail(e["node_id"], f + ".node_id", "no encoder node has this id");
        return;
      }
      if (!named_ok) r.Fail(e, f + ".node_id", "is required (an encoder node)");
      x.node = r.String(e, "node", f, std::nullopt);
      if (x.node == "gyro" && s.gyro) return;
      if (x.node == "accel4" && s.accel4) return;
      if (x.node != "gyro" && x.node != "accel4") {
        r.Fail(e["node"], f + ".node",
               fmt::format("'{}' is not gyro or accel4 (encoders: node_id)", x.node));
      }
      r.Fail(e["node"], f + ".node", fmt::format("sensors.{} is not configured", x.node));
    };
    auto wheel = [&] {
      x.wheel = r.String(e, "wheel", f, std::nullopt);
      try {
        x.wheel_index = platform.wheel_index(x.wheel);
      } catch (const std::exception&) {
        r.Fail(e["wheel"], f + ".wheel",
               fmt::format("platform {} has no wheel '{}'", platform.name, x.wheel));
      }
    };
    if (type == "encoder_emcy" || type == "encoder_silent") {
      r.CheckKeys(e, f, {"type", "node_id", "start_s", "end_s", "error_code"});
      x.kind =
          type == "encoder_emcy" ? FaultSpec::Kind::kEncoderEmcy : FaultSpec::Kind::kEncoderSilent;
      x.node_id = static_cast<int>(r.Number(e, "node_id", f, 1, 127, std::nullopt));
      if (!encoder_known(x.node_id))
        r.Fail(e["node_id"], f + ".node_id", "no encoder node has this id");
      window(true);
      x.error_code = static_cast<std::uint16_t>(r.Number(e, "error_code", f, 1, 65535, 0x7305));
    } else if (type == "frame") {
      r.CheckKeys(
          e, f,
          {"type", "kind", "start_s", "end_s", "id", "mask", "extended", "probability", "delay_s",
           "bit_flips", "dlc", "counter_signal", "counter_offset", "checksum_signal", "checksum"});
      x.kind = FaultSpec::Kind::kFrame;
      FrameFault& ff = x.frame;
      ff.kind =
          kind_of(ParseFrameFaultKind,
                  "drop, delay, duplicate, corrupt, wrong_counter, wrong_checksum, wrong_dlc");
      ff.window = lib_window();
      ff.extended = r.Bool(e, "extended", f, false);
      const std::uint64_t max_id = ff.extended ? 0x1FFFFFFF : 0x7FF;
      ff.id = static_cast<std::uint32_t>(ReadId(r, e, "id", f, max_id, 0));
      ff.mask = static_cast<std::uint32_t>(ReadId(r, e, "mask", f, max_id, e["id"] ? max_id : 0));
      ff.probability = r.Number(e, "probability", f, 0, 1, 1.0);
      ff.delay_ns =
          std::llround(r.Number(e, "delay_s", f, 0, 10,
                                ff.kind == FrameFaultKind::kDelay ? std::optional<double>() : 0.0) *
                       1e9);
      ff.bit_flips = static_cast<int>(r.Number(e, "bit_flips", f, 1, 64, 1.0));
      ff.dlc = static_cast<std::uint8_t>(r.Number(
          e, "dlc", f, 0, 8, ff.kind == FrameFaultKind::kWrongDlc ? std::optional<double>() : 0.0));
      ff.counter_signal = r.String(e, "counter_signal", f, std::string());
      ff.counter_offset =
          static_cast<std::int64_t>(r.Number(e, "counter_offset", f, -1e6, 1e6, -1.0));
      ff.checksum_signal = r.String(e, "checksum_signal", f, std::string());
      if (e["checksum"]) {
        const std::string c = r.String(e, "checksum", f, std::nullopt);
        const auto ck = ParseChecksumKind(c);
        if (!ck)
          r.Fail(e["checksum"], f + ".checksum", fmt::format("'{}' is not a checksum kind", c));
        ff.checksum = *ck;
      }
      if (ff.kind == FrameFaultKind::kWrongCounter && ff.counter_signal.empty()) {
        r.Fail(e, f + ".counter_signal", "is required for wrong_counter");
      }
      if (ff.kind == FrameFaultKind::kWrongChecksum && ff.checksum_signal.empty()) {
        r.Fail(e, f + ".checksum_signal", "is required for wrong_checksum");
      }
      if (ff.kind != FrameFaultKind::kWrongCounter && ff.kind != FrameFaultKind::kWrongChecksum) {
        LibraryCheck(r, e, f, [&] { FrameFaultFilter({ff}, nullptr, 0); });
      }
    } else if (type == "bus") {
      r.CheckKeys(e, f,
                  {"type", "kind", "start_s", "end_s", "error_frames", "node_id", "node", "load",
                   "flood_id", "flood_len"});
      x.kind = FaultSpec::Kind::kBus;
      BusFault& b = x.bus;
      b.kind = kind_of(ParseBusFaultKind, "error_burst, bus_off, flood");
      b.window = lib_window();
      b.error_frames = static_cast<int>(r.Number(e, "error_frames", f, 1, 1000, 1.0));
      b.load = r.Number(e, "load", f, 1e-3, 1, 0.5);
      b.flood_id = static_cast<std::uint32_t>(ReadId(r, e, "flood_id", f, 0x7FF, 0x001));
      b.flood_len = static_cast<std::uint8_t>(r.Number(e, "flood_len", f, 0, 8, 8.0));
      if (b.kind == BusFaultKind::kBusOff) {
        target_node(true);
      } else if (e["node_id"] || e["node"]) {
        r.Fail(e["node_id"] ? e["node_id"] : e["node"], f + ".node", "only bus_off takes a node");
      }
      LibraryCheck(r, e, f, [&] {
        CanBusModel bus{CanBusConfig{}};
        BusFault check = b;
        check.node = b.kind == BusFaultKind::kBusOff ? bus.AddNode("target") : -1;
        FaultyCanBus fb(bus, {check});
      });
    } else if (type == "sensor") {
      r.CheckKeys(e, f,
                  {"type", "kind", "start_s", "end_s", "sensor", "wheel", "channel", "value"});
      x.kind = FaultSpec::Kind::kSensor;
      x.sensor.kind = kind_of(ParseSensorFaultKind,
                              "bias_step, drift_ramp, noise_scale, stuck, dropout, saturation, "
                              "missed_counts");
      x.sensor.window = lib_window();
      x.sensor_name = r.String(e, "sensor", f, std::nullopt);
      if (x.sensor_name == "gyro") {
        if (!s.gyro) r.Fail(e["sensor"], f + ".sensor", "sensors.gyro is not configured");
      } else if (x.sensor_name == "accel4") {
        if (!s.accel4) r.Fail(e["sensor"], f + ".sensor", "sensors.accel4 is not configured");
        x.channel = static_cast<int>(r.Number(e, "channel", f, 0, 4, 0.0));
      } else if (x.sensor_name == "encoder") {
        wheel();
        const bool has = std::any_of(s.encoders.begin(), s.encoders.end(),
                                     [&](const auto& en) { return en.wheel == x.wheel; });
        if (!has) r.Fail(e["wheel"], f + ".wheel", "no encoder node on this wheel");
      } else {
        r.Fail(e["sensor"], f + ".sensor",
               fmt::format("'{}' is not one of gyro, encoder, accel4", x.sensor_name));
      }
      if (e["wheel"] && x.sensor_name != "encoder") {
        r.Fail(e["wheel"], f + ".wheel", "only an encoder fault names a wheel");
      }
      if (e["channel"] && x.sensor_name != "accel4") {
        r.Fail(e["channel"], f + ".channel", "only an accel4 fault names a channel");
      }
      if (x.sensor.kind == SensorFaultKind::kMissedCounts && x.sensor_name != "encoder") {
        r.Fail(e["kind"], f + ".kind", "missed_counts applies to encoders only");
      }
      const bool needs_value =
          x.sensor.kind != SensorFaultKind::kStuck && x.sensor.kind != SensorFaultKind::kDropout;
      x.sensor.value =
          r.Number(e, "value", f, -1e9, 1e9, needs_value ? std::optional<double>() : 0.0);
      LibraryCheck(r, e["value"].IsDefined() ? e["value"] : e, f,
                   [&] { SensorFaultInjector("check", {x.sensor}, 0.0, 0); });
    } else if (type == "device") {
      r.CheckKeys(
          e, f,
          {"type", "kind", "start_s", "end_s", "node_id", "node", "error_code", "error_register"});
      x.kind = FaultSpec::Kind::kDevice;
      x.device.kind = kind_of(ParseDeviceFaultKind, "silent, heartbeat_lost, reboot, emcy");
      x.device.window = lib_window();
      if (x.device.kind == DeviceFaultKind::kReboot && !e["end_s"]) {
        r.Fail(e, f + ".end_s", "is required for a reboot (the power-on instant)");
      }
      target_node(x.device.kind == DeviceFaultKind::kSilent);
      x.device.emcy_code =
          static_cast<std::uint16_t>(ReadId(r, e, "error_code", f, 0xFFFF, 0x7305));
      x.device.error_register =
          static_cast<std::uint8_t>(ReadId(r, e, "error_register", f, 0xFF, 0x01));
      LibraryCheck(r, e, f, [&] { DeviceFaultInjector("check", 1, {x.device}); });
    } else if (type == "wheel_friction") {
      r.CheckKeys(e, f, {"type", "wheel", "start_s", "end_s", "mu_scale", "mu_peak", "mu_slide"});
      x.kind = FaultSpec::Kind::kWheelFriction;
      wheel();
      window(false);
      if (!(x.end_s > x.start_s)) r.Fail(e["end_s"], f + ".end_s", "must be after start_s");
      x.mu_scale = r.Number(e, "mu_scale", f, 0, 10, 1.0);
      if (e["mu_peak"] || e["mu_slide"]) {
        if (!e["mu_peak"]) r.Fail(e["mu_slide"], f + ".mu_peak", "is required with mu_slide");
        x.mu_override = ReadFriction(r, e, f, Friction{});
      }
      if (!e["mu_scale"] && !x.mu_override) {
        r.Fail(e, f + ".mu_scale", "give mu_scale and/or mu_peak/mu_slide");
      }
    } else if (type == "torque_disturbance") {
      r.CheckKeys(e, f, {"type", "wheel", "start_s", "end_s", "torque_nm"});
      x.kind = FaultSpec::Kind::kTorqueDisturbance;
      wheel();
      window(false);
      if (!(x.end_s > x.start_s)) r.Fail(e["end_s"], f + ".end_s", "must be after start_s");
      x.torque_nm = r.Number(e, "torque_nm", f, -1e4, 1e4, std::nullopt);
    } else if (type == "bump") {
      r.CheckKeys(e, f,
                  {"type", "x_m", "y_m", "width_m", "height_m", "ramp_length_m", "top_length_m",
                   "mu_peak", "mu_slide"});
      x.kind = FaultSpec::Kind::kBump;
      x.x_m = r.Number(e, "x_m", f, -1e4, 1e4, std::nullopt);
      x.y_m = r.Number(e, "y_m", f, -1e4, 1e4, 0.0);
      x.width_m = r.Number(e, "width_m", f, 1e-3, 100, 2.0);
      x.height_m = r.Number(e, "height_m", f, 1e-4, 0.5, std::nullopt);
      x.ramp_length_m = r.Number(e, "ramp_length_m", f, 1e-3, 100, 4.0 * x.height_m);
      x.top_length_m = r.Number(e, "top_length_m", f, 0, 100, 0.05);
      if (e["mu_peak"] || e["mu_slide"]) x.bump_friction = ReadFriction(r, e, f, Friction{});
    } else {
      r.Fail(e["type"], f + ".type", fmt::format("'{}' is not one of {}", type, kFaultTypes));
    }
    out.push_back(std::move(x));
  }
  return out;
}

FirmwareSpec ReadFirmware(const Reader& r, const YAML::Node& n) {
  FirmwareSpec fw;
  if (!n.IsDefined() || n.IsNull()) return fw;
  r.CheckKeys(n, "firmware", {"command", "config", "overrides"});
  fw.command = r.String(n, "command", "firmware", std::string());
  const std::string cfg = r.String(n, "config", "firmware", std::string());
  if (!cfg.empty()) {
    fw.config = r.Path(cfg);
    if (!fs::exists(fw.config)) r.Fail(n["config"], "firmware.config", fw.config + " not found");
  }
  if (const auto o = n["overrides"]) {
    if (!o.IsMap()) r.Fail(o, "firmware.overrides", "must be a mapping");
    if (fw.config.empty()) r.Fail(o, "firmware.overrides", "needs firmware.config");
    YAML::Emitter e;
    e << o;
    fw.overrides_yaml = e.c_str();
  }
  if (fw.command.find("${CONFIG}") != std::string::npos && fw.config.empty()) {
    r.Fail(n["command"], "firmware.command", "uses ${CONFIG} but firmware.config is not set");
  }
  return fw;
}

TimingSpec ReadTiming(const Reader& r, const YAML::Node& n, double motion_s) {
  TimingSpec t;
  t.duration_s = motion_s;
  if (!n.IsDefined()) return t;
  r.CheckKeys(n, "timing", {"mode", "duration_s", "physics_rate_hz", "sync_period_s", "timeout_s"});
  const std::string mode = r.String(n, "mode", "timing", std::string("lockstep"));
  if (mode == "lockstep") {
    t.lockstep = true;
  } else if (mode == "realtime") {
    t.lockstep = false;
  } else {
    r.Fail(n["mode"], "timing.mode", fmt::format("'{}' is not lockstep or realtime", mode));
  }
  t.duration_s = r.Number(n, "duration_s", "timing", 1e-3, 1e6, motion_s);
  t.physics_rate_hz = r.Number(n, "physics_rate_hz", "timing", 100, 10000, 1000.0);
  t.sync_period_s = r.Number(n, "sync_period_s", "timing", 1e-4, 10, 0.01);
  const double steps = t.sync_period_s * t.physics_rate_hz;
  if (std::abs(steps - std::round(steps)) > 1e-6) {
    r.FailKey(n, "sync_period_s", "timing.sync_period_s",
              "must be a whole number of physics steps");
  }
  t.timeout_s = r.Number(n, "timeout_s", "timing", 1e-3, 3600, 5.0);
  return t;
}

std::vector<Expectation> ReadExpectations(const Reader& r, const YAML::Node& n) {
  std::vector<Expectation> out;
  if (!n.IsDefined()) return out;
  if (!n.IsSequence()) r.Fail(n, "expectations", "must be a list");
  for (std::size_t i = 0; i < n.size(); ++i) {
    const std::string f = fmt::format("expectations[{}]", i);
    r.CheckKeys(n[i], f, {"metric", "<", "<=", ">", ">="});
    Expectation e;
    e.where = r.Where(n[i]);
    e.metric = r.String(n[i], "metric", f, std::nullopt);
    int ops = 0;
    for (const char* op : {"<", "<=", ">", ">="}) {
      const auto v = n[i][op];
      if (!v.IsDefined()) continue;
      ++ops;
      e.op = op;
      double x = 0;
      try {
        x = v.as<double>();
        e.value = x;
      } catch (const YAML::Exception&) {
        e.other_metric = v.Scalar();
      }
    }
    if (ops != 1) r.Fail(n[i], f, "needs exactly one of <, <=, >, >= (a number or a metric)");
    out.push_back(std::move(e));
  }
  return out;
}

}  // namespace

double TrapezoidDuration(double distance, double speed, double accel) {
  if (distance <= 0) return 0;
  const double d_ramp = speed * speed / accel;  // accelerate + decelerate
  if (distance <= d_ramp) return 2.0 * std::sqrt(distance / accel);
  return 2.0 * speed / accel + (distance - d_ramp) / speed;
}

double TrapezoidSpeed(double distance, double speed, double accel, double t_s) {
  const double total = TrapezoidDuration(distance, speed, accel);
  if (t_s <= 0 || t_s >= total) return 0;
  const double peak = std::min(speed, std::sqrt(distance * accel));
  return std::min({peak, accel * t_s, accel * (total - t_s)});
}

double MotionDuration(const std::vector<MotionSegment>& motion) {
  double t = 0;
  for (const auto& m : motion) t += m.duration_s;
  return t;
}

platforms::BodyTwist TwistAt(const std::vector<MotionSegment>& motion, double t_s) {
  double t0 = 0;
  for (const auto& m : motion) {
    if (t_s < t0 + m.duration_s) {
      const double t = t_s - t0;
      switch (m.kind) {
        case MotionSegment::Kind::kTwist:
          return m.twist;
        case MotionSegment::Kind::kTrapezoid: {
          const double v = TrapezoidSpeed(m.distance, m.speed, m.accel, t);
          return {v * m.direction.x(), v * m.direction.y(), v * m.direction.z()};
        }
        case MotionSegment::Kind::kHold:
        case MotionSegment::Kind::kWheels:
          return {};
      }
    }
    t0 += m.duration_s;
  }
  return {};
}

namespace {

// `scoring: {metrics: [name, ...]}`: the metric components that score the run (default: the
// generic ones).
std::vector<std::string> ReadScoring(const Reader& r, const YAML::Node& n) {
  if (!Reader::Present(n)) return scoring::DefaultMetricComponents();
  r.CheckKeys(n, "scoring", {"metrics"});
  const YAML::Node m = Reader::Get(n, "metrics");
  if (!Reader::Present(m)) return scoring::DefaultMetricComponents();
  if (!m.IsSequence()) r.Fail(m, "scoring.metrics", "must be a list of metric component names");
  const auto& known = scoring::MetricComponentNames();
  std::vector<std::string> names;
  for (std::size_t i = 0; i < m.size(); ++i) {
    const std::string f = fmt::format("scoring.metrics[{}]", i);
    const std::string name = r.ToString(m[i], f);
    if (std::find(known.begin(), known.end(), name) == known.end()) {
      r.Fail(m[i], f, fmt::format("'{}' is not one of {}", name, fmt::join(known, ", ")));
    }
    if (std::find(names.begin(), names.end(), name) != names.end()) {
      r.Fail(m[i], f, fmt::format("'{}' is listed twice", name));
    }
    names.push_back(name);
  }
  return names;
}

Scenario ReadScenario(const Reader& r, const YAML::Node& root) {
  r.CheckKeys(root, "",
              {"name", "description", "seed", "platform", "terrain", "motion", "sensors", "faults",
               "firmware", "timing", "expectations", "scoring", "slip_threshold_m_s"});
  Scenario s;
  s.source_path = r.file();
  s.name = r.String(root, "name", "", std::nullopt);
  s.description = r.String(root, "description", "", std::string());
  s.seed = static_cast<std::uint64_t>(r.Number(root, "seed", "", 0, 9e15, 1.0));

  const YAML::Node p = Reader::Get(root, "platform");
  if (!p.IsDefined()) r.Fail(root, "platform", "is required");
  if (p.IsScalar()) {
    const std::string path = r.Path(p.Scalar());
    try {
      s.platform = platforms::LoadPlatformFile(path);
    } catch (const std::invalid_argument& e) {
      r.Fail(p, "platform", e.what());
    }
  } else {
    r.CheckKeys(p, "platform", {"file", "overrides"});
    const std::string path = r.Path(r.String(p, "file", "platform", std::nullopt));
    const YAML::Node overrides = Reader::Get(p, "overrides");
    if (overrides.IsDefined() && !overrides.IsMap()) {
      r.Fail(overrides, "platform.overrides", "must be a mapping");
    }
    try {
      s.platform = platforms::LoadPlatformFile(path, overrides);
    } catch (const std::invalid_argument& e) {
      const bool over = overrides.IsDefined();
      r.Fail(over ? overrides : p["file"], over ? "platform.overrides" : "platform.file", e.what());
    }
  }
  s.terrain = ReadTerrain(r, Reader::Get(root, "terrain"));
  s.motion = ReadMotion(r, root, s.platform);
  s.sensors = ReadSensors(r, root, s.platform);
  s.faults = ReadFaults(r, Reader::Get(root, "faults"), s.sensors, s.platform);
  s.firmware = ReadFirmware(r, Reader::Get(root, "firmware"));
  s.timing = ReadTiming(r, Reader::Get(root, "timing"), MotionDuration(s.motion));
  s.expectations = ReadExpectations(r, Reader::Get(root, "expectations"));
  s.metric_components = ReadScoring(r, Reader::Get(root, "scoring"));
  if (root["slip_threshold_m_s"]) {
    s.slip_threshold_m_s = r.Number(root, "slip_threshold_m_s", "", 1e-6, 10, std::nullopt);
  }
  return s;
}

}  // namespace

Scenario ParseScenario(const std::string& text, const std::string& file) {
  const Reader r(file);
  return r.Guard([&] {
    const YAML::Node root = r.Parse(text);
    if (!root.IsMap()) r.Fail(root, "(document)", "must be a mapping");
    return ReadScenario(r, root);
  });
}

Scenario LoadScenarioFile(const std::string& path) {
  return ParseScenario(Reader(path).ReadFile(), path);
}

}  // namespace wheelhil::emulator::scenario
