#include "firmware_stub/paper002_velocity_fusion.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace wheelhil::fw {
namespace {

constexpr double kPaperPeriodS = 0.001;  // k is defined per 1 ms sample, as in the paper.
constexpr double kLongAgoS = 1e6;        // "No disturbance seen yet"; k = 1 to 1e-12.

void RequirePositive(const std::string& field, double v) {
  if (!std::isfinite(v) || v <= 0.0) {
    throw std::invalid_argument(fmt::format("{} ({}) must be finite and > 0", field, v));
  }
}

void RequireNonNegative(const std::string& field, double v) {
  if (!std::isfinite(v) || v < 0.0) {
    throw std::invalid_argument(fmt::format("{} ({}) must be finite and >= 0", field, v));
  }
}

void ValidateGains(const std::string& prefix, const SlidingModeGains& g) {
  RequirePositive(prefix + "k11_1_s", g.k11_1_s);
  RequireNonNegative(prefix + "k12_u_s", g.k12_u_s);
  RequirePositive(prefix + "k21_1_s2", g.k21_1_s2);
  RequireNonNegative(prefix + "k22_u_s2", g.k22_u_s2);
  RequireNonNegative(prefix + "boundary_layer_u", g.boundary_layer_u);
}

bool Finite3(const std::array<double, 3>& v) {
  return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
}

}  // namespace

BodyAccel DecoupleAccelerometers(const std::array<double, 4>& a, double R) noexcept {
  BodyAccel out;
  out.alpha_rad_s2 = (a[1] - a[0] + a[2] - a[3]) / (4.0 * R);
  out.ax_m_s2 = 0.5 * (a[0] - a[3]);
  out.ay_m_s2 = 0.5 * (a[1] - a[2]);
  return out;
}

std::array<double, 4> AccelerometerReadings(const BodyAccel& a, double R) noexcept {
  const double t = a.alpha_rad_s2 * R;
  return {a.ax_m_s2 - t, a.ay_m_s2 + t, -a.ay_m_s2 + t, -a.ax_m_s2 - t};
}

SlidingModeObserver::SlidingModeObserver(const SlidingModeGains& gains) : gains_(gains) {
  ValidateGains("", gains);
}

bool SlidingModeObserver::Step(double x1_u, double f_u_s2, double dt_s) noexcept {
  if (!std::isfinite(x1_u) || !std::isfinite(f_u_s2) || !std::isfinite(dt_s) || dt_s <= 0.0) {
    return false;
  }
  if (!started_) {
    started_ = true;
    xh1_ = x1_u;
    xh2_ = 0.0;
  }
  position_ = xh1_;
  velocity_ = xh2_;
  const double e = xh1_ - x1_u;
  double s;
  if (gains_.boundary_layer_u > 0.0) {
    s = std::clamp(e / gains_.boundary_layer_u, -1.0, 1.0);
  } else {
    s = static_cast<double>((e > 0.0) - (e < 0.0));
  }
  const double xh1_dot = xh2_ - gains_.k11_1_s * e - gains_.k12_u_s * s;
  const double xh2_dot = f_u_s2 - gains_.k21_1_s2 * e - gains_.k22_u_s2 * s;
  xh1_ += dt_s * xh1_dot;
  xh2_ += dt_s * xh2_dot;
  return true;
}

bool SlidingModeObserver::Predict(double f_u_s2, double dt_s) noexcept {
  if (!std::isfinite(f_u_s2) || !std::isfinite(dt_s) || dt_s <= 0.0) return false;
  if (!started_) return true;
  position_ = xh1_;
  velocity_ = xh2_;
  xh1_ += dt_s * xh2_;
  xh2_ += dt_s * f_u_s2;
  return true;
}

void SlidingModeObserver::LimitInnovation(double x1_u, double max_error_u) noexcept {
  if (!started_ || !std::isfinite(x1_u) || !std::isfinite(max_error_u)) return;
  const double m = std::abs(max_error_u);
  xh1_ = x1_u + std::clamp(xh1_ - x1_u, -m, m);
}

VelocityFusion::VelocityFusion(const VelocityFusionConfig& config) : config_(config) {
  RequirePositive("period_s", config.period_s);
  RequirePositive("accel_mount_radius_m", config.accel_mount_radius_m);
  if (!std::isfinite(config.k_min) || config.k_min <= 0.0 || config.k_min > 1.0) {
    throw std::invalid_argument(fmt::format("k_min ({}) must be in (0, 1]", config.k_min));
  }
  static constexpr const char* kNames[3] = {"x", "y", "theta"};
  for (int i = 0; i < 3; ++i) {
    const auto& a = config.axes[i];
    const std::string prefix = fmt::format("axes.{}.", kNames[i]);
    ValidateGains(prefix + "observer.", a.observer);
    RequirePositive(prefix + "disturbance_threshold_u_s2", a.disturbance_threshold_u_s2);
    RequirePositive(prefix + "recovery_time_s", a.recovery_time_s);
    // Explicit Euler of the observer's linear part (plus the boundary layer's slope) is stable
    // only if the gains are small against 1/dt.
    const auto& g = a.observer;
    const double phi = g.boundary_layer_u;
    const double k1 = g.k11_1_s + (phi > 0.0 ? g.k12_u_s / phi : 0.0);
    const double k2 = g.k21_1_s2 + (phi > 0.0 ? g.k22_u_s2 / phi : 0.0);
    const double dt = config.period_s;
    // Jury conditions for z^2 - (2 - k1 dt) z + (1 - k1 dt + k2 dt^2).
    const double a1 = -(2.0 - k1 * dt);
    const double a0 = 1.0 - k1 * dt + k2 * dt * dt;
    if (!(std::abs(a0) < 1.0 && 1.0 + a1 + a0 > 0.0 && 1.0 - a1 + a0 > 0.0)) {
      throw std::invalid_argument(fmt::format(
          "{}observer: gains (k11 + k12/phi = {}, k21 + k22/phi = {}) make the explicit-Euler "
          "observer unstable at period_s = {}",
          prefix, k1, k2, dt));
    }
    observers_[i] = SlidingModeObserver(a.observer);
  }
  Reset();
}

