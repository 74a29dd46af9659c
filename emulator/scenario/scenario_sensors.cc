// The scenario loader's `sensors:` section (emulator/scenario/scenario.h).
#include <cmath>
#include <numbers>
#include <memory>
#include <optional>
#include <set>

#include <fmt/format.h>

#include "bus/dbc.h"
#include "emulator/scenario/internal/scenario_reader.h"

namespace wheelhil::emulator::scenario::internal {

namespace {

// sensors.dbc_imu: the file, the bindings and the noise; the node itself checks the bindings
// against the DBC (unknown messages or signals, units, cycle times), reported at this entry.
DbcImuSpec ReadDbcImu(const Reader& r, const YAML::Node& n) {
  const std::string f = "sensors.dbc_imu";
  r.CheckKeys(n, f, {"dbc", "mount_m", "channels", "messages", "gyro", "accel"});
  DbcImuSpec d;
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
                  fmt::format("'{}' is not one of {}", kind, ChecksumKindNames()));
      }
      if (*k == ChecksumKind::kE2eP11 || *k == ChecksumKind::kE2eP22) {
        r.FailKey(ms[i], "checksum_kind", mf + ".checksum_kind",
                  "an E2E profile needs its data ids: describe the IMU as a devices entry "
                  "(kind: dbc)");
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
  const auto db = LoadDbcAt(r, n, "dbc", f + ".dbc", d.dbc);
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

}  // namespace

SensorsSpec ReadSensors(const Reader& r, const YAML::Node& root,
                        const platforms::Platform& platform) {
  SensorsSpec s;
  const YAML::Node n = Reader::Get(root, "sensors");
  const bool devices = Reader::Present(Reader::Get(root, "devices"));
  if (!n.IsDefined()) {
    if (devices) return s;
    r.Fail(root, "sensors", "is required (encoders at least), or a devices list");
  }
  r.CheckKeys(n, "sensors", {"encoders", "gyro", "bus", "accel4", "dbc_imu"});
  const YAML::Node e = Reader::Get(n, "encoders");
  if (!e.IsDefined() && !devices) r.Fail(n, "sensors.encoders", "is required");
  if (e.IsDefined()) {
    r.CheckKeys(e, "sensors.encoders",
                {"lines_per_rev", "quadrature_x4", "missed_count_prob", "glitch_prob",
                 "eccentricity_deg", "nodes"});
  }
  s.encoder_lines_per_rev =
      static_cast<int>(r.Number(e, "lines_per_rev", "sensors.encoders", 1, 1e7, 500.0));
  s.encoder_quadrature_x4 = r.Bool(e, "quadrature_x4", "sensors.encoders", true);
  s.encoder_missed_count_prob = r.Number(e, "missed_count_prob", "sensors.encoders", 0, 1, 0.0);
  s.encoder_glitch_prob = r.Number(e, "glitch_prob", "sensors.encoders", 0, 1, 0.0);
  s.encoder_eccentricity_rad =
      r.Number(e, "eccentricity_deg", "sensors.encoders", 0, 5, 0.0) * std::numbers::pi / 180;
  const YAML::Node nodes = Reader::Get(e, "nodes");
  if (e.IsDefined() && (!nodes.IsSequence() || nodes.size() == 0)) {
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

}  // namespace wheelhil::emulator::scenario::internal
