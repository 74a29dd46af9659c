#include "firmware_stub/paper001_follower_odometry.h"

#include <fmt/format.h>

#include <cmath>
#include <stdexcept>

#include "firmware_stub/encoder_counter.h"

namespace wheelhil::fw {
namespace {

using Mat3 = std::array<std::array<double, 3>, 3>;

// Row j of eq 2: (-sin beta_j, cos beta_j, d).
Mat3 RimMatrix(const FollowerGeometry& g) {
  Mat3 m{};
  for (int j = 0; j < 3; ++j) {
    m[j] = {-std::sin(g.angles_rad[j]), std::cos(g.angles_rad[j]), g.mount_radius_m};
  }
  return m;
}

double Det(const Mat3& m) {
  return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
         m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
         m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
}

// Adjugate over determinant.
Mat3 Inverse(const Mat3& m) {
  const double inv_det = 1.0 / Det(m);
  Mat3 r{};
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      const int a = (j + 1) % 3;
      const int b = (j + 2) % 3;
      const int c = (i + 1) % 3;
      const int e = (i + 2) % 3;
      r[i][j] = (m[a][c] * m[b][e] - m[a][e] * m[b][c]) * inv_det;
    }
  }
  return r;
}

FollowerTwist Apply(const Mat3& inv, const std::array<double, 3>& rim) {
  FollowerTwist t;
  t.vx_m_s = inv[0][0] * rim[0] + inv[0][1] * rim[1] + inv[0][2] * rim[2];
  t.vy_m_s = inv[1][0] * rim[0] + inv[1][1] * rim[1] + inv[1][2] * rim[2];
  t.omega_rad_s = inv[2][0] * rim[0] + inv[2][1] * rim[1] + inv[2][2] * rim[2];
  return t;
}

void RequirePositive(const char* field, double v) {
  if (!std::isfinite(v) || v <= 0.0) {
    throw std::invalid_argument(fmt::format("{} ({}) must be finite and > 0", field, v));
  }
}

}  // namespace

std::array<double, 3> FollowerRimSpeeds(const FollowerGeometry& g,
                                        const FollowerTwist& v_P) noexcept {
  const Mat3 m = RimMatrix(g);
  std::array<double, 3> rim{};
  for (int j = 0; j < 3; ++j) {
    rim[j] = m[j][0] * v_P.vx_m_s + m[j][1] * v_P.vy_m_s + m[j][2] * v_P.omega_rad_s;
  }
  return rim;
}

FollowerTwist BodyTwistFromRimSpeeds(const FollowerGeometry& g,
                                     const std::array<double, 3>& rim_m_s) noexcept {
  return Apply(Inverse(RimMatrix(g)), rim_m_s);
}

FollowerTwist WorldTwistFromRimSpeeds(const FollowerGeometry& g,
                                      const std::array<double, 3>& rim_m_s,
                                      double theta_rad) noexcept {
  const FollowerTwist b = BodyTwistFromRimSpeeds(g, rim_m_s);
  const double c = std::cos(theta_rad);
  const double s = std::sin(theta_rad);
  return {c * b.vx_m_s - s * b.vy_m_s, s * b.vx_m_s + c * b.vy_m_s, b.omega_rad_s};
}

FollowerTwist PaperToForwardTwist(const FollowerTwist& v_P) noexcept {
  return {v_P.vy_m_s, -v_P.vx_m_s, v_P.omega_rad_s};
}

Pose2 PaperToForwardPose(const Pose2& X_VP) noexcept {
  return {X_VP.y_m, -X_VP.x_m, X_VP.theta_rad};
}

FollowerOdometry::FollowerOdometry(const FollowerOdometryConfig& config) : config_(config) {
  RequirePositive("geometry.mount_radius_m", config.geometry.mount_radius_m);
  RequirePositive("follower_radius_m", config.follower_radius_m);
  RequirePositive("counts_per_rev", config.counts_per_rev);
  if (config.counter_bits < 1 || config.counter_bits > 64) {
    throw std::invalid_argument(
        fmt::format("counter_bits ({}) must be in [1, 64]", config.counter_bits));
  }
  for (int j = 0; j < 3; ++j) {
    if (!std::isfinite(config.geometry.angles_rad[j])) {
      throw std::invalid_argument(fmt::format("geometry.angles_rad[{}] ({}) must be finite", j,
                                              config.geometry.angles_rad[j]));
    }
  }
  const Mat3 m = RimMatrix(config.geometry);
  // det = d * (sum of sin(beta_j - beta_k) terms); normalise by d so the check is unit-free.
  if (std::abs(Det(m)) / config.geometry.mount_radius_m < 1e-6) {
    throw std::invalid_argument(
        "geometry.angles_rad: followers are degenerate (no three independent rolling directions)");
  }
  inverse_ = Inverse(m);
}

void FollowerOdometry::UpdateCounts(const std::array<std::uint64_t, 3>& raw_counts) noexcept {
  if (!primed_) {
    primed_ = true;
    last_raw_ = raw_counts;
    return;
  }
  std::array<std::int64_t, 3> delta{};
  for (int j = 0; j < 3; ++j) {
    delta[j] = CounterDelta(last_raw_[j], raw_counts[j], config_.counter_bits);
  }
  last_raw_ = raw_counts;
  StepDeltaCounts(delta);
}

void FollowerOdometry::StepDeltaCounts(const std::array<std::int64_t, 3>& delta_counts) noexcept {
  std::array<double, 3> rim{};
  for (int j = 0; j < 3; ++j) {
    rim[j] = CountsToMeters(delta_counts[j], config_.counts_per_rev, config_.follower_radius_m);
  }
  (void)StepRimDisplacements(rim);  // Finite by construction.
}

bool FollowerOdometry::StepRimDisplacements(const std::array<double, 3>& rim_m) noexcept {
  for (double v : rim_m) {
    if (!std::isfinite(v)) return false;
  }
  last_body_ = Apply(inverse_, rim_m);
  pose_ = AdvancePose(pose_, last_body_.vx_m_s, last_body_.vy_m_s, last_body_.omega_rad_s,
                      config_.heading_rule);
  return true;
}

void FollowerOdometry::Reset() noexcept {
  primed_ = false;
  pose_ = Pose2{};
  last_body_ = FollowerTwist{};
}

}  // namespace wheelhil::fw
