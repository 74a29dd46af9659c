// The scenario loader's `faults:` section (emulator/scenario/scenario.h).
#include <cmath>
#include <limits>
#include <set>
#include <stdexcept>

#include <fmt/format.h>

#include "emulator/scenario/internal/scenario_reader.h"

namespace wheelhil::emulator::scenario::internal {

namespace {

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
    "encoder_emcy, encoder_silent, frame, bus, sensor, device, drive, wheel_friction, "
    "torque_disturbance, bump";

}  // namespace

std::vector<FaultSpec> ReadFaults(const Reader& r, const YAML::Node& n, const SensorsSpec& s,
                                  const std::vector<DeviceSpec>& devices,
                                  const platforms::Platform& platform) {
  std::vector<FaultSpec> out;
  if (!n.IsDefined()) return out;
  // The encoders of both lists, and the named devices of `devices:` (their sensor channels are
  // NAME.rate_x .. NAME.accel_z).
  std::vector<EncoderDeviceSpec> encoders = s.encoders;
  std::vector<std::string> device_names;
  std::vector<std::string> drive_names;
  for (const DeviceSpec& d : devices) {
    if (d.kind == DeviceSpec::Kind::kCanopenCia402) {
      device_names.push_back(d.drive.name);
      drive_names.push_back(d.drive.name);
    }
    if (d.kind == DeviceSpec::Kind::kCanopenCia406) encoders.push_back(d.encoder);
    if (d.kind == DeviceSpec::Kind::kDbc || d.kind == DeviceSpec::Kind::kMm5_10) {
      device_names.push_back(d.dbc_device.name);
    }
  }
  auto named_device = [&](const std::string& name) {
    return std::find(device_names.begin(), device_names.end(), name) != device_names.end();
  };
  auto device_channel = [&](const std::string& channel) {
    const auto dot = channel.rfind('.');
    if (dot == std::string::npos || !named_device(channel.substr(0, dot))) return false;
    const std::string axis = channel.substr(dot + 1);
    return axis == "rate_x" || axis == "rate_y" || axis == "rate_z" || axis == "accel_x" ||
           axis == "accel_y" || axis == "accel_z";
  };
  if (!n.IsSequence()) r.Fail(n, "faults", "must be a list");
  auto encoder_known = [&](int id) {
    return std::any_of(encoders.begin(), encoders.end(),
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
      if (named_device(x.node)) return;
      if (x.node != "gyro" && x.node != "accel4") {
        r.Fail(e["node"], f + ".node",
               fmt::format("'{}' is not gyro, accel4 or the name of a device (encoders: node_id)",
                           x.node));
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
          r.Fail(e["checksum"], f + ".checksum", fmt::format("'{}' is not one of {}", c, ChecksumKindNames()));
        if (*ck == ChecksumKind::kE2eP11 || *ck == ChecksumKind::kE2eP22) {
          r.Fail(e["checksum"], f + ".checksum",
                 "an E2E profile needs its data ids: not a frame fault's recomputation");
        }
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
        const bool has = std::any_of(encoders.begin(), encoders.end(),
                                     [&](const auto& en) { return en.wheel == x.wheel; });
        if (!has) r.Fail(e["wheel"], f + ".wheel", "no encoder node on this wheel");
      } else if (!device_channel(x.sensor_name)) {
        r.Fail(e["sensor"], f + ".sensor",
               fmt::format("'{}' is not one of gyro, encoder, accel4, DEVICE.rate_x .. "
                           "DEVICE.accel_z",
                           x.sensor_name));
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
      const std::string node_name = e["node"] && e["node"].IsScalar() ? e["node"].Scalar() : "";
      if (std::find(drive_names.begin(), drive_names.end(), node_name) != drive_names.end() &&
          x.device.kind != DeviceFaultKind::kSilent &&
          x.device.kind != DeviceFaultKind::kHeartbeatLost) {
        r.Fail(e["kind"], f + ".kind",
               "a drive takes silent or heartbeat_lost here; its own faults are type: drive");
      }
      const bool on_drive =
          std::find(drive_names.begin(), drive_names.end(), node_name) != drive_names.end();
      target_node(x.device.kind == DeviceFaultKind::kSilent ||
                  (x.device.kind == DeviceFaultKind::kHeartbeatLost && on_drive));
      x.device.emcy_code =
          static_cast<std::uint16_t>(ReadId(r, e, "error_code", f, 0xFFFF, 0x7305));
      x.device.error_register =
          static_cast<std::uint8_t>(ReadId(r, e, "error_register", f, 0xFF, 0x01));
      LibraryCheck(r, e, f, [&] { DeviceFaultInjector("check", 1, {x.device}); });
    } else if (type == "drive") {
      r.CheckKeys(e, f, {"type", "kind", "drive", "start_s", "end_s", "torque_limit_nm"});
      x.kind = FaultSpec::Kind::kDrive;
      const std::string k = r.String(e, "kind", f, std::nullopt);
      if (k == "overcurrent") {
        x.drive.kind = DriveFault::Kind::kOverCurrent;
      } else if (k == "stuck") {
        x.drive.kind = DriveFault::Kind::kStuck;
      } else if (k == "torque_limit") {
        x.drive.kind = DriveFault::Kind::kTorqueLimit;
      } else {
        r.Fail(e["kind"], f + ".kind",
               fmt::format("'{}' is not one of overcurrent, stuck, torque_limit", k));
      }
      const FaultWindow w = lib_window();
      x.drive.t0_ns = w.t0_ns;
      x.drive.t1_ns = w.t1_ns == FaultWindow::kForever ? std::numeric_limits<std::int64_t>::max()
                                                       : w.t1_ns;
      x.node = r.String(e, "drive", f, std::nullopt);
      if (std::find(drive_names.begin(), drive_names.end(), x.node) == drive_names.end()) {
        r.Fail(e["drive"], f + ".drive",
               fmt::format("'{}' is not the name of a drive (devices of kind canopen_cia402)",
                           x.node));
      }
      const bool limit = x.drive.kind == DriveFault::Kind::kTorqueLimit;
      if (!limit && e["torque_limit_nm"]) {
        r.Fail(e["torque_limit_nm"], f + ".torque_limit_nm", "belongs to kind torque_limit");
      }
      if (limit) x.drive.torque_limit_nm = r.Number(e, "torque_limit_nm", f, 0, 1e4, std::nullopt);
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

}  // namespace wheelhil::emulator::scenario::internal
