#pragma once
/// The Bosch MM5.10 yaw-rate sensor as a CAN device (Mm5ImuNode over bus/dbc/bosch_mm5_10.dbc):
/// at each of its sample instants it samples its gyro (GyroModel, rad/s about body z) from the
/// body rate, a sensor fault (channel "gyro") acts on the reading (a dropped reading sends no
/// frame) and the frame carries the yaw rate and the body-frame lateral acceleration of that
/// step. Device faults act on its frames. Thread-compatible.

#include <cstdint>
#include <memory>
#include <string>

#include "emulator/devices/device.h"
#include "emulator/devices/mm5_imu_node.h"

namespace wheelhil::emulator {

class Mm5GyroDevice final : public Device {
 public:
  /// `first_sample_ns`: the first sample instant (then every 1 / gyro.rate_hz).
  Mm5GyroDevice(std::shared_ptr<const bus::DbcDatabase> mm5_dbc, const GyroParams& gyro,
                std::int64_t first_sample_ns);
  ~Mm5GyroDevice() override;
  std::unique_ptr<Device> Clone() const override;

  const std::string& name() const override { return name_; }
  std::string fault_name() const override { return "gyro"; }
  std::int64_t NextEventNs() const override { return node_.next_sample_ns(); }
  void Poll(std::int64_t t_ns, const DeviceWorld& world, DevicePort& port) override;
  bool ReadsFrame(std::uint32_t) const override { return false; }  // it only sends
  std::vector<std::string> sensor_channels() const override { return {"gyro"}; }
  double channel_noise_std(const std::string& channel) const override;
  void ArmFaults(DeviceFaults faults) override;

 private:
  Mm5GyroDevice(const Mm5GyroDevice& other);

  std::string name_ = "imu";
  GyroParams gyro_;
  Mm5ImuNode node_;
  std::unique_ptr<SensorFaultInjector> gyro_fault_;
};

}  // namespace wheelhil::emulator
