#pragma once
/// Models a single-axis MEMS rate gyro sampled at a fixed rate, in rad/s about a sensitive axis
/// given in the body frame B (default: body z, the yaw-rate gyro).
///
/// Per sample k (period dt = 1 / rate_hz), with w = axis_B . omega_WB_B the true rate:
///   y_k   = y_{k-1} + (1 - exp(-2 pi f_c dt)) ((1 + scale_factor_error) w - y_{k-1})
///           first-order low-pass at bandwidth f_c (exact discretisation; f_c = 0: no filter;
///           the filter starts at the first input, without a start-up transient)
///   b_k   = b_{k-1} + bias_random_walk * sqrt(dt) * N(0,1)   (b_0 = bias_rad_s)
///   out_k = quantise(saturate(y_k + b_k + noise_density * sqrt(rate_hz) * N(0,1)))
/// The output is then delayed by `delay_samples` whole samples (a pure latency on top of the
/// filter's group delay; the first output fills the delay line).
/// The white-noise density is specified at the output, as datasheets do (rad/s/sqrt(Hz));
/// the discrete noise std is density * sqrt(rate_hz). Saturation clips to +-range_rad_s;
/// quantisation rounds to the nearest multiple of resolution_rad_s (0 = none).
/// One std::mt19937_64 seeded with `seed`: same seed and inputs -> same samples (libstdc++).
/// The caller calls Sample once per period; sample scheduling is the device's job.
/// Thread-compatible.

#include <Eigen/Core>

#include <cstdint>
#include <deque>
#include <limits>
#include <random>

namespace wheelhil::emulator {

struct GyroParams {
  double rate_hz = 100.0;                      ///< Sample rate [Hz], > 0.
  Eigen::Vector3d axis_B{0.0, 0.0, 1.0};       ///< Sensitive axis in the body frame (normalised).
  double bias_rad_s = 0.0;                     ///< Initial (turn-on) bias [rad/s].
  double bias_random_walk_rad_s_sqrt_s = 0.0;  ///< Rate random walk [rad/s/sqrt(s)], >= 0.
  double noise_density_rad_s_sqrt_hz = 0.0;    ///< Angle random walk density [rad/s/sqrt(Hz)].
  double scale_factor_error = 0.0;             ///< Dimensionless; 0.01 = reads 1 % high.
  double resolution_rad_s = 0.0;               ///< Quantisation step (LSB) [rad/s]; 0 = none.
  double range_rad_s = std::numeric_limits<double>::infinity();  ///< Saturation [rad/s], > 0.
  double bandwidth_hz = 0.0;  ///< First-order -3 dB bandwidth [Hz]; 0 = no filter.
  int delay_samples = 0;      ///< Pure output latency in samples (data ready late), >= 0.
  std::uint64_t seed = 0;     ///< RNG seed.
};

class GyroModel {
 public:
  /// Throws std::invalid_argument naming the bad field.
  explicit GyroModel(const GyroParams& params);

  /// One sample from the true body angular velocity omega_WB_B [rad/s], projected on axis_B.
  double Sample(const Eigen::Vector3d& omega_WB_B);
  /// One sample from the true rate about the sensitive axis [rad/s].
  double SampleRate(double true_rate_rad_s);

  double period_s() const { return period_s_; }
  /// The current bias (initial bias plus random walk so far) [rad/s].
  double bias_rad_s() const { return bias_rad_s_; }
  /// Discrete white-noise standard deviation per sample [rad/s].
  double noise_std_rad_s() const { return noise_std_rad_s_; }

 private:
  GyroParams params_;
  double period_s_;
  double noise_std_rad_s_;
  double bias_step_std_rad_s_;
  double filter_gain_;  ///< 1 - exp(-2 pi f_c dt); 1 when unfiltered.
  bool filter_started_ = false;
  double filtered_rad_s_ = 0.0;
  double bias_rad_s_;
  std::deque<double> delay_line_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
};

}  // namespace wheelhil::emulator
