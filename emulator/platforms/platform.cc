#include "emulator/platforms/platform.h"

#include <fnmatch.h>

#include <cmath>
#include <numbers>
#include <random>
#include <set>
#include <stdexcept>

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include "bus/yaml_fields.h"
#include "emulator/physics/roller_geometry.h"
#include "emulator/platforms/robot_description.h"

namespace wheelhil::emulator::platforms {

namespace {

using physics::WheelKind;
using physics::WheelSpec;
constexpr double kDeg = std::numbers::pi / 180.0;

// Platform fields; a wheel's key missing from the wheel is looked up in wheel_defaults.
class Reader : public bus::yaml::FieldReader {
 public:
  using FieldReader::FieldReader;

  // node[key], else fallback[key] (the defaults); undefined when neither has it. A null value
  // counts as given (and then fails as not a number).
  static YAML::Node Lookup(const YAML::Node& node, const YAML::Node& fallback,
                           const std::string& key) {
    const YAML::Node n = Get(node, key);
    return n.IsDefined() ? n : Get(fallback, key);
  }

  // Lookup(parent, fallback, key) as a number in [min, max]; required unless def given.
  double Value(const YAML::Node& parent, const YAML::Node& fallback, const std::string& key,
               const std::string& prefix, double min, double max,
               const double* def = nullptr) const {
    const YAML::Node n = Lookup(parent, fallback, key);
    const std::string field = prefix + key;
    if (!n.IsDefined()) {
      if (def != nullptr) return *def;
      Fail(parent, field, "is required");
    }
    return ToNumber(n, field, min, max);
  }
  double ValueOr(const YAML::Node& parent, const YAML::Node& fallback, const std::string& key,
                 const std::string& prefix, double min, double max, double def) const {
    return Value(parent, fallback, key, prefix, min, max, &def);
  }

  Eigen::Vector3d Vec3(const YAML::Node& parent, const std::string& key,
                       const std::string& field) const {
    const YAML::Node n = Get(parent, key);
    if (!n.IsDefined()) Fail(parent, field, "is required");
    if (!n.IsSequence() || n.size() != 3) Fail(n, field, "must be a list of 3 numbers");
    return {ToNumber(n[0], field + "[0]"), ToNumber(n[1], field + "[1]"),
            ToNumber(n[2], field + "[2]")};
  }

