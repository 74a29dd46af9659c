#pragma once
/// A user's IMU described by its own DBC file, as a CAN device (DbcImuNode): three gyro axes
/// (GyroModel along body x, y, z) and a three-axis accelerometer (AccelerometerModel) at the
/// mounting point r_BP_B, sampled at each instant one of the IMU's messages is due (its
/// GenMsgCycleTime) from the body kinematics of that step; the node encodes the configured
/// signals with the units of their DBC unit strings, rolling counters and checksums. Device
/// faults act on its frames ("dbc_imu"); its sensor channels are "dbc_imu.rate_x" .. "accel_z".
/// Thread-compatible.

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "emulator/devices/dbc_imu_node.h"
#include "emulator/devices/device.h"
#include "emulator/devices/six_axis_imu.h"
#include "emulator/sensors/accelerometer_model.h"
#include "emulator/sensors/gyro_model.h"

namespace wheelhil::emulator {

struct DbcImuDeviceConfig {
  DbcImuConfig node;                            ///< Which signals carry what.
  Eigen::Vector3d r_BP_B = Eigen::Vector3d::Zero();  ///< Mounting point on the body [m].
  /// Per axis x, y, z (axis_B, rate_hz and seed are set by the device).
  GyroParams gyro;
  /// Three axes x, y, z at r_BP_B (axes_B, r_BP_B, rate_hz and seed set by the device).
  AccelerometerParams accel;
  std::uint64_t seed = 0;
  std::int64_t first_sample_ns = 0;
};

class DbcImuDevice final : public Device {
 public:
  /// Throws std::invalid_argument ("dbc_imu.<field>: problem") for a configuration the node or
  /// the sensor models refuse.
  DbcImuDevice(std::shared_ptr<const bus::DbcDatabase> dbc, const DbcImuDeviceConfig& config);
  ~DbcImuDevice() override;
  std::unique_ptr<Device> Clone() const override {
    return std::unique_ptr<Device>(new DbcImuDevice(*this));
  }

  const std::string& name() const override { return name_; }
  std::int64_t NextEventNs() const override { return node_.NextEventNs(); }
  void Poll(std::int64_t t_ns, const DeviceWorld& world, DevicePort& port) override;
  bool ReadsFrame(std::uint32_t) const override { return false; }  // it only sends
  std::vector<std::string> sensor_channels() const override;
  double channel_noise_std(const std::string& channel) const override;
  void ArmFaults(DeviceFaults faults) override;

 private:
  DbcImuDevice(const DbcImuDevice&) = default;

  std::string name_ = "dbc_imu";
  DbcImuNode node_;
  SixAxisImu imu_;  // along the body axes
};

}  // namespace wheelhil::emulator
