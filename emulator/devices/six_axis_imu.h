#pragma once
/// The sensing part of a six-axis IMU device (the `dbc` device, the DBC IMU of sensors.dbc_imu):
/// three gyro axes and a three-axis accelerometer along the sensor axes (the columns of R_BS, in
/// the body frame B) at the mounting point r_BS_B, sampled together, each through its sensor
/// fault. Channels are "<name>.rate_x" .. "<name>.accel_z" (rad/s about, m/s^2 along the sensor
/// axes). Seeds: gyro axis i from seed * 31 + i, the accelerometer from seed * 31 + 3.
/// Thread-compatible.

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "emulator/devices/device.h"
#include "emulator/sensors/accelerometer_model.h"
#include "emulator/sensors/gyro_model.h"

namespace wheelhil::emulator {

class SixAxisImu {
 public:
  /// `gyro` and `accel` give noise, bias and the like; their axes, rate, point and seeds are
  /// set here. Throws std::invalid_argument for parameters the models refuse.
  SixAxisImu(std::string name, const GyroParams& gyro, const AccelerometerParams& accel,
             const Eigen::Matrix3d& R_BS, const Eigen::Vector3d& r_BS_B, double rate_hz,
             std::uint64_t seed);
  ~SixAxisImu();
  SixAxisImu(const SixAxisImu& other);
  SixAxisImu& operator=(const SixAxisImu&) = delete;

  /// One sample of the six channels from the body (rate x y z, accel x y z) at t_ns, through
  /// the channels' faults; false when a fault drops it (the models advance all the same).
  bool Sample(const physics::BodyTruth& body, std::int64_t t_ns, std::array<double, 6>& out);

  std::vector<std::string> channels() const;
  /// A channel's white-noise standard deviation per sample.
  double noise_std(const std::string& channel) const;
  /// Takes the sensor faults of its channels out of `faults`.
  void ArmFaults(DeviceFaults& faults);

 private:
  std::string name_;
  std::vector<GyroModel> gyros_;  // x, y, z
  std::unique_ptr<AccelerometerModel> accel_;
  std::array<std::unique_ptr<SensorFaultInjector>, 6> faults_;
};

}  // namespace wheelhil::emulator
