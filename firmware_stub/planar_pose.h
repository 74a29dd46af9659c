#pragma once
/// Planar pose and the one-step dead-reckoning update shared by the paper-000 and paper-001
/// estimators. Pure functions, thread-safe.

namespace wheelhil::fw {

/// Pose of the body frame B in the world frame W: origin (x_m, y_m) in W, heading theta_rad =
/// angle from the W x axis to the B x axis, counter-clockwise positive, not wrapped (it
/// accumulates, so turns can be counted).
struct Pose2 {
  double x_m = 0.0;
  double y_m = 0.0;
  double theta_rad = 0.0;
};

/// How the heading is taken over one sampling interval when a body-frame displacement is turned
/// into a world-frame one.
enum class HeadingRule {
  /// Heading at the start of the interval, theta_i (paper 001 eq 8). Error O(dtheta) per step.
  kStart,
  /// Heading at the middle, theta_i + dtheta/2 (paper 000). Exact direction of the chord of a
  /// constant-twist step; its length is over-estimated by a factor 1/sinc(dtheta/2).
  kMidpoint,
  /// Midpoint heading and the chord length ds*sin(h)/h, h = dtheta/2: the exact SE(2) update
  /// for a twist that is constant over the interval (not in the papers; strictly better).
  kExactArc,
};

/// Advances `X_WB` by the body-frame displacement (dx_B_m, dy_B_m) and heading change
/// dtheta_rad accumulated over one interval: X_WB.xy += Rot(theta*) * c * (dx_B, dy_B),
/// X_WB.theta += dtheta, with theta* and c (1, or sinc) as `rule` says.
Pose2 AdvancePose(const Pose2& X_WB, double dx_B_m, double dy_B_m, double dtheta_rad,
                  HeadingRule rule) noexcept;

}  // namespace wheelhil::fw
