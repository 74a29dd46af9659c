#pragma once
/// Platform files: a YAML description of one robot (chassis, wheels, suspension, motors,
/// kinematics, sensor mounts) turned into a physics::VehicleSpec plus what the command path
/// and the sensors need. Every quantity carries its unit in the key (mass_kg, heading_deg, ...).
/// The three papers' platforms ship in scenarios/platforms/ (diff2, mecanum4_omni3, ortho3).
/// Load errors throw std::invalid_argument "file:line:col: field: problem". Body frame B: x
/// forward, y left, z up, origin at the chassis centre of mass. Value types, thread-compatible.

#include <cstdint>
#include <string>
#include <vector>

#include <yaml-cpp/yaml.h>
#include <Eigen/Core>

#include "emulator/physics/roller_vehicle.h"
#include "emulator/physics/vehicle_spec.h"

namespace wheelhil::emulator::platforms {

enum class KinematicsKind { kDiffDrive, kMecanum4, kOmni3 };

/// A sensor mounting point (gyro, accelerometer, ...), in B.
struct SensorMount {
  std::string name;
  std::string kind;                                      ///< "gyro", "accelerometer", ...
  Eigen::Vector3d position_B = Eigen::Vector3d::Zero();  ///< m
  Eigen::Vector3d axis_B = Eigen::Vector3d::UnitZ();     ///< unit sensitive axis
};

/// Manufacturing and mounting tolerances of a platform file's `tolerances:` block: +- limits
/// that each run draws uniformly and independently for every wheel (DrawWheelDeviations). They
/// are the systematic odometry errors of UMBmark (unequal wheel diameters, an uncertain track or
/// wheelbase) and those of roller wheels (mounting angle, roller angle). 0 = exact.
struct PlatformTolerances {
  double radius_m = 0;     ///< every wheel's radius
  double mount_m = 0;      ///< x and y of every wheel's mount (track, wheelbase, follower radius)
  double heading_rad = 0;  ///< every wheel's mounting angle
  double roller_angle_rad = 0;  ///< Mecanum and omni wheels' roller angle
  [[nodiscard]] bool any() const noexcept {
    return radius_m > 0 || mount_m > 0 || heading_rad > 0 || roller_angle_rad > 0;
  }
};

/// One wheel's drawn deviation from its nominal geometry.
struct WheelDeviation {
  double radius_m = 0;
  double mount_x_m = 0;
  double mount_y_m = 0;
  double heading_rad = 0;
  double roller_angle_rad = 0;
};

struct Platform {
  std::string name;
  std::string description;
  std::string source_file;
  std::string chassis_mesh;  ///< as written in the file (relative to the repository root)
  physics::VehicleSpec vehicle;
  KinematicsKind kinematics = KinematicsKind::kDiffDrive;
  std::vector<std::size_t> drive_wheels;    ///< indices into vehicle.wheels
  std::vector<std::size_t> encoder_wheels;  ///< wheels with an encoder shaft
  std::vector<SensorMount> sensors;
  PlatformTolerances tolerances;
  /// Named kinematic parameters from the `kinematics:` block (track_m, l1_m, l2_m, d_m, ...).
  std::vector<std::pair<std::string, double>> parameters;
  [[nodiscard]] double parameter(const std::string& key) const;                ///< throws if absent
  [[nodiscard]] std::size_t wheel_index(const std::string& wheel_name) const;  ///< throws
};

/// Planar body twist in B: forward, left, counter-clockwise.
struct BodyTwist {
  double vx_m_s = 0;
  double vy_m_s = 0;
  double wz_rad_s = 0;
};

/// Loads a platform file. Throws std::invalid_argument naming file, line and field.
/// `overrides` (a YAML mapping, or undefined/null for none) is deep-merged into the file before
/// it is read, so a scenario or campaign can vary e.g. a spring stiffness without a copy of the
/// file: mappings merge key by key, scalars and lists replace, a key the file lacks is added and
/// then checked like any other. Under `wheels` (a list in the file) the override is a mapping
/// from a wheel name, or an fnmatch glob such as `follower_*`, to that wheel's overrides; a name
/// matching no wheel is an error. Errors in overridden values carry the override's line.
Platform LoadPlatformFile(const std::string& path, const YAML::Node& overrides = YAML::Node());
/// Parses platform YAML text; `file` is used in error messages. `overrides` as above.
Platform LoadPlatformYaml(const std::string& text, const std::string& file,
                          const YAML::Node& overrides = YAML::Node());

/// Draws every wheel's deviation within platform.tolerances from `seed` (uniform, independent,
/// the same seed gives the same draws on any machine).
std::vector<WheelDeviation> DrawWheelDeviations(const Platform& platform, std::uint64_t seed);
/// The vehicle with the deviations applied (one per wheel, in wheel order): the robot as built.
/// The platform's kinematic parameters stay nominal: they are what the firmware believes.
physics::VehicleSpec AsBuilt(const physics::VehicleSpec& nominal,
                             const std::vector<WheelDeviation>& deviations);

/// No-slip spin rate (rad/s) of any wheel for a body twist: the rim speed the contact point's
/// motion implies along the wheel's constrained direction, divided by the radius. Conventional:
/// (v_c . f)/r; Mecanum/omni/orthogonal: (v_c . u)/(r sin(alpha)); caster: 0.
double WheelSpeedForTwist(const physics::WheelSpec& wheel, const BodyTwist& twist) noexcept;
/// Rim speed (m/s) = WheelSpeedForTwist * radius.
double RimSpeedForTwist(const physics::WheelSpec& wheel, const BodyTwist& twist) noexcept;

/// Inverse kinematics: commanded speed for every wheel (0 for passive ones), in wheel order.
/// For the Mecanum drive this is paper 001 eq 1, for diff2 the differential drive, for ortho3
/// the 3-wheel omni equivalent (all follow from WheelSpeedForTwist).
std::vector<double> InverseKinematics(const Platform& platform, const BodyTwist& twist);
/// Sends InverseKinematics(twist) to the vehicle's driven wheels.
void CommandTwist(physics::RollerVehicle& vehicle, const Platform& platform,
                  const BodyTwist& twist) noexcept;

}  // namespace wheelhil::emulator::platforms
