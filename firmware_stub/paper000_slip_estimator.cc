#include "firmware_stub/paper000_slip_estimator.h"

#include <fmt/format.h>

#include <cmath>
#include <stdexcept>

namespace wheelhil::fw {
namespace {

int Sign(double v) { return (v > 0.0) - (v < 0.0); }

void RequirePositive(const char* field, double v) {
  if (!std::isfinite(v) || v <= 0.0) {
    throw std::invalid_argument(fmt::format("{} ({}) must be finite and > 0", field, v));
  }
}

}  // namespace

SlipCorrectingOdometry::SlipCorrectingOdometry(const SlipEstimatorConfig& config)
    : config_(config) {
  RequirePositive("track_width_m", config.track_width_m);
  RequirePositive("z", config.z);
  if (config.calibration_samples == 0) {
    if (!std::isfinite(config.residual_mean_rad)) {
      throw std::invalid_argument(
          fmt::format("residual_mean_rad ({}) must be finite", config.residual_mean_rad));
    }
    RequirePositive("residual_sigma_rad", config.residual_sigma_rad);
    mean_rad_ = config.residual_mean_rad;
    sigma_rad_ = config.residual_sigma_rad;
    calibrated_ = true;
  } else if (config.calibration_samples < 2) {
    throw std::invalid_argument(
        fmt::format("calibration_samples ({}) must be 0 (use configured statistics) or >= 2",
                    config.calibration_samples));
  } else {
    calibration_.reserve(config.calibration_samples);
  }
}

void SlipCorrectingOdometry::FinishCalibration() noexcept {
  const double n = static_cast<double>(calibration_.size());
  double sum = 0.0;
  for (double r : calibration_) sum += r;
  const double mean = sum / n;
  double b2 = 0.0;
  for (double r : calibration_) b2 += (r - mean) * (r - mean);
  mean_rad_ = mean;
  sigma_rad_ = std::sqrt(b2 / n);  // Divisor n, as B2 of the normality test.
  const bus::NormalityResult test = bus::SkewnessKurtosisTest(calibration_, 1.96);
  normality_ = test.defined ? std::optional(test) : std::nullopt;
  calibrated_ = true;
}

bool SlipCorrectingOdometry::Step(double dL_m, double dR_m, double dth_gyro_rad) noexcept {
  if (!std::isfinite(dL_m) || !std::isfinite(dR_m) || !std::isfinite(dth_gyro_rad)) {
    ++rejected_;
    return false;
  }
  ++samples_;
  const double B = config_.track_width_m;
  const double dth_encoder = (dR_m - dL_m) / B;  // eq 1
  const double r = dth_encoder - dth_gyro_rad;   // eq 2

  SlipStepResult out;
  out.residual_rad = r;
  out.dL_corrected_m = dL_m;
  out.dR_corrected_m = dR_m;
  out.ds_m = 0.5 * (dL_m + dR_m);
  out.dtheta_rad = dth_encoder;

  const bool was_calibrated = calibrated_;
  if (!was_calibrated) {
    calibration_.push_back(r);
    if (calibration_.size() >= config_.calibration_samples) FinishCalibration();
  } else {
    out.calibrated = true;
    out.band_low_rad = band_low_rad();
    out.band_high_rad = band_high_rad();
    out.out_of_band = r < out.band_low_rad || r > out.band_high_rad;
  }

  if (out.out_of_band) {
    // A spinning wheel over-reports travel: r ~ +s_R/B or -s_L/B (REFERENCE.md).
    const bool right_rule = Sign(r) == Sign(dR_m) && Sign(dR_m) != 0;
    const bool left_rule = Sign(r) == -Sign(dL_m) && Sign(dL_m) != 0;
    bool right = right_rule;
    bool left = left_rule;
    if (right_rule && left_rule) {
      // Both hold only when the wheels turn in opposite senses (turning on the spot); the wheel
      // reporting more travel is taken as the one that spun.
      right = std::abs(dR_m) >= std::abs(dL_m);
      left = !right;
    }
    out.dtheta_rad = dth_gyro_rad;  // Heading from the gyro in every slip case.
    if (right) {
      out.slip_right = true;
      out.dR_corrected_m = dL_m + B * dth_gyro_rad;  // eqs 9-12, right slipped
      ++slips_right_;
    } else if (left) {
      out.slip_left = true;
      out.dL_corrected_m = dR_m - B * dth_gyro_rad;  // eqs 9-12, left slipped
      ++slips_left_;
    } else {
      out.slip_unattributed = true;  // Travel stays the encoders' mean, heading the gyro's.
      ++slips_unattributed_;
    }
    out.ds_m = 0.5 * (out.dL_corrected_m + out.dR_corrected_m);
  }

  pose_encoder_ =
      AdvancePose(pose_encoder_, 0.5 * (dL_m + dR_m), 0.0, dth_encoder, config_.heading_rule);
  pose_corrected_ =
      AdvancePose(pose_corrected_, out.ds_m, 0.0, out.dtheta_rad, config_.heading_rule);
  out.pose_encoder = pose_encoder_;
  out.pose_corrected = pose_corrected_;
  last_ = out;
  return true;
}

void SlipCorrectingOdometry::ResetPose() noexcept {
  pose_encoder_ = Pose2{};
  pose_corrected_ = Pose2{};
}

}  // namespace wheelhil::fw
