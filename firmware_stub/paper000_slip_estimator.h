#pragma once
/// Paper 000: wheel-slip identification and correction for a differential-drive robot with wheel
/// encoders and a z-rate gyro (see docs/estimators.md and /work/shared/seeds/REFERENCE.md).
///
/// Fed once per sampling interval with the left/right wheel travel increments dL_m, dR_m (from
/// the encoders, e.g. via EncoderIncrement) and the gyro heading increment dth_gyro_rad (the
/// z-rate integrated over the same interval, zero drift already removed). It forms the residual
///     r = (dR - dL)/B - dth_gyro          (eqs 1-2, rad)
/// and, once the residual band mean +- z*sigma is known (from a calibration window of slip-free
/// samples, or configured), flags a slip when r leaves the band, decides which wheel slipped
/// (sign rules), replaces the slipping wheel's travel by the one consistent with the gyro
/// (eqs 9-12), and dead-reckons both the plain encoder pose and the corrected pose.
///
/// Frames: world W = the body frame at the first sample (x forward, y left, z up), heading
/// counter-clockwise positive. Poses are of the wheel-axle midpoint.
/// Thread-compatible: one instance per estimator thread; no allocation after construction.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

#include "bus/normality.h"
#include "firmware_stub/planar_pose.h"

namespace wheelhil::fw {

struct SlipEstimatorConfig {
  /// B: distance between the two drive wheels' contact points [m], > 0.
  double track_width_m = 0.0;
  /// N: slip-free samples collected at start to estimate the residual's mean and sigma. While
  /// calibrating no slip is flagged and both poses follow the encoders. 0 = use the configured
  /// residual_mean_rad / residual_sigma_rad from the first sample on.
  std::size_t calibration_samples = 0;
  /// Configured residual statistics [rad], used when calibration_samples == 0 (sigma > 0 then).
  double residual_mean_rad = 0.0;
  double residual_sigma_rad = 0.0;
  /// Band half-width in sigmas; 1.96 is the paper's 95 % band. > 0.
  double z = 1.96;
  /// Heading used over an interval; the paper uses the midpoint.
  HeadingRule heading_rule = HeadingRule::kMidpoint;
};

/// Everything one interval produced.
struct SlipStepResult {
  double residual_rad = 0.0;       ///< r = (dR - dL)/B - dth_gyro.
  double band_low_rad = 0.0;       ///< mean - z*sigma (0 while calibrating).
  double band_high_rad = 0.0;      ///< mean + z*sigma (0 while calibrating).
  bool calibrated = false;         ///< The band is known; false during the calibration window.
  bool out_of_band = false;        ///< r outside [band_low, band_high]: a slip happened.
  bool slip_left = false;          ///< The left wheel was identified as slipping.
  bool slip_right = false;         ///< The right wheel was identified as slipping.
  bool slip_unattributed = false;  ///< Out of band but neither sign rule held (see docs).
  double dL_corrected_m = 0.0;     ///< Left travel after correction (= dL unless left slipped).
  double dR_corrected_m = 0.0;     ///< Right travel after correction (= dR unless right slipped).
  double ds_m = 0.0;               ///< Corrected travel of the axle midpoint.
  double dtheta_rad = 0.0;         ///< Corrected heading increment.
  Pose2 pose_encoder;              ///< Encoder-only dead reckoning, after this interval.
  Pose2 pose_corrected;            ///< Slip-corrected dead reckoning, after this interval.
};

class SlipCorrectingOdometry {
 public:
  /// Throws std::invalid_argument naming the field ("track_width_m (0) must be finite and > 0").
  explicit SlipCorrectingOdometry(const SlipEstimatorConfig& config);

  /// Processes one interval. Returns false, and changes nothing, if an input is not finite.
  [[nodiscard]] bool Step(double dL_m, double dR_m, double dth_gyro_rad) noexcept;

  /// The result of the last accepted Step (all zero before the first).
  const SlipStepResult& last() const { return last_; }
  const Pose2& pose_encoder() const { return pose_encoder_; }
  const Pose2& pose_corrected() const { return pose_corrected_; }
  bool calibrated() const { return calibrated_; }
  double residual_mean_rad() const { return mean_rad_; }
  double residual_sigma_rad() const { return sigma_rad_; }
  double band_low_rad() const { return mean_rad_ - config_.z * sigma_rad_; }
  double band_high_rad() const { return mean_rad_ + config_.z * sigma_rad_; }
  /// Skewness/kurtosis test of the calibration window's residuals (nullopt before calibration
  /// ends, when the statistics were configured, or when the test is undefined, e.g. sigma 0).
  const std::optional<bus::NormalityResult>& calibration_normality() const { return normality_; }

  std::uint64_t samples() const { return samples_; }
  std::uint64_t slips_left() const { return slips_left_; }
  std::uint64_t slips_right() const { return slips_right_; }
  std::uint64_t slips_unattributed() const { return slips_unattributed_; }
  std::uint64_t rejected_samples() const { return rejected_; }

  /// Both poses back to (0, 0, 0); calibration and counters are kept.
  void ResetPose() noexcept;

  const SlipEstimatorConfig& config() const { return config_; }

 private:
  void FinishCalibration() noexcept;

  SlipEstimatorConfig config_;
  bool calibrated_ = false;
  double mean_rad_ = 0.0;
  double sigma_rad_ = 0.0;
  std::vector<double> calibration_;  // Reserved to N at construction.
  std::optional<bus::NormalityResult> normality_;
  Pose2 pose_encoder_;
  Pose2 pose_corrected_;
  SlipStepResult last_;
  std::uint64_t samples_ = 0;
  std::uint64_t slips_left_ = 0;
  std::uint64_t slips_right_ = 0;
  std::uint64_t slips_unattributed_ = 0;
  std::uint64_t rejected_ = 0;
};

}  // namespace wheelhil::fw
