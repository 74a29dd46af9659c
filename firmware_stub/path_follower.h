#pragma once
/// The reference firmware's motion controller: follows a list of waypoints from the firmware's
/// own pose estimate (world frame W: the start pose is the origin, heading 0) and gives the body
/// velocity to command, one call per control cycle. Pure; no bus, no clock; thread-compatible.
///
/// Each waypoint is a leg from the previous one (the first from the origin), driven and stopped
/// at its end, as the papers' motions are: the speed along the leg is a trapezoid (accel_m_s2 up
/// to speed_m_s, then down so as to stop at the end: v <= sqrt(2 a d) for the remaining d), the
/// direction aims at a carrot lookahead_m further along the leg from the estimate's projection,
/// which pulls the robot back onto the line. Holonomic (Mecanum, omni): it translates toward
/// the carrot in any direction and holds the heading (or turns to the waypoint's theta, at most
/// yaw_rate, heading_gain proportional). Differential drive: pure pursuit (yaw rate = 2 v
/// sin(alpha) / distance to the carrot, alpha its bearing), turning in place first when the leg
/// lies more than 60 deg off the heading, and at the end to the waypoint's theta if it has one.
/// A leg ends within tolerance_m of its end (and heading_tolerance of its theta); the path ends
/// after the last leg, and the command is zero from then on.

#include <cstddef>

#include "firmware_stub/fw_config.h"
#include "firmware_stub/planar_pose.h"

namespace wheelhil::fw {

/// Body velocity (x forward, y left, yaw CCW) [m/s, rad/s].
struct BodyVelocity {
  double vx_m_s = 0.0, vy_m_s = 0.0, omega_rad_s = 0.0;
};

class PathFollower {
 public:
  PathFollower(const PathSettings& path, bool holonomic);

  /// The command for the next dt_s from the estimate X_WB.
  BodyVelocity Step(const Pose2& X_WB, double dt_s);

  bool done() const { return leg_ >= path_.waypoints.size(); }
  std::size_t leg() const { return leg_; }
  /// Speed along the leg commanded last [m/s].
  double speed_m_s() const { return speed_m_s_; }

 private:
  Waypoint LegStart() const;
  double TargetHeading() const;

  PathSettings path_;
  bool holonomic_;
  std::size_t leg_ = 0;
  double speed_m_s_ = 0.0;
  double held_heading_rad_ = 0.0;  // Heading of the leg's start (the last theta reached).
};

/// Wheel speeds [rad/s] of the drives' wheels for a body velocity: with the contact point's
/// velocity c = (vx - w y, vy + w x), a conventional wheel rolling along f (its heading) turns at
/// c.f / R; a wheel with rollers at angle a to its axle at c.u / (R sin a), u = the roller
/// normal (heading 0: (vx - w y + (vy + w x) cot a) / R). Times each drive's sign.
void WheelSpeedsFor(const DriveSettings& drives, const BodyVelocity& v, double* out_rad_s);

}  // namespace wheelhil::fw
