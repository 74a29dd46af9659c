#include "emulator/devices/dbc_imu_device.h"

#include <algorithm>
#include <cmath>

#include "emulator/devices/accel4_device.h"
#include "emulator/faults/device_faults.h"
#include "emulator/faults/sensor_faults.h"

namespace wheelhil::emulator {

namespace {

const std::array<const char*, 6> kChannels = {"dbc_imu.rate_x",  "dbc_imu.rate_y",
                                              "dbc_imu.rate_z",  "dbc_imu.accel_x",
                                              "dbc_imu.accel_y", "dbc_imu.accel_z"};

// The models' sample rate: the fastest message's (each due instant is one sample).
double FastestRateHz(const DbcImuNode& node) {
  std::int64_t period = 0;
  for (std::size_t i = 0; i < node.message_count(); ++i) {
    period = period == 0 ? node.period_ns(i) : std::min(period, node.period_ns(i));
  }
  return period > 0 ? 1e9 / static_cast<double>(period) : 100.0;
}

}  // namespace

DbcImuDevice::DbcImuDevice(std::shared_ptr<const bus::DbcDatabase> dbc,
                           const DbcImuDeviceConfig& config)
    : node_(std::move(dbc), config.node, config.first_sample_ns) {
  const double rate_hz = FastestRateHz(node_);
  for (int axis = 0; axis < 3; ++axis) {
    GyroParams gp = config.gyro;
    gp.axis_B = Eigen::Vector3d::Unit(axis);
    gp.rate_hz = rate_hz;
    gp.seed = config.seed * 31 + static_cast<std::uint64_t>(axis);
    gyros_.emplace_back(gp);
  }
  AccelerometerParams ap = config.accel;
  ap.rate_hz = rate_hz;
  ap.r_BP_B = config.r_BP_B;
  ap.axes_B = {Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ()};
  ap.seed = config.seed * 31 + 3;
  accel_ = std::make_unique<AccelerometerModel>(ap);
}

DbcImuDevice::~DbcImuDevice() = default;

std::vector<std::string> DbcImuDevice::sensor_channels() const {
  return {kChannels.begin(), kChannels.end()};
}

double DbcImuDevice::channel_noise_std(const std::string& channel) const {
  for (std::size_t c = 0; c < 3; ++c) {
    if (channel == kChannels[c]) return gyros_[c].noise_std_rad_s();
  }
  return accel_->noise_std_m_s2();
}

void DbcImuDevice::ArmFaults(DeviceFaults faults) {
  TakeDeviceFaults(faults);
  for (auto& [channel, injector] : faults.sensors) {
    for (std::size_t c = 0; c < kChannels.size(); ++c) {
      if (channel == kChannels[c]) faults_[c] = std::move(injector);
    }
  }
}

void DbcImuDevice::Poll(std::int64_t t_ns, const DeviceWorld& world, DevicePort& port) {
  while (node_.NextEventNs() <= t_ns) {
    const std::int64_t ts = node_.NextEventNs();
    const BodyKinematics k = AccelKinematics(*world.body);
    std::array<double, 6> v{};
    for (std::size_t c = 0; c < 3; ++c) v[c] = gyros_[c].Sample(k.omega_WB_B);
    const std::vector<double>& a = accel_->Sample(k);
    for (std::size_t c = 0; c < 3; ++c) v[3 + c] = a[c];
    const bool dropped = !ApplyToChannels(faults_, v, ts);
    ImuSample sample;
    sample.rate_rad_s = {v[0], v[1], v[2]};
    sample.accel_m_s2 = {v[3], v[4], v[5]};
    std::vector<NodeFrame> frames = node_.Poll(ts, sample);  // advances even when dropped
    if (dropped) continue;
    SendThroughDeviceFaults(std::move(frames), true, port);
  }
}

}  // namespace wheelhil::emulator
