#include "emulator/devices/dbc_imu_device.h"

#include <algorithm>
#include <cmath>

#include "emulator/faults/device_faults.h"

namespace wheelhil::emulator {

namespace {

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
    : node_(std::move(dbc), config.node, config.first_sample_ns),
      imu_(name_, config.gyro, config.accel, Eigen::Matrix3d::Identity(), config.r_BP_B,
           FastestRateHz(node_), config.seed) {}

DbcImuDevice::~DbcImuDevice() = default;

std::vector<std::string> DbcImuDevice::sensor_channels() const { return imu_.channels(); }

double DbcImuDevice::channel_noise_std(const std::string& channel) const {
  return imu_.noise_std(channel);
}

void DbcImuDevice::ArmFaults(DeviceFaults faults) {
  TakeDeviceFaults(faults);
  imu_.ArmFaults(faults);
}

void DbcImuDevice::Poll(std::int64_t t_ns, const DeviceWorld& world, DevicePort& port) {
  while (node_.NextEventNs() <= t_ns) {
    const std::int64_t ts = node_.NextEventNs();
    std::array<double, 6> v{};
    const bool dropped = !imu_.Sample(*world.body, ts, v);
    ImuSample sample;
    sample.rate_rad_s = {v[0], v[1], v[2]};
    sample.accel_m_s2 = {v[3], v[4], v[5]};
    std::vector<NodeFrame> frames = node_.Poll(ts, sample);  // advances even when dropped
    if (dropped) continue;
    SendThroughDeviceFaults(std::move(frames), true, port);
  }
}

}  // namespace wheelhil::emulator
