#pragma once
/// Platforms from a robot's own description: a platform file that names a URDF file
/// (`urdf: robot.urdf`, read by urdfdom) or an SDF file (`sdf: robot.sdf`, `model: NAME` when
/// it holds several; read by libsdformat) takes its chassis and wheels from it, and what the
/// description cannot say (which joints are wheels and of which kind, motors, suspension,
/// encoders, kinematics, sensors, tolerances) from the platform file itself, the overlay
/// (docs/platforms-from-urdf-sdf.md).
///
/// From the description:
/// - the chassis: every link not under a wheel joint, lumped into one rigid body (mass, centre
///   of mass, inertia by the parallel-axis theorem) at the joints' zero positions; the body
///   frame B is the base link's frame moved to that centre of mass. `half_extents_m` from the
///   base link's collision box, `mesh` from its collision (else visual) mesh, its package://,
///   model://, file:// or relative path resolved (package_paths, then the file's directory).
/// - each wheel named by `joint:` (a continuous joint, or an SDF revolute one without limits;
///   a caster's may sit below a swivel): the spin axis and the mount from the joint's frame,
///   the radius from the child link's collision cylinder or sphere, the mass
///   (suspension.hub_mass_kg) and the inertia about the spin axis from the child link and
///   everything under it. The joint's frame is at the wheel centre with the suspension hanging
///   at max_length_m (the robot lifted off the floor), so the mount is max_length_m above it.
///   heading_deg: positive joint rotation rolls along it.
/// Positions are rounded to the nanometre and angles to the nano-degree, so a description and
/// a platform YAML that state the same numbers give the same platform, bit for bit.
/// A value both the description and the overlay give must agree (1e-9 relative; headings
/// modulo 360 deg), or the error names both places; the overlay's chassis.inertia_kg_m2
/// replaces a lumped inertia that is not diagonal in B.
/// Not thread-safe: urdfdom reports through console_bridge's one process-wide log handler.

#include <string>
#include <vector>

#include <yaml-cpp/yaml.h>
#include <Eigen/Core>

#include "bus/yaml_fields.h"

namespace wheelhil::emulator::platforms {

/// When `root` (a platform document, overrides merged) has a `urdf:` or `sdf:` key: reads that
/// file (relative to the directory of rd.file()) and fills `root`'s chassis, name and the
/// wheels that name a `joint:` from it, then removes the keys only this step reads (urdf, sdf,
/// model, base_link, package_paths, wheels[].joint), leaving a document the platform reader
/// reads as any other. Throws std::invalid_argument "file:line:col: field: problem" at the
/// overlay's field, with the description's file, line and link or joint in the problem.
void ImportRobotDescription(YAML::Node root, const bus::yaml::FieldReader& rd);

/// A joint of a robot description that may be a wheel: continuous, with a horizontal axis and
/// a collision cylinder or sphere on its child link.
struct WheelJoint {
  std::string joint;
  Eigen::Vector3d centre_m = Eigen::Vector3d::Zero();  ///< in the root (canonical) link's frame
  Eigen::Vector3d axis = Eigen::Vector3d::UnitY();     ///< the same frame, unit
  double radius_m = 0;
  bool below_moving_joint = false;  ///< under a swivel: a caster's
};

/// The wheel joints of the URDF (or, for a .sdf file, the SDF model `model_name`, "" for the
/// file's own) at `path`, in joint-name order; `base_has_box`: the root link has a collision
/// box (the chassis' half extents). Throws std::invalid_argument naming the file.
std::vector<WheelJoint> FindWheelJoints(const std::string& path, const std::string& model_name,
                                        bool* base_has_box);

}  // namespace wheelhil::emulator::platforms
