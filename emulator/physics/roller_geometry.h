#pragma once
/// Where a wheel with discrete rollers touches a flat floor, as a function of the wheel's spin
/// angle: the roller in contact, the rolling radius, the contact's offsets from below the wheel
/// centre and the effective roller angle. Pure functions of the geometry, no state.
///
/// Model. `count` rollers per row sit at equal pitch 2*pi/count around the axle, their centres at
/// `centre_radius` from it. Each roller is an ellipsoid of revolution about its own axis (radius
/// `a`, half-length `b`), the axis in the plane tangent to the wheel at the roller's centre, at
/// the roller angle alpha from the axle (+-45 deg Mecanum, 90 deg omni). With the default radius
/// the rollers' envelope is the wheel's cylinder of radius R to second order,
///   a^2 cos^2(alpha) - R a + b^2 sin^2(alpha) = 0,  centre_radius = R - a,
/// as on a real Mecanum wheel (and on the MuJoCo peer model). For a roller at phase phi (wheel
/// angle past the one where its centre is lowest), with S = sqrt(a^2 + (b^2 - a^2) sin^2(alpha)
/// sin^2(phi)):
///   rolling radius  h   = centre_radius cos(phi) + S             (support of the ellipsoid)
///   along the axle  y   = (b^2 - a^2) sin(alpha) cos(alpha) sin(phi) / S  (+ the row offset)
///   forward         x   = -centre_radius sin(phi) + (b^2 - a^2) sin^2(alpha) sin(phi) cos(phi) / S
///   roller angle        tan(alpha_eff) = tan(alpha) cos(phi)     (axis projected on the floor)
///   roller radius   rho = a^2 sqrt(1 - sin^2(alpha) sin^2(phi)) / S  (contact to roller axis)
/// The floor touches the lowest roller (the largest h over every row's nearest rollers); the
/// contact jumps to the next roller at the hand-over. Two rows (a "double" omni or Mecanum
/// wheel) sit at +-row_offset along the axle, the second staggered by half a pitch.
///
/// Frames: the wheel's own, x along the rolling direction, y along the axle, z up; angles in
/// rad, positive spin rolls the wheel forward. Thread-safe (no state).

#include "emulator/physics/vehicle_spec.h"

namespace wheelhil::emulator::physics {

/// Derived, validated geometry of one wheel's rollers.
struct RollerGeometry {
  int count = 0;  ///< per row
  int rows = 1;
  double wheel_radius_m = 0;
  double roller_angle_rad = 0;
  double roller_radius_m = 0;  ///< a
  double half_length_m = 0;    ///< b
  double centre_radius_m = 0;  ///< distance of a roller centre from the axle
  double row_offset_m = 0;
  double sin_angle = 1, cos_angle = 0;  ///< of roller_angle_rad, once rather than per contact
  bool nearest_is_lowest = true;  ///< h falls with |phase| over 1.5 pitches: one roller per row
};

/// The contact of a wheel at one spin angle.
struct RollerContact {
  int roller = 0;        ///< row * count + k; roller k of row 0 is lowest at angle 0
  double phase_rad = 0;  ///< wheel angle past the one where this roller's centre is lowest
  double rolling_radius_m = 0;
  double lateral_offset_m = 0;  ///< along the axle (left of the rolling direction)
  double forward_offset_m = 0;  ///< along the rolling direction
  double roller_cos = 0;       ///< cosine and sine of the effective roller angle, measured from the
  double roller_sin = 1;       ///< axle like WheelSpec::roller_angle_rad
  double roller_radius_m = 0;  ///< contact point to the roller's axis
  [[nodiscard]] double roller_angle_rad() const noexcept;
};

/// Geometry of wheel w's rollers (w.rollers.count > 0). Throws std::invalid_argument naming
/// `where` and the field when the rollers cannot form such a wheel (a roller longer than the
/// envelope allows, a radius not below the wheel's, too few rollers to cover the rim).
RollerGeometry MakeRollerGeometry(const WheelSpec& w, const std::string& where);

/// Contact of roller `roller` (row * count + k) at wheel angle `angle_rad`.
RollerContact RollerContactAt(const RollerGeometry& g, int roller, double angle_rad) noexcept;

/// The contact of the lowest roller at wheel angle `angle_rad`.
RollerContact LowestRollerContact(const RollerGeometry& g, double angle_rad) noexcept;

}  // namespace wheelhil::emulator::physics
