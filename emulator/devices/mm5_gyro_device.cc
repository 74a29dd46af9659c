#include "emulator/devices/mm5_gyro_device.h"

#include <cmath>

#include "emulator/faults/device_faults.h"
#include "emulator/faults/sensor_faults.h"

namespace wheelhil::emulator {

Mm5GyroDevice::Mm5GyroDevice(std::shared_ptr<const bus::DbcDatabase> mm5_dbc,
                             const GyroParams& gyro, std::int64_t first_sample_ns)
    : gyro_(gyro), node_(std::move(mm5_dbc), gyro, first_sample_ns) {}

Mm5GyroDevice::~Mm5GyroDevice() = default;

Mm5GyroDevice::Mm5GyroDevice(const Mm5GyroDevice& other)
    : Device(other),
      name_(other.name_),
      gyro_(other.gyro_),
      node_(other.node_),
      gyro_fault_(CopyOf(other.gyro_fault_)) {}

std::unique_ptr<Device> Mm5GyroDevice::Clone() const {
  return std::unique_ptr<Device>(new Mm5GyroDevice(*this));
}

double Mm5GyroDevice::channel_noise_std(const std::string&) const {
  return gyro_.noise_density_rad_s_sqrt_hz * std::sqrt(gyro_.rate_hz);
}

void Mm5GyroDevice::ArmFaults(DeviceFaults faults) {
  TakeDeviceFaults(faults);
  for (auto& [channel, injector] : faults.sensors) {
    if (channel == "gyro") gyro_fault_ = std::move(injector);
  }
}

void Mm5GyroDevice::Poll(std::int64_t t_ns, const DeviceWorld& world, DevicePort& port) {
  while (node_.next_sample_ns() <= t_ns) {
    const std::int64_t ts = node_.next_sample_ns();
    const auto& b = *world.body;
    const Eigen::Vector3d w_B = b.q_WB.conjugate() * b.omega_WB_W;
    const Eigen::Vector3d a_B = b.q_WB.conjugate() * b.a_WB_W;
    std::optional<double> rate = node_.SampleYawRate(w_B);
    if (gyro_fault_) rate = gyro_fault_->Apply(*rate, ts);
    if (!rate) continue;  // dropout: no frame for this sample
    std::vector<NodeFrame> frames(1);
    frames[0].due_ns = ts;
    (void)node_.Encode(*rate, a_B.y(), frames[0].frame);
    SendThroughDeviceFaults(std::move(frames), true, port);
  }
}

}  // namespace wheelhil::emulator
