#pragma once
/// The MuJoCo peer of the Mecanum platform (built only where Debian's libmujoco-dev is
/// installed: WHEELHIL_HAVE_MUJOCO). The model is the explicit-roller one of the peer study
/// (docs/physics.md, "Cross-engine check"): a 0.6 x 0.5 x 0.1 m, 20 kg chassis box on a free
/// joint; four wheels R = 0.05 m on hinges with 0.01 kg m^2 armature and a <velocity kv=5>
/// actuator; per wheel `rollers` passive ellipsoid rollers (10 g, damping 1e-5, armature 1e-6)
/// whose envelope is the wheel's cylinder to second order; Euler, MuJoCo's default contact
/// softness. Not thread-safe (a model per call).

#include <string>

#include "emulator/peers/mecanum_peer.h"

namespace wheelhil::emulator::peers {

/// The peer model's settings. The elliptic friction cone is the default: MuJoCo's pyramidal
/// cone (the peer study's setting) loses speed with friction in every motion, 0.7-1.3 points
/// from mu 0.1 to 1.5, where the elliptic cone's figures stay within 0.1 point at every
/// friction (docs/physics.md, "Cross-engine check").
struct MujocoPeerOptions {
  double mu = 0.8;  ///< floor and roller friction
  double dt_s = 1e-3;
  int rollers = 10;  ///< per wheel
  bool elliptic_cone = true;
};

/// MJCF text of the peer model.
std::string MujocoMecanumModel(const MujocoPeerOptions& options);

/// Runs `motion` in MuJoCo, measured as MeasureWheelhil does. Throws std::runtime_error when
/// MuJoCo cannot load the model (its message) or the state turns non-finite.
PeerMeasurement MeasureMujoco(const PeerMotion& motion, const MujocoPeerOptions& options);

}  // namespace wheelhil::emulator::peers
