#include "emulator/sensors/gyro_model.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

namespace wheelhil::emulator {
namespace {
void RequireNonNegative(double v, const char* field) {
  if (!(v >= 0.0) || !std::isfinite(v)) {
    throw std::invalid_argument(fmt::format("gyro.{} ({}) must be finite and >= 0", field, v));
  }
}
}  // namespace

GyroModel::GyroModel(const GyroParams& params)
    : params_(params), bias_rad_s_(params.bias_rad_s), rng_(params.seed) {
  if (!(params.rate_hz > 0.0) || !std::isfinite(params.rate_hz)) {
    throw std::invalid_argument(
        fmt::format("gyro.rate_hz ({}) must be finite and > 0", params.rate_hz));
  }
  const double norm = params.axis_B.norm();
  if (!(norm > 1e-9) || !std::isfinite(norm)) {
    throw std::invalid_argument("gyro.axis_B must be a finite non-zero vector");
  }
  params_.axis_B /= norm;
  if (!std::isfinite(params.bias_rad_s)) {
    throw std::invalid_argument(
        fmt::format("gyro.bias_rad_s ({}) must be finite", params.bias_rad_s));
  }
  if (!std::isfinite(params.scale_factor_error) || params.scale_factor_error <= -1.0) {
    throw std::invalid_argument(fmt::format("gyro.scale_factor_error ({}) must be finite and > -1",
                                            params.scale_factor_error));
  }
  RequireNonNegative(params.bias_random_walk_rad_s_sqrt_s, "bias_random_walk_rad_s_sqrt_s");
  RequireNonNegative(params.noise_density_rad_s_sqrt_hz, "noise_density_rad_s_sqrt_hz");
  RequireNonNegative(params.resolution_rad_s, "resolution_rad_s");
  RequireNonNegative(params.bandwidth_hz, "bandwidth_hz");
  if (params.delay_samples < 0) {
    throw std::invalid_argument(
        fmt::format("gyro.delay_samples ({}) must be >= 0", params.delay_samples));
  }
  if (!(params.range_rad_s > 0.0)) {
    throw std::invalid_argument(
        fmt::format("gyro.range_rad_s ({}) must be > 0", params.range_rad_s));
  }
  period_s_ = 1.0 / params.rate_hz;
  noise_std_rad_s_ = params.noise_density_rad_s_sqrt_hz * std::sqrt(params.rate_hz);
  bias_step_std_rad_s_ = params.bias_random_walk_rad_s_sqrt_s * std::sqrt(period_s_);
  filter_gain_ = params.bandwidth_hz > 0.0
                     ? 1.0 - std::exp(-2.0 * std::numbers::pi * params.bandwidth_hz * period_s_)
                     : 1.0;
}

double GyroModel::Sample(const Eigen::Vector3d& omega_WB_B) {
  return SampleRate(params_.axis_B.dot(omega_WB_B));
}

double GyroModel::SampleRate(double true_rate_rad_s) {
  const double scaled = (1.0 + params_.scale_factor_error) * true_rate_rad_s;
  if (!filter_started_) {
    filtered_rad_s_ = scaled;
    filter_started_ = true;
  } else {
    filtered_rad_s_ += filter_gain_ * (scaled - filtered_rad_s_);
  }
  if (bias_step_std_rad_s_ > 0.0) bias_rad_s_ += bias_step_std_rad_s_ * normal_(rng_);
  double out = filtered_rad_s_ + bias_rad_s_;
  if (noise_std_rad_s_ > 0.0) out += noise_std_rad_s_ * normal_(rng_);
  out = std::clamp(out, -params_.range_rad_s, params_.range_rad_s);
  if (params_.resolution_rad_s > 0.0) {
    out = std::round(out / params_.resolution_rad_s) * params_.resolution_rad_s;
  }
  if (params_.delay_samples > 0) {
    if (delay_line_.empty())
      delay_line_.assign(static_cast<std::size_t>(params_.delay_samples), out);
    delay_line_.push_back(out);
    out = delay_line_.front();
    delay_line_.pop_front();
  }
  return out;
}

}  // namespace wheelhil::emulator
