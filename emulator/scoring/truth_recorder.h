#pragma once
/// Records a run's ground truth from the physics: the planar pose and body velocity relative to
/// the motion start (truth.csv / truth.tum rows at the truth rate and at every SYNC), and per
/// motion step which drive wheels slip and which wheels are off the floor (for the slip
/// intervals and contact-loss metrics). Poses in the start frame (origin and heading of the
/// body at the motion start), velocities in the body frame B, times in s since the motion
/// start. Thread-compatible.

#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "emulator/physics/roller_vehicle.h"
#include "emulator/scoring/artefacts.h"
#include "emulator/scoring/metrics.h"

namespace wheelhil::emulator::scoring {

struct TruthRecorderOptions {
  std::vector<std::size_t> drive_wheels;  ///< Vehicle wheel indices whose slip is scored.
  /// A drive wheel slips while its contact slip speed exceeds this (m/s); nullopt: the
  /// solver's own `slipping` flag.
  std::optional<double> slip_threshold_m_s;
  std::int64_t every_ns = 10'000'000;  ///< Truth row period (rows also at every SYNC).
  std::int64_t step_ns = 1'000'000;    ///< Physics step.
};

/// A wheel's state at a truth row (for run.mcap): spin rate, contact slip speed, load, motor.
struct WheelState {
  double omega_rad_s = 0;
  double slip_speed_m_s = 0;
  double normal_load_n = 0;
  double motor_torque_nm = 0;
  bool in_contact = false;
  bool slipping = false;
};

class TruthRecorder {
 public:
  explicit TruthRecorder(TruthRecorderOptions options) : o_(std::move(options)) {}

  /// The motion starts at t0_ns with the body at `body`: the origin of poses and times. Rows
  /// recorded before are dropped.
  void StartMotion(std::int64_t t0_ns, const physics::BodyTruth& body);

  /// A truth row at t_ns when it falls on the row period (or always with `force`); a second row
  /// at the same instant is not added.
  void Record(std::int64_t t_ns, const physics::BodyTruth& body,
              const std::vector<physics::WheelTruth>& wheels, bool force);
  /// The slip and contact state of the motion step that ended at t_end_ns.
  void RecordMotionStep(std::int64_t t_end_ns, const std::vector<physics::WheelTruth>& wheels);

  /// The instant of the motion start in s (0 before StartMotion): times are relative to it.
  double motion0_s() const { return t_motion0_s_; }
  double step_s() const { return static_cast<double>(o_.step_ns) * 1e-9; }

  const std::vector<TruthRow>& rows() const { return rows_; }
  /// Per row, every wheel's state (vehicle order).
  const std::vector<std::vector<WheelState>>& wheel_states() const { return wheel_states_; }
  const std::vector<PoseSample>& poses() const { return pose_; }
  const std::vector<VelocitySample>& velocities() const { return vel_; }
  /// Per motion step: its start (s since the motion start) and whether a drive wheel slipped.
  const std::vector<double>& step_t_s() const { return step_t_; }
  const std::vector<bool>& slipping() const { return slipping_; }
  /// Per wheel (vehicle order), per motion step: the wheel is off the floor.
  const std::vector<std::vector<bool>>& airborne() const { return airborne_; }

 private:
  bool Slipping(const physics::WheelTruth& w) const {
    return o_.slip_threshold_m_s ? w.slip_speed_m_s > *o_.slip_threshold_m_s : w.slipping;
  }

  TruthRecorderOptions o_;
  double t_motion0_s_ = 0;
  Eigen::Vector3d p0_ = Eigen::Vector3d::Zero();
  double yaw0_ = 0;
  std::vector<TruthRow> rows_;
  std::vector<std::vector<WheelState>> wheel_states_;
  std::vector<PoseSample> pose_;
  std::vector<VelocitySample> vel_;
  std::vector<double> step_t_;
  std::vector<bool> slipping_;
  std::vector<std::vector<bool>> airborne_;
};

}  // namespace wheelhil::emulator::scoring