void VelocityFusion::Reset() noexcept {
  for (auto& o : observers_) o.Reset();
  fused_ = {};
  integrated_ = {};
  since_disturbance_s_ = {kLongAgoS, kLongAgoS, kLongAgoS};
  odometry_gap_ = false;
  odometry_velocity_ = {};
  out_ = FusionOutput{};
}

bool VelocityFusion::StepRaw(const std::array<double, 3>& odometry_position,
                             const std::array<double, 4>& accelerometers_m_s2,
                             const std::array<double, 3>& commanded) noexcept {
  for (double a : accelerometers_m_s2) {
    if (!std::isfinite(a)) return false;
  }
  return Step(odometry_position,
              DecoupleAccelerometers(accelerometers_m_s2, config_.accel_mount_radius_m), commanded);
}

bool VelocityFusion::StepRawUnobserved(const std::array<double, 4>& accelerometers_m_s2,
                                       const std::array<double, 3>& commanded) noexcept {
  for (double a : accelerometers_m_s2) {
    if (!std::isfinite(a)) return false;
  }
  return StepUnobserved(DecoupleAccelerometers(accelerometers_m_s2, config_.accel_mount_radius_m),
                        commanded);
}

bool VelocityFusion::Step(const std::array<double, 3>& odometry_position, const BodyAccel& measured,
                          const std::array<double, 3>& commanded) noexcept {
  if (!Finite3(odometry_position)) return false;
  return DoStep(&odometry_position, measured, commanded);
}

bool VelocityFusion::StepUnobserved(const BodyAccel& measured,
                                    const std::array<double, 3>& commanded) noexcept {
  return DoStep(nullptr, measured, commanded);
}

bool VelocityFusion::DoStep(const std::array<double, 3>* odometry_position,
                            const BodyAccel& measured,
                            const std::array<double, 3>& commanded) noexcept {
  const std::array<double, 3> a_B = {measured.ax_m_s2, measured.ay_m_s2, measured.alpha_rad_s2};
  if (!Finite3(a_B) || !Finite3(commanded)) return false;
  const bool observed = odometry_position != nullptr;
  const double dt = config_.period_s;

  // d/dt of the body-frame velocity = a_B - omega x v_B, evaluated with each branch's own
  // velocities (fused, and the pure integration).
  auto body_rate = [&](const std::array<double, 3>& v) {
    std::array<double, 3> r = a_B;
    if (config_.compensate_rotation) {
      r[kX] += v[kTheta] * v[kY];
      r[kY] -= v[kTheta] * v[kX];
    }
    return r;
  };
  const std::array<double, 3> rate_fused = body_rate(fused_);
  const std::array<double, 3> rate_integrated = body_rate(integrated_);

  for (int i = 0; i < 3; ++i) {
    const FusionAxisConfig& ac = config_.axes[i];
    FusionAxisOutput& o = out_.axes[i];
    const double f = config_.observer_uses_commanded_accel ? commanded[i] : 0.0;
    const double inertial = fused_[i] + rate_fused[i] * dt;
    if (observed) {
      if (odometry_gap_) {
        // The odometry is back with the whole gap's displacement: whatever of it the prediction
        // did not expect beyond one boundary layer moves the position state, not the velocity.
        observers_[i].LimitInnovation((*odometry_position)[i],
                                      observers_[i].gains().boundary_layer_u);
      }
      (void)observers_[i].Step((*odometry_position)[i], f, dt);  // Inputs checked above.
      odometry_velocity_[i] = observers_[i].velocity();
    } else {
      (void)observers_[i].Predict(rate_fused[i], dt);  // Finite: checked above.
    }

    o.disturbance_u_s2 = commanded[i] - rate_fused[i];
    o.disturbed = std::abs(o.disturbance_u_s2) > ac.disturbance_threshold_u_s2;
    since_disturbance_s_[i] = o.disturbed ? 0.0 : std::min(since_disturbance_s_[i] + dt, kLongAgoS);
    const double t = since_disturbance_s_[i] / ac.recovery_time_s;
    const double k = 1.0 - (1.0 - config_.k_min) / (1.0 + t * t);
    // No odometry this period: w = 0, the accelerometers alone carry the velocity.
    const double w = observed ? 1.0 - std::pow(1.0 - k, dt / kPaperPeriodS) : 0.0;

    fused_[i] = w * odometry_velocity_[i] + (1.0 - w) * inertial;
    integrated_[i] += rate_integrated[i] * dt;

    o.fused = fused_[i];
    o.odometry = odometry_velocity_[i];
    o.accel_integrated = integrated_[i];
    o.weight_k = k;
    o.time_since_disturbance_s = since_disturbance_s_[i];
    o.odometry_observed = observed;
  }
  odometry_gap_ = !observed;
  return true;
}

}  // namespace wheelhil::fw