  // parent[key] as a string; required.
  std::string Text(const YAML::Node& parent, const std::string& key,
                   const std::string& field) const {
    const YAML::Node n = Get(parent, key);
    if (!n.IsDefined()) Fail(parent, field, "is required");
    return ToString(n, field);
  }
};

const std::set<std::string> kWheelKeys = {"name",
                                          "kind",
                                          "mount_m",
                                          "heading_deg",
                                          "radius_m",
                                          "inertia_kg_m2",
                                          "roller_angle_deg",
                                          "rolling_resistance",
                                          "bearing_friction_nm",
                                          "bearing_viscous_nm_s",
                                          "lateral_mu_scale",
                                          "handover_dip_m",
                                          "handover_zone_deg",
                                          "half_offset_m",
                                          "rollers",
                                          "encoder",
                                          "suspension",
                                          "motor"};
const std::set<std::string> kSuspensionKeys = {
    "free_length_m", "min_length_m",       "max_length_m",
    "stiffness_n_m", "damping_n_s_m",      "bump_stiffness_n_m",
    "hub_mass_kg",   "tire_stiffness_n_m", "tire_damping_n_s_m"};
const std::set<std::string> kRollerKeys = {"count",
                                           "length_m",
                                           "radius_m",
                                           "rows",
                                           "row_offset_m",
                                           "inertia_kg_m2",
                                           "bearing_friction_nm",
                                           "bearing_viscous_nm_s"};
const std::set<std::string> kMotorKeys = {
    "gear_ratio",          "torque_constant_nm_a", "max_current_a",          "max_torque_nm",
    "rotor_inertia_kg_m2", "supply_voltage_v",     "winding_resistance_ohm", "max_accel_rad_s2",
    "speed_gain_nm_s_rad", "integral_gain_nm_rad"};

// `rollers: continuous` (the default) or a mapping of discrete rollers; keys missing from the
// wheel's mapping come from wheel_defaults.rollers. Defaults apply only to roller wheels.
void ParseRollers(const Reader& rd, const YAML::Node& n, const YAML::Node& defaults,
                  const std::string& prefix, WheelSpec* w) {
  const bool roller_wheel = w->kind == WheelKind::kMecanum || w->kind == WheelKind::kOmni;
  const YAML::Node own = Reader::Get(n, "rollers");
  const std::string field = prefix + "rollers";
  if (own.IsDefined() && !roller_wheel) {
    rd.Fail(own, field, "only mecanum and omni wheels have rollers");
  }
  if (!roller_wheel) return;
  const YAML::Node dflt = Reader::Get(defaults, "rollers");
  auto continuous = [&](const YAML::Node& node) {
    if (!node.IsDefined()) return false;
    if (node.IsScalar()) {
      if (node.Scalar() != "continuous") {
        rd.Fail(node, field, "must be 'continuous' or a mapping {count, length_m, ...}");
      }
      return true;
    }
    if (!node.IsMap())
      rd.Fail(node, field, "must be 'continuous' or a mapping {count, length_m, ...}");
    rd.CheckKeys(node, field, kRollerKeys);
    return false;
  };
  if (continuous(own)) return;
  if (!own.IsDefined() && (!dflt.IsDefined() || continuous(dflt))) return;
  const YAML::Node dmap = dflt.IsDefined() && dflt.IsMap() ? dflt : YAML::Node();
  const YAML::Node map = own.IsDefined() ? own : dmap;
  const YAML::Node fallback = own.IsDefined() ? dmap : YAML::Node();
  const std::string rp = field + ".";
  physics::RollerSpec& r = w->rollers;
  const double count = rd.Value(map, fallback, "count", rp, 3, 64);
  if (count != std::floor(count))
    rd.Fail(Reader::Lookup(map, fallback, "count"), rp + "count", "must be an integer");
  r.count = static_cast<int>(count);
  r.length_m = rd.Value(map, fallback, "length_m", rp, 1e-4, 1);
  r.radius_m = rd.ValueOr(map, fallback, "radius_m", rp, 1e-5, 1, 0.0);
  const double rows = rd.ValueOr(map, fallback, "rows", rp, 1, 2, 1);
  if (rows != 1 && rows != 2)
    rd.Fail(Reader::Lookup(map, fallback, "rows"), rp + "rows", "must be 1 or 2");
  r.rows = static_cast<int>(rows);
  r.row_offset_m = rd.ValueOr(map, fallback, "row_offset_m", rp, 0, 0.5, 0.0);
  if (r.rows == 2 && !Reader::Lookup(map, fallback, "row_offset_m").IsDefined()) {
    rd.Fail(map, rp + "row_offset_m", "is required with rows: 2");
  }
  r.inertia_kg_m2 = rd.ValueOr(map, fallback, "inertia_kg_m2", rp, 0, 1, 0.0);
  r.bearing_friction_nm = rd.ValueOr(map, fallback, "bearing_friction_nm", rp, 0, 10, 0.0);
  r.bearing_viscous_nm_s = rd.ValueOr(map, fallback, "bearing_viscous_nm_s", rp, 0, 10, 0.0);
  try {
    (void)physics::MakeRollerGeometry(*w, "");
  } catch (const std::invalid_argument& e) {
    // "{where}: rollers.field (value) rule": point at the rollers block.
    std::string what = e.what();
    const std::string lead = ": rollers.";
    if (what.rfind(lead, 0) == 0) what = what.substr(lead.size());
    rd.Fail(map, field, what);
  }
}

WheelSpec ParseWheel(const Reader& rd, const YAML::Node& n, const YAML::Node& defaults,
                     const std::string& prefix, bool* encoder) {
  rd.CheckKeys(n, prefix.substr(0, prefix.size() - 1), kWheelKeys);
  WheelSpec w;
  w.name = rd.Text(n, "name", prefix + "name");
  const YAML::Node kind_node = rd.Lookup(n, defaults, "kind");
  if (!kind_node.IsDefined()) rd.Fail(n, prefix + "kind", "is required");
  const std::string kind = rd.ToString(kind_node, prefix + "kind");
  if (kind == "conventional") {
    w.kind = WheelKind::kConventional;
  } else if (kind == "mecanum") {
    w.kind = WheelKind::kMecanum;
  } else if (kind == "omni") {
    w.kind = WheelKind::kOmni;
  } else if (kind == "orthogonal") {
    w.kind = WheelKind::kOrthogonal;
  } else if (kind == "caster") {
    w.kind = WheelKind::kCaster;
  } else {
    rd.Fail(
        kind_node, prefix + "kind",
        fmt::format("'{}' is not one of conventional, mecanum, omni, orthogonal, caster", kind));
  }
  w.mount_B = rd.Vec3(n, "mount_m", prefix + "mount_m");
  w.heading_rad = rd.ValueOr(n, defaults, "heading_deg", prefix, -360, 360, 0) * kDeg;
  w.radius_m = rd.Value(n, defaults, "radius_m", prefix, 1e-3, 2);
  w.inertia_kg_m2 = rd.Value(n, defaults, "inertia_kg_m2", prefix, 1e-9, 100);
  const double def_roller = w.kind == WheelKind::kMecanum ? 45.0 : 90.0;
  w.roller_angle_rad =
      rd.ValueOr(n, defaults, "roller_angle_deg", prefix, -90, 90, def_roller) * kDeg;
  if (w.kind == WheelKind::kMecanum &&
      std::abs(std::abs(w.roller_angle_rad) - 0.25 * std::numbers::pi) > 0.35) {
    rd.Fail(n, prefix + "roller_angle_deg", "a Mecanum roller angle must be near +-45");
  }
  w.rolling_resistance = rd.ValueOr(n, defaults, "rolling_resistance", prefix, 0, 0.5, 0.01);
  w.bearing_friction_nm = rd.ValueOr(n, defaults, "bearing_friction_nm", prefix, 0, 100, 0.001);
  w.bearing_viscous_nm_s = rd.ValueOr(n, defaults, "bearing_viscous_nm_s", prefix, 0, 100, 0.0);
  w.lateral_mu_scale = rd.ValueOr(n, defaults, "lateral_mu_scale", prefix, 0.01, 10, 1.0);
  w.handover_dip_m = rd.ValueOr(n, defaults, "handover_dip_m", prefix, 0, 0.1, 0.0);
  // 90 deg (the default) keeps the rad value bit-exact: the whole-segment dip.
  const double zone_deg = rd.ValueOr(n, defaults, "handover_zone_deg", prefix, 0.1, 90, 90.0);
  w.handover_zone_rad = zone_deg == 90.0 ? 0.5 * std::numbers::pi : zone_deg * kDeg;
  w.half_offset_m = rd.ValueOr(n, defaults, "half_offset_m", prefix, 0, 0.2, 0.0);
  ParseRollers(rd, n, defaults, prefix, &w);
  const YAML::Node enc = rd.Lookup(n, defaults, "encoder");
  *encoder = false;
  if (enc.IsDefined()) {
    if (!enc.IsScalar() || (enc.Scalar() != "true" && enc.Scalar() != "false")) {
      rd.Fail(enc, prefix + "encoder", "must be true or false");
    }
    *encoder = enc.Scalar() == "true";
  }

  const YAML::Node susp = n["suspension"];
  const YAML::Node dsusp =
      defaults.IsDefined() && defaults.IsMap() ? defaults["suspension"] : YAML::Node();
  if (susp.IsDefined()) rd.CheckKeys(susp, prefix + "suspension", kSuspensionKeys);
  if (!susp.IsDefined() && !dsusp.IsDefined()) rd.Fail(n, prefix + "suspension", "missing");
  const std::string sp = prefix + "suspension.";
  auto& q = w.suspension;
  q.free_length_m = rd.Value(susp, dsusp, "free_length_m", sp, 1e-4, 2);
  q.min_length_m = rd.Value(susp, dsusp, "min_length_m", sp, 0, 2);
  q.max_length_m = rd.Value(susp, dsusp, "max_length_m", sp, 1e-4, 2);
  if (q.min_length_m >= q.max_length_m) {
    rd.Fail(susp.IsDefined() ? susp : n, sp + "min_length_m", "must be below max_length_m");
  }
  q.stiffness_n_m = rd.Value(susp, dsusp, "stiffness_n_m", sp, 1e-3, 1e8);
  q.damping_n_s_m = rd.Value(susp, dsusp, "damping_n_s_m", sp, 0, 1e6);
  q.bump_stiffness_n_m =
      rd.ValueOr(susp, dsusp, "bump_stiffness_n_m", sp, 0, 1e9, 10 * q.stiffness_n_m);
  q.hub_mass_kg = rd.Value(susp, dsusp, "hub_mass_kg", sp, 1e-4, 100);
  q.tire_stiffness_n_m =
      rd.ValueOr(susp, dsusp, "tire_stiffness_n_m", sp, 1, 1e9, q.tire_stiffness_n_m);
  q.tire_damping_n_s_m =
      rd.ValueOr(susp, dsusp, "tire_damping_n_s_m", sp, 0, 1e6, q.tire_damping_n_s_m);

  const YAML::Node motor = n["motor"];
  w.driven = motor.IsDefined() && !motor.IsNull();
  if (w.driven) {
    rd.CheckKeys(motor, prefix + "motor", kMotorKeys);
    const YAML::Node dmotor =
        defaults.IsDefined() && defaults.IsMap() ? defaults["motor"] : YAML::Node();
    const std::string mp = prefix + "motor.";
    auto& m = w.motor;
    m.gear_ratio = rd.Value(motor, dmotor, "gear_ratio", mp, 1e-3, 1e4);
    m.torque_constant_nm_a = rd.Value(motor, dmotor, "torque_constant_nm_a", mp, 1e-6, 100);
    m.max_current_a = rd.Value(motor, dmotor, "max_current_a", mp, 1e-6, 1e4);
    m.max_torque_nm = rd.ValueOr(motor, dmotor, "max_torque_nm", mp, 1e-6, 1e6, 1e6);
    m.rotor_inertia_kg_m2 = rd.ValueOr(motor, dmotor, "rotor_inertia_kg_m2", mp, 0, 10, 0);
    m.supply_voltage_v = rd.ValueOr(motor, dmotor, "supply_voltage_v", mp, 1e-3, 1e4, 24);
    m.winding_resistance_ohm = rd.ValueOr(motor, dmotor, "winding_resistance_ohm", mp, 0, 1e4, 0);
    m.max_accel_rad_s2 = rd.ValueOr(motor, dmotor, "max_accel_rad_s2", mp, 0, 1e6, 0);
    m.speed_gain_nm_s_rad =
        rd.ValueOr(motor, dmotor, "speed_gain_nm_s_rad", mp, 1e-6, 1e6, m.speed_gain_nm_s_rad);
    m.integral_gain_nm_rad =
        rd.ValueOr(motor, dmotor, "integral_gain_nm_rad", mp, 0, 1e8, m.integral_gain_nm_rad);
    if (w.kind == WheelKind::kCaster) rd.Fail(motor, prefix + "motor", "a caster cannot be driven");
  }
  return w;
}

}  // namespace

double Platform::parameter(const std::string& key) const {
  for (const auto& [k, v] : parameters) {
    if (k == key) return v;
  }
  throw std::invalid_argument(fmt::format("{}: kinematics.{}: missing", source_file, key));
}

std::size_t Platform::wheel_index(const std::string& wheel_name) const {
  for (std::size_t i = 0; i < vehicle.wheels.size(); ++i) {
    if (vehicle.wheels[i].name == wheel_name) return i;
  }
  throw std::invalid_argument(fmt::format("{}: wheel '{}' not found", source_file, wheel_name));
}

namespace {

// Deep merge of `over` into `base` (both mappings); see LoadPlatformFile. `field` names the
// position for errors ("" at the document root).
void MergeOverrides(YAML::Node base, const YAML::Node& over, const std::string& field,
                    const Reader& rd) {
  const std::string name = field.empty() ? "overrides" : field;
  if (!over.IsMap()) rd.Fail(over, name, "must be a mapping");
  for (const auto& kv : over) {
    const std::string key = rd.KeyName(kv.first, name);
    const std::string here = field.empty() ? key : field + "." + key;
    const YAML::Node value = kv.second;
    if (field.empty() && key == "wheels") {
      YAML::Node wheels = base["wheels"];
      if (!wheels.IsDefined() || !wheels.IsSequence())
        rd.Fail(value, here, "file has no wheel list");
      if (!value.IsMap()) rd.Fail(value, here, "must map wheel names (or globs) to overrides");
      for (const auto& w : value) {
        const std::string pattern = rd.KeyName(w.first, here);
        std::size_t matched = 0;
        for (std::size_t i = 0; i < wheels.size(); ++i) {
          const YAML::Node name = wheels[i]["name"];
          if (name.IsDefined() && name.IsScalar() &&
              ::fnmatch(pattern.c_str(), name.Scalar().c_str(), 0) == 0) {
            MergeOverrides(wheels[i], w.second, fmt::format("wheels[{}]", i), rd);
            ++matched;
          }
        }
        if (matched == 0) rd.Fail(w.first, here + "." + pattern, "matches no wheel name");
      }
      continue;
    }
    YAML::Node target = base[key];
    if (value.IsMap() && target.IsDefined() && target.IsMap()) {
      MergeOverrides(target, value, here, rd);
    } else {
      base[key] = YAML::Clone(value);
    }
  }
}

Platform ReadPlatform(const Reader& rd, const YAML::Node& root) {
  rd.CheckKeys(root, "",
               {"name", "description", "paper", "chassis", "wheel_defaults", "wheels", "kinematics",
                "sensors", "solver", "tolerances"});
  Platform p;
  p.source_file = rd.file();
  p.name = rd.Text(root, "name", "name");
  if (root["description"]) p.description = rd.Text(root, "description", "description");
  auto& v = p.vehicle;
  v.name = p.name;

  const YAML::Node ch = root["chassis"];
  if (!ch.IsDefined()) rd.Fail(root, "chassis", "missing");
  rd.CheckKeys(ch, "chassis", {"mass_kg", "inertia_kg_m2", "half_extents_m", "mesh"});
  const YAML::Node none;
  v.mass_kg = rd.Value(ch, none, "mass_kg", "chassis.", 1e-3, 1e5);
  v.inertia_kg_m2 = rd.Vec3(ch, "inertia_kg_m2", "chassis.inertia_kg_m2");
  for (int k = 0; k < 3; ++k) {
    if (!(v.inertia_kg_m2[k] > 0)) {
      rd.Fail(ch["inertia_kg_m2"], fmt::format("chassis.inertia_kg_m2[{}]", k), "must be > 0");
    }
  }
  v.half_extents_m = rd.Vec3(ch, "half_extents_m", "chassis.half_extents_m");
  if (ch["mesh"]) p.chassis_mesh = rd.Text(ch, "mesh", "chassis.mesh");

  if (const YAML::Node s = root["solver"]; s.IsDefined()) {
    rd.CheckKeys(s, "solver", {"slip_threshold_m_s", "stribeck_velocity_m_s", "iterations"});
    v.slip_threshold_m_s =
        rd.ValueOr(s, none, "slip_threshold_m_s", "solver.", 1e-6, 10, v.slip_threshold_m_s);
    v.stribeck_velocity_m_s =
        rd.ValueOr(s, none, "stribeck_velocity_m_s", "solver.", 1e-6, 10, v.stribeck_velocity_m_s);
    v.solver_iterations = static_cast<int>(
        rd.ValueOr(s, none, "iterations", "solver.", 1, 1000, v.solver_iterations));
  }

  const YAML::Node defaults = root["wheel_defaults"];
  const YAML::Node wheels = root["wheels"];
  if (!wheels.IsDefined()) rd.Fail(root, "wheels", "missing");
  if (!wheels.IsSequence() || wheels.size() == 0)
    rd.Fail(wheels, "wheels", "must be a non-empty list");
  if (wheels.size() > 32) rd.Fail(wheels, "wheels", "at most 32 wheels");
  std::set<std::string> names;
  for (std::size_t i = 0; i < wheels.size(); ++i) {
    bool encoder = false;
    const std::string prefix = fmt::format("wheels[{}].", i);
    WheelSpec w = ParseWheel(rd, wheels[i], defaults, prefix, &encoder);
    if (!names.insert(w.name).second) {
      rd.Fail(wheels[i]["name"], prefix + "name", fmt::format("duplicate wheel name '{}'", w.name));
    }
    if (encoder || w.driven) p.encoder_wheels.push_back(i);
    if (w.driven) p.drive_wheels.push_back(i);
    v.wheels.push_back(std::move(w));
  }

  const YAML::Node kin = root["kinematics"];
  if (!kin.IsDefined()) rd.Fail(root, "kinematics", "missing");
  if (!kin.IsMap()) rd.Fail(kin, "kinematics", "must be a mapping");
  const std::string type = rd.Text(kin, "type", "kinematics.type");
  if (type == "diff_drive") {
    p.kinematics = KinematicsKind::kDiffDrive;
  } else if (type == "mecanum4") {
    p.kinematics = KinematicsKind::kMecanum4;
  } else if (type == "omni3") {
    p.kinematics = KinematicsKind::kOmni3;
  } else {
    rd.Fail(kin["type"], "kinematics.type",
            fmt::format("'{}' is not one of diff_drive, mecanum4, omni3", type));
  }
  for (const auto& kv : kin) {
    const std::string key = rd.KeyName(kv.first, "kinematics");
    if (key == "type") continue;
    // Every length of the layout divides something in the kinematics (a zero track width
    // turns a heading into inf), so lengths are positive and of robot size.
    const bool length = key.size() > 2 && key.compare(key.size() - 2, 2, "_m") == 0;
    p.parameters.emplace_back(key, length ? rd.ToNumber(kv.second, "kinematics." + key, 1e-4, 100.0)
                                          : rd.ToNumber(kv.second, "kinematics." + key));
  }
  const std::size_t expected_drive = p.kinematics == KinematicsKind::kDiffDrive  ? 2
                                     : p.kinematics == KinematicsKind::kMecanum4 ? 4
                                                                                 : 3;
  if (p.drive_wheels.size() != expected_drive) {
    rd.Fail(kin["type"], "kinematics.type",
            fmt::format("{} needs {} driven wheels (with a motor:), found {}", type, expected_drive,
                        p.drive_wheels.size()));
  }

  if (const YAML::Node sensors = root["sensors"]; sensors.IsDefined()) {
    if (!sensors.IsSequence()) rd.Fail(sensors, "sensors", "must be a list");
    for (std::size_t i = 0; i < sensors.size(); ++i) {
      const std::string prefix = fmt::format("sensors[{}].", i);
      rd.CheckKeys(sensors[i], fmt::format("sensors[{}]", i), {"name", "kind", "mount_m", "axis"});
      SensorMount s;
      s.name = rd.Text(sensors[i], "name", prefix + "name");
      s.kind = rd.Text(sensors[i], "kind", prefix + "kind");
      s.position_B = rd.Vec3(sensors[i], "mount_m", prefix + "mount_m");
      if (sensors[i]["axis"]) {
        s.axis_B = rd.Vec3(sensors[i], "axis", prefix + "axis");
        if (s.axis_B.norm() < 1e-9)
          rd.Fail(sensors[i]["axis"], prefix + "axis", "must be non-zero");
        s.axis_B.normalize();
      }
      p.sensors.push_back(s);
    }
  }
  if (const YAML::Node t = root["tolerances"]; t.IsDefined()) {
    rd.CheckKeys(t, "tolerances", {"radius_m", "mount_m", "heading_deg", "roller_angle_deg"});
    auto& tol = p.tolerances;
    tol.radius_m = rd.ValueOr(t, none, "radius_m", "tolerances.", 0, 0.01, 0);
    tol.mount_m = rd.ValueOr(t, none, "mount_m", "tolerances.", 0, 0.05, 0);
    tol.heading_rad = rd.ValueOr(t, none, "heading_deg", "tolerances.", 0, 5, 0) * kDeg;
    tol.roller_angle_rad = rd.ValueOr(t, none, "roller_angle_deg", "tolerances.", 0, 5, 0) * kDeg;
    for (std::size_t i = 0; i < v.wheels.size(); ++i) {
      if (tol.radius_m >= 0.1 * v.wheels[i].radius_m) {
        rd.Fail(t["radius_m"], "tolerances.radius_m",
                fmt::format("must be below a tenth of the smallest wheel radius ({} m, wheel '{}')",
                            v.wheels[i].radius_m, v.wheels[i].name));
      }
    }
  }
  try {
    physics::ValidateVehicleSpec(v, "vehicle");
  } catch (const std::invalid_argument& e) {
    // A rule across several values: no one position to point at.
    throw std::invalid_argument(fmt::format("{}: {}", rd.Where(YAML::Mark::null_mark()), e.what()));
  }
  return p;
}

}  // namespace

Platform LoadPlatformYaml(const std::string& text, const std::string& file,
                          const YAML::Node& overrides) {
  const Reader rd(file);
  return rd.Guard([&] {
    YAML::Node root = rd.Parse(text);
    if (!root.IsMap()) rd.Fail(root, "(document)", "must be a mapping");
    if (overrides.IsDefined() && !overrides.IsNull()) MergeOverrides(root, overrides, "", rd);
    ImportRobotDescription(root, rd);
    return ReadPlatform(rd, root);
  });
}

Platform LoadPlatformFile(const std::string& path, const YAML::Node& overrides) {
  return LoadPlatformYaml(Reader(path).ReadFile(), path, overrides);
}

std::vector<WheelDeviation> DrawWheelDeviations(const Platform& p, std::uint64_t seed) {
  std::mt19937_64 rng(seed ^ 0x70E2A4CEull);
  // Uniform in [-limit, limit] from the generator's bits (the standard distributions' algorithms
  // are the library's own; this is the same everywhere).
  auto draw = [&](double limit) {
    const double u = static_cast<double>(rng() >> 11) * 0x1.0p-53;
    return limit * (2 * u - 1);
  };
  const PlatformTolerances& t = p.tolerances;
  std::vector<WheelDeviation> out(p.vehicle.wheels.size());
  for (std::size_t i = 0; i < out.size(); ++i) {
    const WheelSpec& w = p.vehicle.wheels[i];
    WheelDeviation& d = out[i];
    d.radius_m = draw(t.radius_m);
    d.mount_x_m = draw(t.mount_m);
    d.mount_y_m = draw(t.mount_m);
    d.heading_rad = draw(t.heading_rad);
    const double roller = draw(t.roller_angle_rad);
    if (w.kind == WheelKind::kMecanum || w.kind == WheelKind::kOmni) d.roller_angle_rad = roller;
  }
  return out;
}

physics::VehicleSpec AsBuilt(const physics::VehicleSpec& nominal,
                             const std::vector<WheelDeviation>& deviations) {
  physics::VehicleSpec v = nominal;
  for (std::size_t i = 0; i < v.wheels.size() && i < deviations.size(); ++i) {
    WheelSpec& w = v.wheels[i];
    const WheelDeviation& d = deviations[i];
    w.radius_m += d.radius_m;
    w.mount_B.x() += d.mount_x_m;
    w.mount_B.y() += d.mount_y_m;
    w.heading_rad += d.heading_rad;
    w.roller_angle_rad += d.roller_angle_rad;
  }
  return v;
}

double WheelSpeedForTwist(const WheelSpec& w, const BodyTwist& t) noexcept {
  const double px = w.mount_B.x(), py = w.mount_B.y();
  const double vx = t.vx_m_s - t.wz_rad_s * py;
  const double vy = t.vy_m_s + t.wz_rad_s * px;
  const double fx = std::cos(w.heading_rad), fy = std::sin(w.heading_rad);
  const double ax = -fy, ay = fx;
  switch (w.kind) {
    case WheelKind::kConventional:
      return (vx * fx + vy * fy) / w.radius_m;
    case WheelKind::kMecanum:
    case WheelKind::kOmni:
    case WheelKind::kOrthogonal: {
      const double ca = std::cos(w.roller_angle_rad), sa = std::sin(w.roller_angle_rad);
      const double ux = ca * ax + sa * fx, uy = ca * ay + sa * fy;
      return (vx * ux + vy * uy) / (w.radius_m * sa);
    }
    case WheelKind::kCaster:
      return 0.0;
  }
  return 0.0;
}

double RimSpeedForTwist(const WheelSpec& w, const BodyTwist& t) noexcept {
  return WheelSpeedForTwist(w, t) * w.radius_m;
}

std::vector<double> InverseKinematics(const Platform& p, const BodyTwist& t) {
  std::vector<double> out(p.vehicle.wheels.size(), 0.0);
  for (std::size_t i : p.drive_wheels) out[i] = WheelSpeedForTwist(p.vehicle.wheels[i], t);
  return out;
}

void CommandTwist(physics::RollerVehicle& vehicle, const Platform& p, const BodyTwist& t) noexcept {
  for (std::size_t i : p.drive_wheels) {
    (void)vehicle.SetWheelSpeedCommand(i, WheelSpeedForTwist(p.vehicle.wheels[i], t));
  }
}

}  // namespace wheelhil::emulator::platforms
