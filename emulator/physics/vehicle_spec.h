#pragma once
/// Plain data describing one wheeled vehicle for RollerVehicle: chassis, wheels, suspension,
/// motors. SI units throughout; the body frame B has x forward, y left, z up, origin at the
/// chassis centre of mass. Filled by the platform loader (emulator/platforms/platform.h) or by
/// hand in tests. Value type, thread-compatible.

#include <algorithm>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace wheelhil::emulator::physics {

/// How the contact between a wheel and the floor carries force.
enum class WheelKind {
  kConventional,  ///< tyre: friction along and across the rolling direction (friction circle)
  kMecanum,  ///< rollers at roller_angle (+-45 deg) to the axle: force only along the roller axis
  kOmni,     ///< rollers along the rim (90 deg): force only along the rolling direction
  kOrthogonal,  ///< orthogonal-wheel assembly: like omni, two half wheels take turns (paper 002)
  kCaster,      ///< swivel/ball caster: carries load, only rolling resistance, no spin state
};

/// Raycast suspension along -z_B from the mount point. Lengths are mount -> wheel centre.
/// The spring force is stiffness*(free_length - length) (free_length > max_length = preload);
/// below min_length the bump stop adds bump_stiffness*(min_length - length). The wheel hub has
/// mass hub_mass_kg (unsprung), so a weak spring lets the wheel leave the floor over a crest; the
/// hub meets the floor through a stiff tyre spring-damper (integrated implicitly).
struct SuspensionSpec {
  double free_length_m = 0.10;
  double min_length_m = 0.02;  ///< bump stop engages below this
  double max_length_m = 0.12;  ///< droop stop: the wheel hangs here
  double stiffness_n_m = 2.0e4;
  double damping_n_s_m = 4.0e2;
  double bump_stiffness_n_m = 2.0e5;
  double hub_mass_kg = 0.3;
  /// Tyre/roller contact compliance between hub and floor: N = k*penetration + c*rate, >= 0.
  double tire_stiffness_n_m = 2.0e5;
  double tire_damping_n_s_m = 300;
};

/// Driven-wheel motor: a PI speed servo at the wheel, torque = speed_gain*(cmd - omega) +
/// integral_gain*integral(cmd - omega), the proportional part solved implicitly together with the
/// contacts, behind a gear, saturated by the wheel-side torque limit, the current limit
/// (torque = gear_ratio * torque_constant * current) and, when winding_resistance_ohm > 0, the
/// supply voltage against the back-EMF (anti-windup: the integral is clamped to the same window).
struct MotorSpec {
  double gear_ratio = 1.0;             ///< motor turns per wheel turn
  double torque_constant_nm_a = 0.05;  ///< = back-EMF constant in V*s/rad
  double max_current_a = 10.0;
  double max_torque_nm = 1e9;        ///< wheel side
  double rotor_inertia_kg_m2 = 0.0;  ///< reflected to the wheel as gear_ratio^2 * this
  double supply_voltage_v = 24.0;
  double winding_resistance_ohm = 0.0;  ///< 0 = no voltage limit
  double max_accel_rad_s2 = 0.0;        ///< slew limit of the command at the wheel, 0 = none
  double speed_gain_nm_s_rad = 30.0;    ///< proportional gain, wheel side
  double integral_gain_nm_rad = 300.0;  ///< integral gain, wheel side

  /// The wheel-side torque it can give at all: the torque limit or the current limit's torque,
  /// whichever is lower (the supply voltage narrows it further with speed).
  double TorqueLimitNm() const {
    return std::min(max_torque_nm, torque_constant_nm_a * gear_ratio * max_current_a);
  }
};

/// Discrete rollers of a Mecanum or omni wheel (emulator/physics/roller_geometry.h has the
/// geometry). count 0 is the continuous limit: the contact stays below the hub at the wheel's
/// radius and the nominal roller angle, and the rollers turn freely.
struct RollerSpec {
  int count = 0;             ///< rollers per row; 0 = continuous
  double length_m = 0;       ///< along the roller's axis
  double radius_m = 0;       ///< largest radius; 0 = the envelope matches the wheel's radius
  int rows = 1;              ///< 2: two rows, the second staggered by half a pitch ("double" wheel)
  double row_offset_m = 0;   ///< rows sit at +-this along the axle (rows: 2)
  double inertia_kg_m2 = 0;  ///< one roller about its axis; 0 = no spin state (turns freely)
  double bearing_friction_nm = 0;   ///< Coulomb torque on a roller's spin
  double bearing_viscous_nm_s = 0;  ///< viscous torque per rad/s of a roller's spin
};

/// One wheel (or caster, or orthogonal-wheel assembly).
struct WheelSpec {
  std::string name;
  WheelKind kind = WheelKind::kConventional;
  Eigen::Vector3d mount_B = Eigen::Vector3d::Zero();  ///< suspension mount point in B, m
  double heading_rad = 0.0;  ///< rolling direction in B, about z_B; positive spin rolls along it
  double radius_m = 0.05;
  double inertia_kg_m2 = 1e-3;         ///< about the axle (wheel only; motor rotor adds to it)
  double roller_angle_rad = 0.0;       ///< Mecanum: +-pi/4 measured from the axle; omni: pi/2
  double rolling_resistance = 0.01;    ///< coefficient: force = c*N along free directions
  double bearing_friction_nm = 0.001;  ///< Coulomb torque on the spin
  double bearing_viscous_nm_s = 0.0;   ///< viscous torque per rad/s on the spin
  double lateral_mu_scale = 1.0;  ///< conventional: friction ellipse lateral/longitudinal ratio
  // Orthogonal wheel only: the active half wheel switches every pi/2 of wheel angle; the rolling
  // radius is short by up to handover_dip_m inside a zone of handover_zone_rad of wheel angle
  // centred on each hand-over: radius - dip*(1 - psi/(zone/2))^2 at psi (angle to the nearest
  // hand-over) < zone/2, the full radius elsewhere. zone = pi/2 (the default) dips across the
  // whole segment: radius - dip*(4phi/pi)^2 at phase phi in [-pi/4, pi/4). The contact sits
  // half_offset_m along the axle (+ for one half, - for the other).
  double handover_dip_m = 0.0;
  double handover_zone_rad = 1.5707963267948966;
  double half_offset_m = 0.0;
  RollerSpec rollers;  ///< Mecanum and omni only
  bool driven = false;
  MotorSpec motor;
  SuspensionSpec suspension;
};

/// Whole vehicle.
struct VehicleSpec {
  std::string name;
  double mass_kg = 10.0;  ///< sprung (chassis) mass; hub masses come on top
  Eigen::Vector3d inertia_kg_m2 = Eigen::Vector3d(0.1, 0.1, 0.1);  ///< principal, about COM, in B
  Eigen::Vector3d half_extents_m =
      Eigen::Vector3d(0.2, 0.15, 0.05);  ///< chassis box (not colliding)
  std::vector<WheelSpec> wheels;
  double slip_threshold_m_s = 0.02;     ///< ground-truth slip flag: |slip velocity| above this
  double stribeck_velocity_m_s = 0.05;  ///< slip-curve decay from peak to sliding mu
  int solver_iterations = 10;
};

}  // namespace wheelhil::emulator::physics
