#pragma once
/// A Bosch MM5.10-style yaw-rate node (bus/dbc/bosch_mm5_10.dbc): every period it samples its
/// GyroModel (rad/s about body z) and sends MM5_YawRate_AccelY (0x174) with the yaw rate in deg/s
/// and the lateral acceleration in g, encoded through the DBC codec (no hand-packed bytes). Only
/// the yaw message is sent (the firmware uses nothing else of the IMU). Pure state machine in
/// virtual time (integer ns); the caller supplies the true body motion at each sample instant.
/// Thread-compatible.

#include <cstdint>
#include <memory>

#include <Eigen/Core>

#include "bus/can_frame.h"
#include "bus/dbc.h"
#include "emulator/sensors/gyro_model.h"

namespace wheelhil::emulator {

class Mm5ImuNode {
 public:
  /// Throws std::invalid_argument when the database lacks MM5_YawRate_AccelY or its signals, or
  /// the gyro parameters are bad.
  Mm5ImuNode(std::shared_ptr<const bus::DbcDatabase> mm5_dbc, const GyroParams& gyro,
             std::int64_t first_sample_ns);

  /// The instant of the next sample.
  std::int64_t next_sample_ns() const { return next_ns_; }
  /// Samples the gyro at next_sample_ns() from the true body rate (omega_WB_B, rad/s) and the
  /// body-frame lateral acceleration (m/s^2), returns the frame and schedules the next sample.
  /// Returns false when a value had to be saturated (the frame is still built, saturated).
  bool Sample(const Eigen::Vector3d& omega_WB_B, double accel_y_B_m_s2, bus::CanFrame& out);
  /// The two halves of Sample, for a sensor fault between the model and the frame: samples the
  /// gyro (rad/s) at next_sample_ns() and schedules the next sample ...
  double SampleYawRate(const Eigen::Vector3d& omega_WB_B);
  /// ... and encodes one frame from a yaw rate (rad/s) and lateral acceleration (m/s^2).
  bool Encode(double yaw_rate_rad_s, double accel_y_B_m_s2, bus::CanFrame& out);

  std::uint64_t samples() const { return samples_; }
  std::uint64_t saturated() const { return saturated_; }

 private:
  std::shared_ptr<const bus::DbcDatabase> dbc_;
  const bus::DbcMessage* yaw_msg_ = nullptr;
  const bus::DbcSignal* yaw_sig_ = nullptr;
  const bus::DbcSignal* accel_sig_ = nullptr;
  GyroModel gyro_;
  std::int64_t period_ns_;
  std::int64_t first_ns_;
  std::int64_t next_ns_;
  std::uint64_t samples_ = 0;
  std::uint64_t saturated_ = 0;
};

}  // namespace wheelhil::emulator
