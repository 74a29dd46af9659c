#pragma once
/// Cross-engine check of the Mecanum contact: the same four steady motions on the same platform
/// in wheelhil (scenarios/platforms/mecanum4_mujoco_peer.yaml) and in MuJoCo (an explicit-roller
/// model generated in mujoco_mecanum.h), measured the same way. Each motion: settle 0.5 s at
/// zero command, step the wheel-speed command, run 5 s; the steady window is t = 1..5 s.
///   steady efficiency = progress in the window / ideal progress (along the ideal direction in
///                       the initial body frame; heading for the spin), %
///   ripple            = std of the per-step speed along that direction (yaw rate for the spin)
///                       in the window / its mean, %
///   steps_per_s       = physics steps of the 5 s run per wall second (the only timed part).
/// Not thread-safe (each measurement owns its world); deterministic apart from steps_per_s.

#include <array>
#include <string>

#include "emulator/platforms/platform.h"

namespace wheelhil::emulator::peers {

/// The measuring protocol both engines follow, s.
inline constexpr double kPeerSettle_s = 0.5;      ///< at zero command before the step
inline constexpr double kPeerRun_s = 5.0;         ///< after the command step
inline constexpr double kPeerSteadyFrom_s = 1.0;  ///< the steady window opens here

/// One steady motion: wheel-speed commands FL, FR, RL, RR (rad/s) and the ideal body twist.
struct PeerMotion {
  const char* name;
  std::array<double, 4> wheel_rad_s;
  double vx_m_s, vy_m_s, wz_rad_s;
};
/// forward 0.3 m/s, sideways right 0.3 m/s, clockwise spin 0.5 rad/s, diagonal front-right
/// 0.3 m/s: the MuJoCo peer bench's four (R 0.05 m, l1 + l2 = 0.47 m).
const std::array<PeerMotion, 4>& PeerMotions();

struct PeerMeasurement {
  double steady_efficiency_pct = 0;
  double ripple_pct = 0;
  double steps_per_s = 0;
};

/// Runs `motion` on `platform` (its four driven wheels in FL, FR, RL, RR order) on a flat plane
/// of friction mu (peak = slide) with fixed step dt_s.
PeerMeasurement MeasureWheelhil(const platforms::Platform& platform, const PeerMotion& motion,
                                double mu, double dt_s = 1e-3);

/// Accumulates the steady figures from per-step samples (shared by both engines). `heading` is
/// the body's yaw when the command started: the ideal direction is taken in that frame.
class SteadyWindow {
 public:
  SteadyWindow(const PeerMotion& motion, double heading) : motion_(motion), heading_(heading) {}
  /// Position (m) and unwrapped yaw (rad) when the window opens.
  void Start(double x, double y, double yaw);
  /// One step's planar velocity (world frame, m/s) and yaw rate (rad/s).
  void Sample(double vx_W, double vy_W, double wz);
  /// Position and yaw when the window closes, duration_s after it opened.
  PeerMeasurement Finish(double x, double y, double yaw, double duration_s) const;

 private:
  PeerMotion motion_;
  double heading_;
  double x0_ = 0, y0_ = 0, yaw0_ = 0;
  double sum_ = 0, sum2_ = 0;
  long n_ = 0;
};

/// The per-step rate along the motion: yaw rate for a spin, else the planar velocity (world
/// frame) projected on the ideal direction rotated by the initial heading yaw0.
double SpeedAlong(const PeerMotion& motion, double vx_W, double vy_W, double wz, double yaw0);

}  // namespace wheelhil::emulator::peers
