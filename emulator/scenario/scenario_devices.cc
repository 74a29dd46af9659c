// The scenario loader's `devices:` list (emulator/scenario/scenario.h, docs/own-hardware.md).
#include <algorithm>
#include <cctype>
#include <charconv>
#include <functional>
#include <map>
#include <memory>
#include <set>

#include <fmt/format.h>

#include "bus/canopen_eds.h"
#include "bus/dbc.h"
#include "emulator/devices/checksum_yaml.h"
#include "emulator/devices/cia402_eds.h"
#include "emulator/devices/cia406_eds.h"
#include "emulator/scenario/internal/scenario_reader.h"

namespace wheelhil::emulator::scenario::internal {

namespace {

Eigen::Vector3d ReadVector3(const Reader& r, const YAML::Node& parent, const std::string& key,
                            const std::string& prefix, double limit) {
  Eigen::Vector3d v = Eigen::Vector3d::Zero();
  const YAML::Node n = Reader::Get(parent, key);
  if (!Reader::Present(n)) return v;
  const std::string f = Reader::Join(prefix, key);
  if (!n.IsSequence() || n.size() != 3) r.Fail(n, f, "must be [x, y, z]");
  for (std::size_t i = 0; i < 3; ++i) {
    v[static_cast<int>(i)] = r.ToNumber(n[i], fmt::format("{}[{}]", f, i), -limit, limit);
  }
  return v;
}

// `mount: {xyz_m: [x, y, z], rpy_deg: [roll, pitch, yaw]}` on the body frame B.
void ReadMount(const Reader& r, const YAML::Node& n, const std::string& f, DbcDeviceConfig& c) {
  const YAML::Node m = Reader::Get(n, "mount");
  if (!Reader::Present(m)) return;
  const std::string mf = f + ".mount";
  r.CheckKeys(m, mf, {"xyz_m", "rpy_deg"});
  c.r_BS_B = ReadVector3(r, m, "xyz_m", mf, 10);
  c.R_BS = MountRotation(ReadVector3(r, m, "rpy_deg", mf, 360));
}

// One `signals:` entry: `NAME: quantity` or `NAME: {quantity, ...}`; NAME is a signal of any
// message of the node, or MESSAGE.SIGNAL.
DbcSignalBinding ReadSignal(const Reader& r, const YAML::Node& key, const YAML::Node& v,
                            const std::string& prefix, const platforms::Platform& platform) {
  DbcSignalBinding b;
  const std::string name = r.ToString(key, prefix);
  b.field = Reader::Join(prefix, name);
  if (const auto dot = name.find('.'); dot != std::string::npos) {
    b.message = name.substr(0, dot);
    b.signal = name.substr(dot + 1);
  } else {
    b.signal = name;
  }
  const YAML::Node q = v.IsMap() ? Reader::Get(v, "quantity") : v;
  if (!Reader::Present(q)) r.Fail(v, b.field + ".quantity", "is required");
  const std::string qs = r.ToString(q, b.field);
  const auto quantity = ParseDbcQuantity(qs);
  if (!quantity) {
    r.Fail(q, b.field, fmt::format("'{}' is not one of {}", qs, DbcQuantityNames()));
  }
  b.quantity = *quantity;
  const bool wheel_quantity =
      b.quantity == DbcQuantity::kWheelAngle || b.quantity == DbcQuantity::kWheelSpeed ||
      b.quantity == DbcQuantity::kWheelSpeedSetpoint || b.quantity == DbcQuantity::kDriveEnable ||
      b.quantity == DbcQuantity::kMotorCurrent || b.quantity == DbcQuantity::kMotorTorque;
  if (!v.IsMap()) {
    if (wheel_quantity || b.quantity == DbcQuantity::kConstant ||
        b.quantity == DbcQuantity::kChecksum) {
      r.Fail(v, b.field,
             fmt::format("{} needs a mapping ({{quantity: {}, {}}})", qs, qs,
                         b.quantity == DbcQuantity::kConstant   ? "value: V"
                         : b.quantity == DbcQuantity::kChecksum ? "type: T"
                                                                : "wheel: W"));
    }
    return b;
  }
  std::set<std::string> keys{"quantity", "gain"};
  switch (b.quantity) {
    case DbcQuantity::kWheelAngle:
      keys.insert({"wheel", "counts_per_rev"});
      break;
    case DbcQuantity::kWheelSpeed:
    case DbcQuantity::kWheelSpeedSetpoint:
    case DbcQuantity::kMotorCurrent:
    case DbcQuantity::kMotorTorque:
      keys.insert("wheel");
      break;
    case DbcQuantity::kDriveEnable:
      keys = {"quantity", "wheel"};
      break;
    case DbcQuantity::kConstant:
      keys = {"quantity", "value"};
      break;
    case DbcQuantity::kCounter:
      keys = {"quantity", "step", "modulo", "shared"};
      break;
    case DbcQuantity::kChecksum:
      keys = ChecksumSpecKeys();
      keys.insert("quantity");
      break;
    default:
      break;
  }
  r.CheckKeys(v, b.field, keys);
  b.gain = r.Number(v, "gain", b.field, -1e9, 1e9, 1.0);
  if (wheel_quantity) {
    const std::string wheel = r.String(v, "wheel", b.field, std::nullopt);
    try {
      b.wheel_index = platform.wheel_index(wheel);
    } catch (const std::exception&) {
      r.Fail(v["wheel"], b.field + ".wheel",
             fmt::format("platform {} has no wheel '{}'", platform.name, wheel));
    }
    b.counts_per_rev = r.Number(v, "counts_per_rev", b.field, 1, 1e9, 0.0);
    const physics::WheelSpec& w = platform.vehicle.wheels[b.wheel_index];
    const bool needs_motor =
        b.quantity != DbcQuantity::kWheelAngle && b.quantity != DbcQuantity::kWheelSpeed;
    if (needs_motor && !w.driven) {
      r.Fail(v["wheel"], b.field + ".wheel",
             fmt::format("wheel '{}' of platform {} has no motor ({} is a driven wheel's)", wheel,
                         platform.name, qs));
    }
    if (w.driven) b.motor_torque_limit_nm = w.motor.TorqueLimitNm();
  }
  if (b.quantity == DbcQuantity::kConstant) b.value = r.Number(v, "value", b.field, -1e15, 1e15);
  if (b.quantity == DbcQuantity::kCounter) {
    b.counter_step = r.Integer(v, "step", b.field, -65535, 65535, 1);
    if (Reader::Present(Reader::Get(v, "modulo"))) {
      b.counter_modulo = static_cast<std::uint64_t>(r.Integer(v, "modulo", b.field, 2, 1LL << 32));
    }
    b.counter_shared = r.Bool(v, "shared", b.field, false);
  }
  if (b.quantity == DbcQuantity::kChecksum) b.checksum = ReadChecksumSpec(r, v, b.field);
  return b;
}

void ReadSensorModels(const Reader& r, const YAML::Node& n, const std::string& f,
                      DbcDeviceConfig& c);

// The shipped MM5.10 as a `dbc` device: its six signals bound (bus/dbc/bosch_mm5_10.dbc).
DeviceSpec ReadMm5Device(const Reader& r, const YAML::Node& n, const std::string& f) {
  r.CheckKeys(n, f, {"kind", "name", "mount", "messages", "gyro", "accel"});
  DeviceSpec d;
  d.kind = DeviceSpec::Kind::kMm5_10;
  d.dbc = "${DBC_DIR}/bosch_mm5_10.dbc";
  DbcDeviceConfig& c = d.dbc_device;
  c.field = f;
  c.node = "MM5_10";
  c.name = r.String(n, "name", f, std::string("mm5_10"));
  ReadMount(r, n, f, c);
  const std::pair<const char*, DbcQuantity> kSignals[] = {
      {"MM5_YawRate", DbcQuantity::kRateZ},   {"MM5_AccelY", DbcQuantity::kAccelY},
      {"MM5_RollRate", DbcQuantity::kRateX},  {"MM5_AccelX", DbcQuantity::kAccelX},
      {"MM5_PitchRate", DbcQuantity::kRateY}, {"MM5_AccelZ", DbcQuantity::kAccelZ}};
  for (const auto& [signal, quantity] : kSignals) {
    DbcSignalBinding b;
    b.signal = signal;
    b.quantity = quantity;
    b.field = fmt::format("{}.{}", f, signal);
    c.signals.push_back(b);
  }
  ReadSensorModels(r, n, f, c);
  return d;
}

DeviceSpec ReadDbcDevice(const Reader& r, const YAML::Node& n, const std::string& f,
                         const platforms::Platform& platform) {
  r.CheckKeys(n, f,
              {"kind", "name", "dbc", "node", "mount", "signals", "messages", "gyro", "accel",
               "temperature_c", "setpoint_timeout_ms"});
  DeviceSpec d;
  d.kind = DeviceSpec::Kind::kDbc;
  DbcDeviceConfig& c = d.dbc_device;
  c.field = f;
  c.node = r.String(n, "node", f, std::nullopt);
  c.name = r.String(n, "name", f, c.node);
  d.dbc = r.Path(r.String(n, "dbc", f, std::nullopt));
  ReadMount(r, n, f, c);
  std::map<std::string, YAML::Node> where;  // field -> node, for the device's own errors
  const YAML::Node sigs = Reader::Get(n, "signals");
  if (!sigs.IsMap() || sigs.size() == 0) {
    r.FailKey(n, "signals", f + ".signals", "must map signal names to quantities");
  }
  for (auto it = sigs.begin(); it != sigs.end(); ++it) {
    c.signals.push_back(ReadSignal(r, it->first, it->second, f + ".signals", platform));
    where[c.signals.back().field] = it->first;
  }
  ReadSensorModels(r, n, f, c);
  for (const DbcMessageTiming& t : c.timing) where[t.field] = n["messages"];
  c.temperature_k = r.Number(n, "temperature_c", f, -100, 300, 25.0) + 273.15;
  c.setpoint_timeout_s = r.Number(n, "setpoint_timeout_ms", f, 0, 1e6, 0.0) * 1e-3;
  // The bindings against the DBC, now: an error names the entry's line.
  const auto db = LoadDbcAt(r, n, "dbc", f + ".dbc", d.dbc);
  try {
    (void)DbcDevice(db, c);
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    const auto colon = what.find(": ");
    const std::string field = colon == std::string::npos ? f : what.substr(0, colon);
    const auto at = where.find(field);
    r.Fail(at != where.end() ? at->second : n, field,
           colon == std::string::npos ? what : what.substr(colon + 2));
  }
  return d;
}

// `messages`, `gyro`, `accel` of a dbc-based device.
void ReadSensorModels(const Reader& r, const YAML::Node& n, const std::string& f,
                      DbcDeviceConfig& c) {
  if (const YAML::Node ms = Reader::Get(n, "messages"); Reader::Present(ms)) {
    if (!ms.IsMap()) r.Fail(ms, f + ".messages", "must map message names to timings");
    for (auto it = ms.begin(); it != ms.end(); ++it) {
      DbcMessageTiming t;
      t.message = r.ToString(it->first, f + ".messages");
      t.field = fmt::format("{}.messages.{}", f, t.message);
      r.CheckKeys(it->second, t.field, {"cycle_time_ms", "phase_ms", "start_delay_ms"});
      if (Reader::Present(Reader::Get(it->second, "cycle_time_ms"))) {
        t.cycle_time_ms = r.Number(it->second, "cycle_time_ms", t.field, 0.01, 3.6e6);
      }
      t.phase_ms = r.Number(it->second, "phase_ms", t.field, 0, 3.6e6, 0.0);
      if (Reader::Present(Reader::Get(it->second, "start_delay_ms"))) {
        t.start_delay_ms = r.Number(it->second, "start_delay_ms", t.field, 0, 3.6e6);
      }
      c.timing.push_back(t);
    }
  }
  if (const YAML::Node g = Reader::Get(n, "gyro"); Reader::Present(g)) {
    const std::string gf = f + ".gyro";
    r.CheckKeys(g, gf,
                {"noise_density_rad_s_sqrt_hz", "bias_rad_s", "bias_random_walk_rad_s_sqrt_s",
                 "scale_factor_error"});
    c.gyro.noise_density_rad_s_sqrt_hz = r.Number(g, "noise_density_rad_s_sqrt_hz", gf, 0, 1, 0.0);
    c.gyro.bias_rad_s = r.Number(g, "bias_rad_s", gf, -10, 10, 0.0);
    c.gyro.bias_random_walk_rad_s_sqrt_s =
        r.Number(g, "bias_random_walk_rad_s_sqrt_s", gf, 0, 1, 0.0);
    c.gyro.scale_factor_error = r.Number(g, "scale_factor_error", gf, -0.5, 0.5, 0.0);
  }
  if (const YAML::Node a = Reader::Get(n, "accel"); Reader::Present(a)) {
    const std::string af = f + ".accel";
    r.CheckKeys(a, af, {"noise_density_m_s2_sqrt_hz", "bias_m_s2"});
    c.accel.noise_density_m_s2_sqrt_hz = r.Number(a, "noise_density_m_s2_sqrt_hz", af, 0, 10, 0.0);
    const double bias = r.Number(a, "bias_m_s2", af, -10, 10, 0.0);
    if (bias != 0) c.accel.bias_m_s2.assign(3, bias);
  }
}

// `objects: {"0x6200": 10, "0x1018sub4": 1234}` after the EDS.
// `set` stores one object's value (throws std::invalid_argument when the device has none such).
void ReadObjects(const Reader& r, const YAML::Node& n, const std::string& f,
                 const std::function<void(std::uint16_t, std::uint8_t, std::uint32_t)>& set) {
  const YAML::Node objs = Reader::Get(n, "objects");
  if (!Reader::Present(objs)) return;
  if (!objs.IsMap())
    r.Fail(objs, f + ".objects", "must map \"0xINDEX\" or \"0xINDEXsubN\" to values");
  for (auto it = objs.begin(); it != objs.end(); ++it) {
    const std::string key = r.ToString(it->first, f + ".objects");
    const std::string kf = f + ".objects." + key;
    std::string text = key;
    std::transform(text.begin(), text.end(), text.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    if (text.starts_with("0x")) text = text.substr(2);
    const auto sub_at = text.find("sub");
    unsigned index = 0, sub = 0;
    const std::string idx = text.substr(0, sub_at);
    const auto r1 = std::from_chars(idx.data(), idx.data() + idx.size(), index, 16);
    bool ok = idx.size() == 4 && r1.ec == std::errc() && r1.ptr == idx.data() + idx.size();
    if (ok && sub_at != std::string::npos) {
      const std::string sv = text.substr(sub_at + 3);
      const auto r2 = std::from_chars(sv.data(), sv.data() + sv.size(), sub, 10);
      ok = !sv.empty() && r2.ec == std::errc() && r2.ptr == sv.data() + sv.size() && sub <= 255;
    }
    if (!ok) r.Fail(it->first, kf, "is not an object: write \"0x6200\" or \"0x1018sub4\"");
    const auto value = static_cast<std::uint32_t>(r.ToInteger(it->second, kf, 0, 0xFFFFFFFFLL));
    try {
      set(static_cast<std::uint16_t>(index), static_cast<std::uint8_t>(sub), value);
    } catch (const std::invalid_argument& e) {
      r.Fail(it->first, kf, e.what());
    }
  }
}

DeviceSpec ReadCia406Device(const Reader& r, const YAML::Node& n, const std::string& f,
                            const platforms::Platform& platform) {
  r.CheckKeys(n, f,
              {"kind", "wheel", "node_id", "direction", "lines_per_rev", "quadrature_x4", "eds",
               "objects"});
  DeviceSpec d;
  d.kind = DeviceSpec::Kind::kCanopenCia406;
  d.encoder.wheel = r.String(n, "wheel", f, std::nullopt);
  try {
    (void)platform.wheel_index(d.encoder.wheel);
  } catch (const std::exception&) {
    r.Fail(n["wheel"], f + ".wheel",
           fmt::format("platform {} has no wheel '{}'", platform.name, d.encoder.wheel));
  }
  d.eds = r.String(n, "eds", f, std::string());
  const bool have_id = Reader::Present(Reader::Get(n, "node_id"));
  if (!have_id && d.eds.empty()) r.FailKey(n, "node_id", f + ".node_id", "is required");
  d.encoder.node_id = have_id ? static_cast<int>(r.Integer(n, "node_id", f, 1, 127)) : 0;
  d.encoder.direction = static_cast<int>(r.Integer(n, "direction", f, -1, 1, 1));
  if (d.encoder.direction == 0) r.Fail(n["direction"], f + ".direction", "must be 1 or -1");
  d.quadrature_x4 = r.Bool(n, "quadrature_x4", f, true);
  std::optional<std::uint32_t> eds_counts;
  if (!d.eds.empty()) {
    d.eds = r.Path(d.eds);
    try {
      const bus::EdsFile eds = bus::EdsFile::LoadFile(d.eds);
      d.eds_node.node_id = static_cast<std::uint8_t>(d.encoder.node_id);
      eds_counts = ApplyCia406Eds(eds, d.eds_node).counts_per_rev;
      d.encoder.node_id = d.eds_node.node_id;
    } catch (const std::invalid_argument& e) {
      r.FailKey(n, "eds", f + ".eds", e.what());
    }
    ReadObjects(r, n, f, [&](std::uint16_t index, std::uint8_t sub, std::uint32_t value) {
      SetCia406Object(d.eds_node, index, sub, value);
    });
  } else if (Reader::Present(Reader::Get(n, "objects"))) {
    r.Fail(n["objects"], f + ".objects", "needs an eds (the objects it sets are the EDS's)");
  }
  const int per_line = d.quadrature_x4 ? 4 : 1;
  if (eds_counts && Reader::Present(Reader::Get(n, "lines_per_rev")) &&
      static_cast<std::uint64_t>(r.Integer(n, "lines_per_rev", f, 1, 10'000'000)) * per_line !=
          *eds_counts) {
    r.Fail(n["lines_per_rev"], f + ".lines_per_rev",
           fmt::format("disagrees with the EDS's 0x6001 ({} counts per revolution)", *eds_counts));
  }
  if (eds_counts && *eds_counts % per_line != 0) {
    r.FailKey(n, "eds", f + ".eds",
              fmt::format("0x6001 = {} counts per revolution is not a whole number of {}-count "
                          "lines (quadrature_x4: {})",
                          *eds_counts, per_line, d.quadrature_x4));
  }
  d.lines_per_rev = eds_counts
                        ? static_cast<int>(*eds_counts / per_line)
                        : static_cast<int>(r.Integer(n, "lines_per_rev", f, 1, 10'000'000, 500));
  return d;
}

// A CiA 402 drive on a driven wheel; its units and limits default to the wheel's motor.
DeviceSpec ReadCia402Device(const Reader& r, const YAML::Node& n, const std::string& f,
                            const platforms::Platform& platform) {
  r.CheckKeys(n, f,
              {"kind", "name", "wheel", "node_id", "eds", "objects", "velocity_unit",
               "counts_per_rev", "gear_ratio", "trip_current_a", "trip_time_s"});
  DeviceSpec d;
  d.kind = DeviceSpec::Kind::kCanopenCia402;
  Cia402DriveDeviceConfig& c = d.drive;
  c.wheel_name = r.String(n, "wheel", f, std::nullopt);
  try {
    c.wheel_index = platform.wheel_index(c.wheel_name);
  } catch (const std::exception&) {
    r.Fail(n["wheel"], f + ".wheel",
           fmt::format("platform {} has no wheel '{}'", platform.name, c.wheel_name));
  }
  const physics::WheelSpec& wheel = platform.vehicle.wheels[c.wheel_index];
  if (!wheel.driven) {
    r.Fail(n["wheel"], f + ".wheel",
           fmt::format("wheel '{}' of platform {} has no motor: a drive powers a driven wheel",
                       c.wheel_name, platform.name));
  }
  const physics::MotorSpec& m = wheel.motor;
  c.motor_torque_limit_nm = m.TorqueLimitNm();
  Cia402DriveConfig& node = c.node;
  node.gear_ratio = r.Number(n, "gear_ratio", f, 1e-3, 1e4, m.gear_ratio);
  node.rated_torque_mnm = static_cast<std::uint32_t>(
      std::max(1.0, std::round(c.motor_torque_limit_nm / node.gear_ratio * 1e3)));
  node.rated_current_ma =
      static_cast<std::uint32_t>(std::max(1.0, std::round(m.max_current_a * 1e3)));
  const std::string unit = r.String(n, "velocity_unit", f, std::string("rpm"));
  if (unit != "rpm" && unit != "counts_per_s") {
    r.Fail(n["velocity_unit"], f + ".velocity_unit",
           fmt::format("'{}' is not rpm or counts_per_s (of the motor shaft)", unit));
  }
  node.velocity_rpm = unit == "rpm";
  node.counts_per_rev =
      static_cast<std::uint32_t>(r.Integer(n, "counts_per_rev", f, 1, 1 << 30, 4096));
  node.trip_current_a = r.Number(n, "trip_current_a", f, 0, 1e4, 0.0);
  node.trip_time_s = r.Number(n, "trip_time_s", f, 0, 10, 0.01);
  d.eds = r.String(n, "eds", f, std::string());
  const bool have_id = Reader::Present(Reader::Get(n, "node_id"));
  if (!have_id && d.eds.empty()) r.FailKey(n, "node_id", f + ".node_id", "is required");
  node.node_id = have_id ? static_cast<std::uint8_t>(r.Integer(n, "node_id", f, 1, 127)) : 0;
  if (!d.eds.empty()) {
    d.eds = r.Path(d.eds);
    try {
      ApplyCia402Eds(bus::EdsFile::LoadFile(d.eds), node);
    } catch (const std::invalid_argument& e) {
      r.FailKey(n, "eds", f + ".eds", e.what());
    }
  }
  ReadObjects(r, n, f, [&](std::uint16_t index, std::uint8_t sub, std::uint32_t value) {
    SetCia402Object(node, index, sub, value);
  });
  c.name = r.String(n, "name", f, fmt::format("drive{}", node.node_id));
  // The node's own checks (mapping, transmission types), at the entry.
  try {
    Cia402DriveNode check(node, c.motor_torque_limit_nm);
  } catch (const std::invalid_argument& e) {
    r.Fail(n, f, e.what());
  }
  return d;
}

}  // namespace

std::vector<DeviceSpec> ReadDevices(const Reader& r, const YAML::Node& n,
                                    const platforms::Platform& platform,
                                    const SensorsSpec& sensors) {
  std::vector<DeviceSpec> out;
  if (!Reader::Present(n)) return out;
  if (!n.IsSequence()) r.Fail(n, "devices", "must be a list of {kind, ...}");
  std::set<std::string> names{"gyro", "accel4", "dbc_imu"};
  std::set<int> node_ids;
  for (const auto& e : sensors.encoders) node_ids.insert(e.node_id);
  for (std::size_t i = 0; i < n.size(); ++i) {
    const std::string f = fmt::format("devices[{}]", i);
    if (!n[i].IsMap()) r.Fail(n[i], f, "must be a mapping {kind, ...}");
    const std::string kind = r.String(n[i], "kind", f, std::nullopt);
    DeviceSpec d;
    if (kind == "dbc") {
      d = ReadDbcDevice(r, n[i], f, platform);
      if (!names.insert(d.dbc_device.name).second) {
        r.Fail(n[i], f + ".name",
               fmt::format("'{}' is taken: give each device its own name", d.dbc_device.name));
      }
    } else if (kind == "mm5_10") {
      d = ReadMm5Device(r, n[i], f);
      if (!names.insert(d.dbc_device.name).second) {
        r.Fail(n[i], f + ".name",
               fmt::format("'{}' is taken: give each device its own name", d.dbc_device.name));
      }
    } else if (kind == "canopen_cia406") {
      d = ReadCia406Device(r, n[i], f, platform);
      if (!node_ids.insert(d.encoder.node_id).second) {
        r.Fail(n[i]["node_id"], f + ".node_id",
               fmt::format("node id {} is taken", d.encoder.node_id));
      }
    } else if (kind == "canopen_cia402") {
      d = ReadCia402Device(r, n[i], f, platform);
      if (!node_ids.insert(d.drive.node.node_id).second) {
        r.Fail(n[i]["node_id"], f + ".node_id",
               fmt::format("node id {} is taken", d.drive.node.node_id));
      }
      if (!names.insert(d.drive.name).second) {
        r.Fail(n[i], f + ".name",
               fmt::format("'{}' is taken: give each device its own name", d.drive.name));
      }
    } else {
      r.FailKey(
          n[i], "kind", f + ".kind",
          fmt::format("'{}' is not one of dbc, mm5_10, canopen_cia406, canopen_cia402", kind));
    }
    d.where = r.Where(n[i]);
    out.push_back(std::move(d));
  }
  return out;
}

}  // namespace wheelhil::emulator::scenario::internal
