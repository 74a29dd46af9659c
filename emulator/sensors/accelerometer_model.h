#pragma once
/// Models a single- or multi-axis (1..3 axes) linear accelerometer mounted on a rigid body B at
/// point P (position r_BP_B from the body origin Bo, expressed in B). Each axis measures the
/// specific force at P along its sensing direction:
///
///   f_P_B = a_WBo_B + alpha_WB_B x r_BP_B + omega_WB_B x (omega_WB_B x r_BP_B) - g_B
///
/// where a_WBo_B is the inertial acceleration of the body origin expressed in B (R_WB^T a_W,
/// NOT the time derivative of body-frame velocity components), omega/alpha the body angular
/// velocity/acceleration in B, and g_B the gravity vector expressed in B (R_WB^T (0,0,-9.81) for
/// a z-up world, so a level sensor at rest reads +9.81 m/s^2 on an upward axis).
///
/// Per axis i with nominal unit direction u_i (body frame), the misalignment rotation
/// R_m = exp([misalignment_rad]x) tilts every axis: u'_i = R_m u_i, then
///   out_i = quantise(saturate((1 + scale_error_i) u'_i . f_P_B + bias_i + sigma n_i))
/// with sigma = noise_density * sqrt(rate_hz) per sample (density specified at the output),
/// saturation at +-range, quantisation to resolution (0 = none). One std::mt19937_64 seeded with
/// `seed`: same seed and inputs -> same samples (libstdc++). Thread-compatible.

#include <Eigen/Core>

#include <cstdint>
#include <limits>
#include <random>
#include <vector>

namespace wheelhil::emulator {

/// Ground-truth rigid-body kinematics a sensor on the body needs, all expressed in B.
struct BodyKinematics {
  Eigen::Vector3d a_WBo_B = Eigen::Vector3d::Zero();     ///< Inertial accel of Bo [m/s^2].
  Eigen::Vector3d omega_WB_B = Eigen::Vector3d::Zero();  ///< Angular velocity [rad/s].
  Eigen::Vector3d alpha_WB_B = Eigen::Vector3d::Zero();  ///< Angular acceleration [rad/s^2].
  Eigen::Vector3d g_B{0.0, 0.0, -9.80665};               ///< Gravity expressed in B [m/s^2].
};

/// Specific force at point P (r_BP_B from the body origin) expressed in B [m/s^2].
Eigen::Vector3d SpecificForceAt(const BodyKinematics& k, const Eigen::Vector3d& r_BP_B);

struct AccelerometerParams {
  double rate_hz = 1000.0;                                        ///< Sample rate [Hz], > 0.
  Eigen::Vector3d r_BP_B = Eigen::Vector3d::Zero();               ///< Mounting point [m].
  std::vector<Eigen::Vector3d> axes_B{Eigen::Vector3d::UnitX()};  ///< 1..3 sensing directions.
  Eigen::Vector3d misalignment_rad = Eigen::Vector3d::Zero();     ///< Small rotation vector [rad].
  std::vector<double> bias_m_s2{};          ///< Per-axis bias [m/s^2]; empty = 0 on every axis.
  std::vector<double> scale_error{};        ///< Per-axis scale error (0.01 = 1 % high); empty = 0.
  double noise_density_m_s2_sqrt_hz = 0.0;  ///< White noise density [m/s^2/sqrt(Hz)], >= 0.
  double resolution_m_s2 = 0.0;             ///< Quantisation step [m/s^2]; 0 = none.
  double range_m_s2 = std::numeric_limits<double>::infinity();  ///< Saturation [m/s^2], > 0.
  std::uint64_t seed = 0;                                       ///< RNG seed.
};

class AccelerometerModel {
 public:
  /// Throws std::invalid_argument naming the bad field.
  explicit AccelerometerModel(const AccelerometerParams& params);

  /// One sample of every axis (size = number of axes) [m/s^2]. The reference stays valid until
  /// the next call.
  const std::vector<double>& Sample(const BodyKinematics& k);

  int axis_count() const { return static_cast<int>(axes_.size()); }
  double period_s() const { return 1.0 / params_.rate_hz; }
  double noise_std_m_s2() const { return noise_std_m_s2_; }
  /// Effective (misaligned, normalised) sensing direction of axis i in B.
  const Eigen::Vector3d& effective_axis_B(int i) const { return axes_[static_cast<size_t>(i)]; }

 private:
  AccelerometerParams params_;
  std::vector<Eigen::Vector3d> axes_;
  std::vector<double> bias_;
  std::vector<double> scale_;
  double noise_std_m_s2_;
  std::vector<double> out_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
};

}  // namespace wheelhil::emulator
