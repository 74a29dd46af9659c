#pragma once
/// Paper 001: dead reckoning from three passive omni follower wheels with encoders (see
/// docs/estimators.md and /work/shared/seeds/REFERENCE.md).
///
/// FRAME WARNING. Everything in this file uses the paper's frames, not the x-forward frame of the
/// rest of the firmware:
///   body frame P:  x_P to the robot's RIGHT, y_P FORWARD, z up; omega counter-clockwise.
///   world frame V: the P frame at the start; theta = angle from x_V to x_P (counter-clockwise),
///                  so at theta = 0 the robot faces +y_V.
/// PaperToForwardTwist / PaperToForwardPose convert to x-forward, y-left frames.
///
/// Follower j sits at angle beta_j (from x_P, counter-clockwise) on a circle of radius d around
/// the body centre and rolls along the counter-clockwise tangent u_j = (-sin beta_j, cos beta_j),
/// so its rim speed is v_j = u_j . (vx, vy) + d*omega. The paper's followers f, l, r sit at
/// beta = 90, 210, 330 deg (front, rear-left, rear-right), which gives its eq 2:
///   vf = -vx + d w,  vl = vx/2 - sqrt3/2 vy + d w,  vr = vx/2 + sqrt3/2 vy + d w.

#include <array>
#include <cstdint>

#include "firmware_stub/planar_pose.h"

namespace wheelhil::fw {

/// A velocity (or, per interval, a displacement) in the paper's frames: in P for body-frame
/// functions, in V for world-frame ones (see each function).
struct FollowerTwist {
  double vx_m_s = 0.0;
  double vy_m_s = 0.0;
  double omega_rad_s = 0.0;
};

/// Where the three followers are; angles in the paper's body frame P.
struct FollowerGeometry {
  double mount_radius_m = 0.0;  ///< d: centre to follower contact [m], > 0.
  std::array<double, 3> angles_rad = {1.5707963267948966, 3.6651914291880923,
                                      5.7595865315812871};  ///< beta_f, beta_l, beta_r.
};

/// Eq 2 (general angles): body twist in P -> follower rim speeds [m/s] (f, l, r order).
std::array<double, 3> FollowerRimSpeeds(const FollowerGeometry& g,
                                        const FollowerTwist& v_P) noexcept;

/// Inverse of eq 2: follower rim speeds -> body twist in P. Also maps rim displacements over an
/// interval to the body-frame displacement. Geometry must be non-degenerate (the
/// FollowerOdometry constructor checks; here a singular geometry gives non-finite values).
FollowerTwist BodyTwistFromRimSpeeds(const FollowerGeometry& g,
                                     const std::array<double, 3>& rim_m_s) noexcept;

/// Eq 5: follower rim speeds and heading theta -> world-frame velocity (x', y', theta') in V.
FollowerTwist WorldTwistFromRimSpeeds(const FollowerGeometry& g,
                                      const std::array<double, 3>& rim_m_s,
                                      double theta_rad) noexcept;

/// P (x right, y forward) -> x-forward, y-left body frame: (vy, -vx, omega).
FollowerTwist PaperToForwardTwist(const FollowerTwist& v_P) noexcept;
/// Pose in V -> pose in the x-forward world frame F (F = V turned by +90 deg, so the robot
/// starts facing +x_F): (y, -x, theta).
Pose2 PaperToForwardPose(const Pose2& X_VP) noexcept;

struct FollowerOdometryConfig {
  FollowerGeometry geometry;
  double follower_radius_m = 0.0;  ///< r [m], > 0.
  double counts_per_rev = 0.0;     ///< P [counts/rev], > 0.
  int counter_bits = 32;           ///< Width of each follower's wrapping counter, [1, 64].
  HeadingRule heading_rule = HeadingRule::kStart;  ///< Eq 8 uses theta_i.
};

/// Eq 8 dead reckoning: per sampling period, follower count deltas -> rim displacements
/// 2*pi*r*counts/P -> body-frame displacement (inverse eq 2) -> world pose in V, rotated at the
/// heading `heading_rule` says (the paper: theta_i, the heading at the start of the period).
/// Starts at pose (0, 0, 0). Thread-compatible; no allocation.
class FollowerOdometry {
 public:
  /// Throws std::invalid_argument naming the field on bad values or degenerate angles.
  explicit FollowerOdometry(const FollowerOdometryConfig& config);

  /// Raw counter readings (f, l, r). The first call only primes the counters. Wrap handled.
  void UpdateCounts(const std::array<std::uint64_t, 3>& raw_counts) noexcept;
  /// Already differenced counts (f, l, r) of one period.
  void StepDeltaCounts(const std::array<std::int64_t, 3>& delta_counts) noexcept;
  /// Rim displacements [m] of one period. Returns false, changing nothing, if one is not finite.
  [[nodiscard]] bool StepRimDisplacements(const std::array<double, 3>& rim_m) noexcept;

  /// Pose of P in V.
  const Pose2& pose() const { return pose_; }
  /// Body-frame displacement of the last period (in P; omega field = dtheta [rad]).
  const FollowerTwist& last_body_displacement() const { return last_body_; }
  void Reset() noexcept;

  const FollowerOdometryConfig& config() const { return config_; }

 private:
  FollowerOdometryConfig config_;
  std::array<std::array<double, 3>, 3> inverse_{};  // Inverse of the eq-2 matrix.
  bool primed_ = false;
  std::array<std::uint64_t, 3> last_raw_{};
  Pose2 pose_;
  FollowerTwist last_body_;
};

}  // namespace wheelhil::fw
