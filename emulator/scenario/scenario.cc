#include "emulator/scenario/scenario.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <numbers>
#include <set>
#include <stdexcept>

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include "emulator/scenario/internal/scenario_reader.h"
#include "emulator/scoring/metric_components.h"
#include "emulator/scoring/metrics.h"

namespace wheelhil::emulator::scenario {

namespace {

namespace fs = std::filesystem;
using internal::Reader;
using internal::ReadFaults;
using internal::ReadFriction;
using internal::ReadSensors;

std::vector<Eigen::Vector2d> ReadPolygon(const Reader& r, const YAML::Node& parent,
                                         const std::string& key, const std::string& prefix) {
  const std::string field = Reader::Join(prefix, key);
  const YAML::Node n = Reader::Get(parent, key);
  if (!n.IsSequence() || n.size() < 3) {
    r.FailKey(parent, key, field, "must be a list of >= 3 [x, y] points");
  }
  r.CheckCount(n, field, ScenarioLimits::kPolygonPoints);
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
    r.CheckCount(m, "terrain.meshes", ScenarioLimits::kMeshes);
    for (std::size_t i = 0; i < m.size(); ++i) {
      const std::string p = r.Path(r.ToString(m[i], fmt::format("terrain.meshes[{}]", i)));
      std::error_code ec;
      if (!fs::exists(p, ec)) {
        r.Fail(m[i], fmt::format("terrain.meshes[{}]", i),
               p + " not found" + (ec ? " (" + ec.message() + ")" : std::string()));
      }
      t.meshes.push_back(p);
    }
  }
  if (const auto ps = n["patches"]) {
    if (!ps.IsSequence()) r.Fail(ps, "terrain.patches", "must be a list");
    r.CheckCount(ps, "terrain.patches", ScenarioLimits::kPatches);
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
    s.count = static_cast<int>(r.Integer(rp, "count", f, 0, 1000, std::nullopt));
    s.x_min_m = r.Number(rp, "x_min_m", f, -1e4, 1e4, std::nullopt);
    s.x_max_m = r.Number(rp, "x_max_m", f, s.x_min_m, 1e4, std::nullopt);
    s.length_min_m = r.Number(rp, "length_min_m", f, 1e-3, 100, 0.05);
    s.length_max_m = r.Number(rp, "length_max_m", f, s.length_min_m, 100, 0.2);
    s.width_m = r.Number(rp, "width_m", f, 1e-3, 10, 0.1);
    const YAML::Node ty = Reader::Get(rp, "track_y_m");
    if (!ty.IsDefined()) r.Fail(rp, f + ".track_y_m", "is required (a list of y)");
    if (!ty.IsSequence() || ty.size() == 0) r.Fail(ty, f + ".track_y_m", "must be a list of y");
    r.CheckCount(ty, f + ".track_y_m", ScenarioLimits::kRandomPatchTracks);
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
  r.CheckCount(pts, f + ".points_m", ScenarioLimits::kWaypoints);
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
  if (n.IsMap()) return {};  // {source: firmware}: ReadFirmwareMotion
  if (!n.IsSequence() || n.size() == 0) {
    r.FailKey(root, "motion", "motion",
              "must be a non-empty list of segments, or {source: firmware}");
  }
  r.CheckCount(n, "motion", ScenarioLimits::kMotionSegments);
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

std::optional<FirmwareMotionSpec> ReadFirmwareMotion(const Reader& r, const YAML::Node& root) {
  const YAML::Node n = Reader::Get(root, "motion");
  if (!n.IsMap()) return std::nullopt;
  r.CheckKeys(n, "motion", {"source", "goal"});
  const std::string source = r.String(n, "source", "motion", std::nullopt);
  if (source != "firmware") {
    r.Fail(n["source"], "motion.source",
           fmt::format("'{}' is not firmware (a scripted motion is a list of segments)", source));
  }
  FirmwareMotionSpec m;
  if (const YAML::Node g = Reader::Get(n, "goal"); Reader::Present(g)) {
    r.CheckKeys(g, "motion.goal", {"x_m", "y_m", "theta_deg"});
    m.goal = Eigen::Vector3d(
        r.Number(g, "x_m", "motion.goal", -1e5, 1e5, std::nullopt),
        r.Number(g, "y_m", "motion.goal", -1e5, 1e5, std::nullopt),
        r.Number(g, "theta_deg", "motion.goal", -1e6, 1e6, 0.0) * std::numbers::pi / 180.0);
    m.goal_has_heading = Reader::Present(Reader::Get(g, "theta_deg"));
  }
  return m;
}

// Closed loop: every driven wheel has exactly one drive, and drives only come with it.
void CheckDrives(const Reader& r, const YAML::Node& root, const Scenario& s) {
  std::vector<int> drives_of(s.platform.vehicle.wheels.size(), 0);
  auto count = [&](const std::string& device, std::size_t wheel) {
    const std::string& name = s.platform.vehicle.wheels[wheel].name;
    if (!s.firmware_motion) {
      r.FailKey(root, "motion", "motion",
                fmt::format("device '{}' drives wheel '{}': a scenario with drives takes its "
                            "motion from the firmware (motion: {{source: firmware}})",
                            device, name));
    }
    if (++drives_of[wheel] > 1) {
      r.FailKey(root, "devices", "devices", fmt::format("wheel '{}' has two drives", name));
    }
  };
  for (const DeviceSpec& d : s.devices) {
    if (d.kind == DeviceSpec::Kind::kCanopenCia402) count(d.drive.name, d.drive.wheel_index);
    if (d.kind != DeviceSpec::Kind::kDbc) continue;
    for (const DbcSignalBinding& b : d.dbc_device.signals) {
      if (b.quantity == DbcQuantity::kWheelSpeedSetpoint) count(d.dbc_device.name, b.wheel_index);
    }
  }
  if (!s.firmware_motion) return;
  for (std::size_t w = 0; w < drives_of.size(); ++w) {
    const auto& wheel = s.platform.vehicle.wheels[w];
    if (wheel.driven && drives_of[w] == 0) {
      r.FailKey(root, "devices", "devices",
                fmt::format("motion.source firmware: driven wheel '{}' has no drive (add a "
                            "device of kind canopen_cia402 on it, or a dbc device with a "
                            "wheel_speed_setpoint signal for it)",
                            wheel.name));
    }
  }
  if (!Reader::Present(Reader::Get(Reader::Get(root, "timing"), "duration_s"))) {
    r.FailKey(root, "timing", "timing.duration_s",
              "is required with motion.source firmware (there is no script to time)");
  }
}

FirmwareSpec ReadFirmware(const Reader& r, const YAML::Node& n) {
  FirmwareSpec fw;
  if (!n.IsDefined() || n.IsNull()) return fw;
  r.CheckKeys(n, "firmware", {"command", "config", "overrides", "outputs"});
  fw.command = r.String(n, "command", "firmware", std::string());
  const std::string cfg = r.String(n, "config", "firmware", std::string());
  if (!cfg.empty()) {
    fw.config = r.Path(cfg);
    std::error_code ec;
    if (!fs::exists(fw.config, ec)) {
      r.Fail(n["config"], "firmware.config",
             fw.config + " not found" + (ec ? " (" + ec.message() + ")" : std::string()));
    }
    if (!fs::is_regular_file(fw.config, ec)) {
      r.Fail(n["config"], "firmware.config", fw.config + " is not a regular file");
    }
  }
  if (const auto o = n["overrides"]) {
    if (!o.IsMap()) r.Fail(o, "firmware.overrides", "must be a mapping");
    if (fw.config.empty()) r.Fail(o, "firmware.overrides", "needs firmware.config");
    YAML::Emitter e;
    e << o;
    fw.overrides_yaml = e.c_str();
  }
  if (const YAML::Node o = Reader::Get(n, "outputs"); Reader::Present(o)) {
    fw.outputs = scoring::ReadOutputs(r, o, "firmware.outputs", r.Path("."));
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
  r.CheckKeys(n, "timing",
              {"mode", "duration_s", "physics_rate_hz", "sync_period_s", "timeout_s", "clock",
               "sync_producer", "spin_cost_s"});
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
  // Lockstep is on the firmware's virtual clock (docs/virtual-time.md), the only one.
  const std::string clock = r.String(n, "clock", "timing", std::string("virtual"));
  if (clock == "cooperative") {
    r.Fail(n["clock"], "timing.clock",
           fmt::format("{} (remove the key)", kCooperativeClockRetired));
  } else if (clock != "virtual") {
    r.Fail(n["clock"], "timing.clock", fmt::format("'{}' is not virtual", clock));
  }
  t.sync_producer_named = n["sync_producer"].IsDefined();
  t.spin_cost_s = r.Number(n, "spin_cost_s", "timing", 0, 0.01, 0.0);
  const std::string producer = r.String(n, "sync_producer", "timing", std::string("firmware"));
  t.firmware_produces_sync = producer == "firmware";
  if (producer != "firmware" && producer != "emulator") {
    r.Fail(n["sync_producer"], "timing.sync_producer",
           fmt::format("'{}' is not firmware or emulator", producer));
  }
  return t;
}

std::vector<Expectation> ReadExpectations(const Reader& r, const YAML::Node& n) {
  std::vector<Expectation> out;
  if (!n.IsDefined()) return out;
  if (!n.IsSequence()) r.Fail(n, "expectations", "must be a list");
  r.CheckCount(n, "expectations", ScenarioLimits::kExpectations);
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
      if (!v.IsScalar()) r.Fail(v, Reader::Join(f, op), "must be a number or a metric name");
      double x = 0;
      if (YAML::convert<double>::decode(v, x)) {
        if (!std::isfinite(x)) r.Fail(v, Reader::Join(f, op), "must be finite");
        e.value = x;
      } else {
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

// `logs: [asc, blf, mcap]`: the bus log in these formats too, beside can.log; the whole run as
// run.mcap.
std::vector<std::string> ReadLogs(const Reader& r, const YAML::Node& n) {
  std::vector<std::string> formats;
  if (!Reader::Present(n)) return formats;
  if (!n.IsSequence()) r.Fail(n, "logs", "must be a list of formats (asc, blf, mcap)");
  for (std::size_t i = 0; i < n.size(); ++i) {
    const std::string f = fmt::format("logs[{}]", i);
    const std::string format = r.ToString(n[i], f);
    if (format != "asc" && format != "blf" && format != "mcap") {
      r.Fail(n[i], f,
             fmt::format("'{}' is not one of the run's other logs (asc, blf, mcap)", format));
    }
    if (std::find(formats.begin(), formats.end(), format) != formats.end()) {
      r.Fail(n[i], f, fmt::format("'{}' is listed twice", format));
    }
    formats.push_back(format);
  }
  return formats;
}

Scenario ReadScenario(const Reader& r, const YAML::Node& root) {
  r.CheckKeys(
      root, "",
      {"name", "description", "seed", "platform", "terrain", "motion", "sensors", "devices",
       "faults", "firmware", "timing", "expectations", "scoring", "slip_threshold_m_s", "logs"});
  Scenario s;
  s.source_path = r.file();
  s.name = r.String(root, "name", "", std::nullopt);
  s.description = r.String(root, "description", "", std::string());
  s.seed = static_cast<std::uint64_t>(r.Integer(root, "seed", "", 0, 9'000'000'000'000'000, 1));

  const YAML::Node p = Reader::Get(root, "platform");
  if (!p.IsDefined()) r.Fail(root, "platform", "is required");
  if (p.IsScalar()) {
    const std::string path = r.Path(r.ToString(p, "platform"));
    try {
      s.platform = platforms::LoadPlatformFile(path);
    } catch (const std::invalid_argument& e) {
      r.Fail(p, "platform", e.what());
    }
  } else {
    r.CheckKeys(p, "platform", {"file", "overrides", "tolerances"});
    const std::string path = r.Path(r.String(p, "file", "platform", std::nullopt));
    const std::string tol = r.String(p, "tolerances", "platform", std::string("sample"));
    if (tol != "sample" && tol != "nominal") {
      r.Fail(p["tolerances"], "platform.tolerances", "must be 'sample' or 'nominal'");
    }
    s.sample_tolerances = tol == "sample";
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
  s.firmware_motion = ReadFirmwareMotion(r, root);
  s.sensors = ReadSensors(r, root, s.platform);
  s.devices = ReadDevices(r, Reader::Get(root, "devices"), s.platform, s.sensors);
  s.faults = ReadFaults(r, Reader::Get(root, "faults"), s.sensors, s.devices, s.platform);
  s.firmware = ReadFirmware(r, Reader::Get(root, "firmware"));
  s.timing = ReadTiming(r, Reader::Get(root, "timing"), MotionDuration(s.motion));
  CheckDrives(r, root, s);
  s.expectations = ReadExpectations(r, Reader::Get(root, "expectations"));
  s.metric_components = ReadScoring(r, Reader::Get(root, "scoring"));
  s.log_formats = ReadLogs(r, Reader::Get(root, "logs"));
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
