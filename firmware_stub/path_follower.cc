#include "firmware_stub/path_follower.h"

#include <algorithm>
#include <cmath>

namespace wheelhil::fw {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kTurnInPlaceRad = 60.0 * kPi / 180.0;
/// Least speed on the last centimetres of a leg not yet ended, so the sqrt profile cannot stall
/// short of its end [m/s].
constexpr double kCreepSpeedMs = 0.02;

double Wrap(double a) { return std::remainder(a, 2.0 * kPi); }

}  // namespace

PathFollower::PathFollower(const PathSettings& path, bool holonomic)
    : path_(path), holonomic_(holonomic) {}

Waypoint PathFollower::LegStart() const {
  if (leg_ == 0) return Waypoint{};
  return path_.waypoints[leg_ - 1];
}

double PathFollower::TargetHeading() const {
  const Waypoint& w = path_.waypoints[leg_];
  return w.has_theta ? w.theta_rad : held_heading_rad_;
}

BodyVelocity PathFollower::Step(const Pose2& X, double dt_s) {
  BodyVelocity cmd;
  while (!done()) {
    const Waypoint a = LegStart();
    const Waypoint& b = path_.waypoints[leg_];
    const double dx = b.x_m - a.x_m, dy = b.y_m - a.y_m;
    const double length = std::hypot(dx, dy);
    const double ux = length > 0 ? dx / length : 0.0, uy = length > 0 ? dy / length : 0.0;
    const double along = std::clamp((X.x_m - a.x_m) * ux + (X.y_m - a.y_m) * uy, 0.0, length);
    const double remaining = length - along;
    const double to_end = std::hypot(b.x_m - X.x_m, b.y_m - X.y_m);
    // Heading error to the target, not wrapped: a theta of -2 pi means a full turn. A
    // differential drive without a theta ends its leg facing wherever the leg took it.
    const bool heading_matters = holonomic_ || b.has_theta;
    const double heading_error = heading_matters ? TargetHeading() - X.theta_rad : 0.0;
    const bool at_end = remaining <= path_.tolerance_m || to_end <= path_.tolerance_m;
    if (at_end && std::abs(heading_error) <= path_.heading_tolerance_rad) {
      held_heading_rad_ = heading_matters ? TargetHeading() : X.theta_rad;
      speed_m_s_ = 0.0;
      ++leg_;
      continue;  // The next leg starts in this same cycle.
    }
    const double turn = std::clamp(path_.heading_gain_1_s * heading_error, -path_.yaw_rate_rad_s,
                                   path_.yaw_rate_rad_s);
    if (at_end) {  // Only the heading is left to reach.
      speed_m_s_ = 0.0;
      cmd.omega_rad_s = turn;
      return cmd;
    }
    // Trapezoid along the leg: ramp up, and never faster than stopping at its end allows.
    const double stop_cap = std::sqrt(2.0 * path_.accel_m_s2 * remaining);
    speed_m_s_ = std::min({path_.speed_m_s, stop_cap, speed_m_s_ + path_.accel_m_s2 * dt_s});
    if (stop_cap < kCreepSpeedMs) speed_m_s_ = std::min(kCreepSpeedMs, path_.speed_m_s);
    const double carry = std::min(along + path_.lookahead_m, length);
    const double cx = a.x_m + ux * carry - X.x_m, cy = a.y_m + uy * carry - X.y_m;
    const double reach = std::hypot(cx, cy);
    if (reach <= 0) return cmd;
    const double c = std::cos(X.theta_rad), s = std::sin(X.theta_rad);
    const double bx = c * cx + s * cy, by = -s * cx + c * cy;  // Carrot in the body frame.
    if (holonomic_) {
      cmd.vx_m_s = speed_m_s_ * bx / reach;
      cmd.vy_m_s = speed_m_s_ * by / reach;
      cmd.omega_rad_s = turn;
      return cmd;
    }
    const double bearing = std::atan2(by, bx);
    if (std::abs(Wrap(bearing)) > kTurnInPlaceRad) {
      speed_m_s_ = 0.0;
      cmd.omega_rad_s =
          std::clamp(path_.heading_gain_1_s * bearing, -path_.yaw_rate_rad_s, path_.yaw_rate_rad_s);
      return cmd;
    }
    cmd.vx_m_s = speed_m_s_;
    cmd.omega_rad_s = std::clamp(2.0 * speed_m_s_ * std::sin(bearing) / reach,
                                 -path_.yaw_rate_rad_s, path_.yaw_rate_rad_s);
    return cmd;
  }
  speed_m_s_ = 0.0;
  return cmd;
}

void WheelSpeedsFor(const DriveSettings& d, const BodyVelocity& v, double* out) {
  double peak = 0.0;
  for (std::size_t i = 0; i < d.nodes.size(); ++i) {
    const DriveNodeSettings& n = d.nodes[i];
    // Contact point velocity, then its component the wheel cannot slide along: the rolling
    // direction f for a conventional wheel, the normal to the roller axis u for rollers.
    const double vx = v.vx_m_s - v.omega_rad_s * n.y_m;
    const double vy = v.vy_m_s + v.omega_rad_s * n.x_m;
    const double fx = std::cos(n.heading_rad), fy = std::sin(n.heading_rad);
    double w = vx * fx + vy * fy;
    if (n.has_rollers) {
      const double ca = std::cos(n.roller_angle_rad), sa = std::sin(n.roller_angle_rad);
      const double ux = -ca * fy + sa * fx, uy = ca * fx + sa * fy;
      w = (vx * ux + vy * uy) / sa;
    }
    out[i] = n.sign * w / d.wheel_radius_m;
    peak = std::max(peak, std::abs(out[i]));
  }
  if (d.max_wheel_speed_rad_s > 0 && peak > d.max_wheel_speed_rad_s) {
    // Scale all together so the body keeps its direction of motion.
    const double k = d.max_wheel_speed_rad_s / peak;
    for (std::size_t i = 0; i < d.nodes.size(); ++i) out[i] *= k;
  }
}

}  // namespace wheelhil::fw
