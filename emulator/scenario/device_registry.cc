#include "emulator/scenario/device_registry.h"

#include <cmath>
#include <numbers>
#include <functional>
#include <random>

#include "bus/canopen.h"
#include "bus/dbc.h"
#include "emulator/devices/accel4_device.h"
#include "emulator/devices/cia402_drive_device.h"
#include "emulator/devices/cia406_encoder_device.h"
#include "emulator/devices/dbc_cia406_codec.h"
#include "emulator/devices/dbc_device.h"
#include "emulator/devices/dbc_imu_device.h"
#include "emulator/devices/mm5_gyro_device.h"

namespace wheelhil::emulator::scenario {

namespace {

using Devices = std::vector<std::unique_ptr<Device>>;
using Builder = std::function<void(const DeviceBuildContext&, Devices&)>;

// One CiA 406 node; `k` numbers the encoders of the run (their seeds).
// `from_eds`: the node's dictionary as its EDS (and the scenario's objects) set it.
std::unique_ptr<Device> MakeEncoder(const DeviceBuildContext& c,
                                    const std::shared_ptr<const DbcCia406Codec>& codec,
                                    const EncoderDeviceSpec& e, int lines_per_rev,
                                    bool quadrature_x4, std::uint64_t k,
                                    const Cia406NodeConfig* from_eds = nullptr) {
  const SensorsSpec& sensors = c.scenario.sensors;
  {
    Cia406EncoderDeviceConfig dc;
    dc.wheel_name = e.wheel;
    dc.wheel_index = c.scenario.platform.wheel_index(e.wheel);
    dc.direction = e.direction;
    EncoderParams& ep = dc.encoder;
    ep.lines_per_rev = lines_per_rev;
    ep.quadrature_x4 = quadrature_x4;
    ep.missed_count_prob = sensors.encoder_missed_count_prob;
    ep.glitch_prob = sensors.encoder_glitch_prob;
    ep.seed = c.seed * 1000003ull + k;
    // A disc is mounted at no particular angle: an edge right at the start angle would make a
    // wheel that only settles there flip a count back and forth. Drawn apart from ep.seed's
    // stream so that the encoder's own imperfections keep their draws.
    std::mt19937_64 phase_rng(ep.seed ^ 0xD15C0FFull);
    ep.disc_phase_counts = std::uniform_real_distribution<double>(0.0, 1.0)(phase_rng);
    if (sensors.encoder_eccentricity_rad > 0) {
      // Drawn after the disc phase, so that runs without eccentricity keep their draws.
      ep.eccentricity_rad = sensors.encoder_eccentricity_rad;
      ep.eccentricity_phase_rad =
          std::uniform_real_distribution<double>(0.0, 2 * std::numbers::pi)(phase_rng);
    }
    dc.initial_angle_rad = c.wheels[dc.wheel_index].angle_rad;
    if (from_eds != nullptr) {
      dc.node = *from_eds;
    } else {
      dc.node.heartbeat_ms = static_cast<std::uint16_t>(sensors.heartbeat_ms);
    }
    dc.node.node_id = static_cast<std::uint8_t>(e.node_id);
    return std::make_unique<Cia406EncoderDevice>(dc, codec);
  }
}

void BuildEncoders(const DeviceBuildContext& c, Devices& out) {
  const SensorsSpec& sensors = c.scenario.sensors;
  if (sensors.encoders.empty()) return;
  const auto codec = DbcCia406Codec::FromFile(c.dbc_dir + "/cia406_encoder.dbc");
  std::uint64_t k = 0;
  for (const auto& e : sensors.encoders) {
    out.push_back(MakeEncoder(c, codec, e, sensors.encoder_lines_per_rev,
                              sensors.encoder_quadrature_x4, ++k));
  }
}

// The `devices:` list, in its order, after the `sensors:` devices.
void BuildDeviceList(const DeviceBuildContext& c, Devices& out) {
  std::shared_ptr<const DbcCia406Codec> codec;
  std::uint64_t k = c.scenario.sensors.encoders.size();
  std::uint64_t index = 0;
  for (const DeviceSpec& d : c.scenario.devices) {
    ++index;
    switch (d.kind) {
      case DeviceSpec::Kind::kCanopenCia406:
        if (!codec) codec = DbcCia406Codec::FromFile(c.dbc_dir + "/cia406_encoder.dbc");
        out.push_back(MakeEncoder(c, codec, d.encoder, d.lines_per_rev, d.quadrature_x4, ++k,
                                  d.eds.empty() ? nullptr : &d.eds_node));
        break;
      case DeviceSpec::Kind::kCanopenCia402:
        out.push_back(std::make_unique<Cia402DriveDevice>(d.drive));
        break;
      case DeviceSpec::Kind::kDbc:
      case DeviceSpec::Kind::kMm5_10: {
        const std::string path = d.kind == DeviceSpec::Kind::kMm5_10
                                     ? c.dbc_dir + "/bosch_mm5_10.dbc"
                                     : d.dbc;
        auto dbc = std::make_shared<const bus::DbcDatabase>(bus::DbcDatabase::LoadFile(path));
        DbcDeviceConfig dc = d.dbc_device;
        dc.seed = c.seed * 2654435761ull + index;
        out.push_back(std::make_unique<DbcDevice>(dbc, dc));
        break;
      }
    }
  }
}

void BuildMm5Gyro(const DeviceBuildContext& c, Devices& out) {
  const SensorsSpec& sensors = c.scenario.sensors;
  if (!sensors.gyro) return;
  GyroParams gp;
  gp.rate_hz = sensors.gyro_rate_hz;
  gp.noise_density_rad_s_sqrt_hz = sensors.gyro_noise_density_rad_s_sqrt_hz;
  gp.bias_rad_s = sensors.gyro_bias_rad_s;
  gp.bias_random_walk_rad_s_sqrt_s = sensors.gyro_bias_random_walk_rad_s_sqrt_s;
  gp.seed = c.seed * 7919ull + 17;
  auto dbc = std::make_shared<const bus::DbcDatabase>(
      bus::DbcDatabase::LoadFile(c.dbc_dir + "/bosch_mm5_10.dbc"));
  out.push_back(std::make_unique<Mm5GyroDevice>(dbc, gp, std::llround(1e9 / gp.rate_hz)));
}

void BuildAccel4(const DeviceBuildContext& c, Devices& out) {
  const SensorsSpec& sensors = c.scenario.sensors;
  if (!sensors.accel4) return;
  auto params =
      Paper002AccelParams(sensors.accel4_radius_m, sensors.accel4_rate_hz, c.seed * 104729ull + 31);
  for (std::size_t i = 0; i < 4; ++i) {
    params[i].noise_density_m_s2_sqrt_hz = sensors.accel4_noise_density_m_s2_sqrt_hz;
    if (!sensors.accel4_bias_m_s2.empty()) params[i].bias_m_s2 = {sensors.accel4_bias_m_s2[i]};
    if (!sensors.accel4_scale_error.empty()) {
      params[i].scale_error = {sensors.accel4_scale_error[i]};
    }
  }
  auto dbc = std::make_shared<const bus::DbcDatabase>(
      bus::DbcDatabase::LoadFile(c.dbc_dir + "/wheelhil_accel4.dbc"));
  out.push_back(
      std::make_unique<Accel4Device>(dbc, params, std::llround(1e9 / sensors.accel4_rate_hz)));
}

void BuildDbcImu(const DeviceBuildContext& c, Devices& out) {
  const auto& spec = c.scenario.sensors.dbc_imu;
  if (!spec) return;
  auto dbc = std::make_shared<const bus::DbcDatabase>(bus::DbcDatabase::LoadFile(spec->dbc));
  DbcImuDeviceConfig dc;
  dc.node = spec->node;
  dc.r_BP_B = spec->mount_m;
  dc.gyro.noise_density_rad_s_sqrt_hz = spec->gyro_noise_density_rad_s_sqrt_hz;
  dc.gyro.bias_rad_s = spec->gyro_bias_rad_s;
  dc.gyro.bias_random_walk_rad_s_sqrt_s = spec->gyro_bias_random_walk_rad_s_sqrt_s;
  dc.accel.noise_density_m_s2_sqrt_hz = spec->accel_noise_density_m_s2_sqrt_hz;
  if (spec->accel_bias_m_s2 != 0) dc.accel.bias_m_s2.assign(3, spec->accel_bias_m_s2);
  dc.seed = c.seed * 15485863ull + 7;
  out.push_back(std::make_unique<DbcImuDevice>(dbc, dc));
}

// The device kinds, in the order their devices join the bus.
const std::vector<std::pair<std::string, Builder>>& Builders() {
  static const std::vector<std::pair<std::string, Builder>> builders{
      {"cia406_encoder", BuildEncoders},
      {"mm5_10", BuildMm5Gyro},
      {"accel4", BuildAccel4},
      {"dbc_imu", BuildDbcImu},
      {"devices", BuildDeviceList}};
  return builders;
}

}  // namespace

std::vector<std::unique_ptr<Device>> BuildScenarioDevices(const DeviceBuildContext& context) {
  Devices devices;
  for (const auto& [name, build] : Builders()) build(context, devices);
  return devices;
}

}  // namespace wheelhil::emulator::scenario
