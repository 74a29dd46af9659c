#include "emulator/sensors/accelerometer_model.h"

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace wheelhil::emulator {

Eigen::Vector3d SpecificForceAt(const BodyKinematics& k, const Eigen::Vector3d& r_BP_B) {
  return k.a_WBo_B + k.alpha_WB_B.cross(r_BP_B) + k.omega_WB_B.cross(k.omega_WB_B.cross(r_BP_B)) -
         k.g_B;
}

AccelerometerModel::AccelerometerModel(const AccelerometerParams& params)
    : params_(params), rng_(params.seed) {
  if (!(params.rate_hz > 0.0) || !std::isfinite(params.rate_hz)) {
    throw std::invalid_argument(
        fmt::format("accelerometer.rate_hz ({}) must be finite and > 0", params.rate_hz));
  }
  const std::size_t n = params.axes_B.size();
  if (n < 1 || n > 3) {
    throw std::invalid_argument(fmt::format("accelerometer.axes_B has {} axes (must be 1..3)", n));
  }
  if (!params.bias_m_s2.empty() && params.bias_m_s2.size() != n) {
    throw std::invalid_argument(fmt::format("accelerometer.bias_m_s2 has {} values for {} axes",
                                            params.bias_m_s2.size(), n));
  }
  if (!params.scale_error.empty() && params.scale_error.size() != n) {
    throw std::invalid_argument(fmt::format("accelerometer.scale_error has {} values for {} axes",
                                            params.scale_error.size(), n));
  }
  if (!params.r_BP_B.allFinite() || !params.misalignment_rad.allFinite()) {
    throw std::invalid_argument("accelerometer.r_BP_B and misalignment_rad must be finite");
  }
  if (!(params.noise_density_m_s2_sqrt_hz >= 0.0) || !(params.resolution_m_s2 >= 0.0) ||
      !std::isfinite(params.noise_density_m_s2_sqrt_hz) || !std::isfinite(params.resolution_m_s2)) {
    throw std::invalid_argument(
        "accelerometer.noise_density_m_s2_sqrt_hz and resolution_m_s2 must be finite and >= 0");
  }
  if (!(params.range_m_s2 > 0.0)) {
    throw std::invalid_argument(
        fmt::format("accelerometer.range_m_s2 ({}) must be > 0", params.range_m_s2));
  }
  const double angle = params.misalignment_rad.norm();
  const Eigen::Matrix3d R_m =
      angle > 0.0 ? Eigen::AngleAxisd(angle, params.misalignment_rad / angle).toRotationMatrix()
                  : Eigen::Matrix3d::Identity();
  for (std::size_t i = 0; i < n; ++i) {
    const double norm = params.axes_B[i].norm();
    if (!(norm > 1e-9) || !std::isfinite(norm)) {
      throw std::invalid_argument(
          fmt::format("accelerometer.axes_B[{}] must be a finite non-zero vector", i));
    }
    axes_.push_back(R_m * (params.axes_B[i] / norm));
    bias_.push_back(params.bias_m_s2.empty() ? 0.0 : params.bias_m_s2[i]);
    scale_.push_back(params.scale_error.empty() ? 0.0 : params.scale_error[i]);
  }
  noise_std_m_s2_ = params.noise_density_m_s2_sqrt_hz * std::sqrt(params.rate_hz);
  out_.resize(n);
}

const std::vector<double>& AccelerometerModel::Sample(const BodyKinematics& k) {
  const Eigen::Vector3d f_P_B = SpecificForceAt(k, params_.r_BP_B);
  for (std::size_t i = 0; i < axes_.size(); ++i) {
    double v = (1.0 + scale_[i]) * axes_[i].dot(f_P_B) + bias_[i];
    if (noise_std_m_s2_ > 0.0) v += noise_std_m_s2_ * normal_(rng_);
    v = std::clamp(v, -params_.range_m_s2, params_.range_m_s2);
    if (params_.resolution_m_s2 > 0.0) {
      v = std::round(v / params_.resolution_m_s2) * params_.resolution_m_s2;
    }
    out_[i] = v;
  }
  return out_;
}

}  // namespace wheelhil::emulator
