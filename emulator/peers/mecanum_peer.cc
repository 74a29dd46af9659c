#include "emulator/peers/mecanum_peer.h"

#include <chrono>
#include <cmath>
#include <stdexcept>

#include <fmt/format.h>

#include "emulator/physics/physics_world.h"

namespace wheelhil::emulator::peers {

const std::array<PeerMotion, 4>& PeerMotions() {
  constexpr double R = 0.05, k = 0.47, V = 0.3, W = 0.5;
  constexpr double vs = V / R, ws = W * k / R;
  static const double vd = V * std::sqrt(2.0) / R;
  static const double s2 = std::sqrt(0.5);
  static const std::array<PeerMotion, 4> motions = {{
      {"forward", {vs, vs, vs, vs}, V, 0, 0},
      {"sideways", {vs, -vs, -vs, vs}, 0, -V, 0},
      {"spin", {ws, -ws, ws, -ws}, 0, 0, -W},
      {"diagonal", {vd, 0, 0, vd}, V * s2, -V * s2, 0},
  }};
  return motions;
}

double SpeedAlong(const PeerMotion& m, double vx_W, double vy_W, double wz, double yaw0) {
  if (m.wz_rad_s != 0) return wz;
  const double n = std::hypot(m.vx_m_s, m.vy_m_s);
  const double c = std::cos(yaw0), s = std::sin(yaw0);
  const double ux = (c * m.vx_m_s - s * m.vy_m_s) / n, uy = (s * m.vx_m_s + c * m.vy_m_s) / n;
  return vx_W * ux + vy_W * uy;
}

void SteadyWindow::Start(double x, double y, double yaw) {
  x0_ = x;
  y0_ = y;
  yaw0_ = yaw;
  sum_ = sum2_ = 0;
  n_ = 0;
}

void SteadyWindow::Sample(double vx_W, double vy_W, double wz) {
  const double speed = SpeedAlong(motion_, vx_W, vy_W, wz, heading_);
  sum_ += speed;
  sum2_ += speed * speed;
  ++n_;
}

PeerMeasurement SteadyWindow::Finish(double x, double y, double yaw, double duration_s) const {
  const PeerMotion& m = motion_;
  PeerMeasurement out;
  double progress = 0, ideal = 0;
  if (m.wz_rad_s != 0) {
    progress = yaw - yaw0_;
    ideal = m.wz_rad_s * duration_s;
  } else {
    progress = SpeedAlong(m, x - x0_, y - y0_, 0, heading_);
    ideal = std::hypot(m.vx_m_s, m.vy_m_s) * duration_s;
  }
  out.steady_efficiency_pct = 100 * progress / ideal;
  if (n_ > 1) {
    const double mean = sum_ / static_cast<double>(n_);
    const double var = std::max(0.0, sum2_ / static_cast<double>(n_) - mean * mean);
    out.ripple_pct = 100 * std::sqrt(var) / std::abs(mean);
  }
  return out;
}

PeerMeasurement MeasureWheelhil(const platforms::Platform& platform, const PeerMotion& motion,
                                double mu, double dt_s) {
  if (platform.drive_wheels.size() != 4) {
    throw std::invalid_argument(
        fmt::format("{}: the peer motions need 4 driven wheels", platform.source_file));
  }
  physics::WorldOptions options;
  options.step_s = dt_s;
  physics::PhysicsWorld world(options);
  world.terrain().AddPlane(Eigen::Vector3d::UnitZ(), Eigen::Vector3d::Zero(), Friction{mu, mu});
  physics::RollerVehicle& vehicle = world.AddVehicle(platform.vehicle, 0, 0, 0);
  world.StepFor(kPeerSettle_s);
  for (std::size_t k = 0; k < 4; ++k) {
    (void)vehicle.SetWheelSpeedCommand(platform.drive_wheels[k], motion.wheel_rad_s[k]);
  }
  const long steps = std::lround(kPeerRun_s / dt_s);
  const long steady_from = std::lround(kPeerSteadyFrom_s / dt_s);
  SteadyWindow window(motion, vehicle.body_truth().yaw_rad);
  const auto t0 = std::chrono::steady_clock::now();
  for (long i = 0; i < steps; ++i) {
    world.Step();
    const physics::BodyTruth& b = vehicle.body_truth();
    if (i + 1 == steady_from) window.Start(b.p_WB.x(), b.p_WB.y(), b.yaw_rad);
    if (i + 1 > steady_from) {
      window.Sample(b.v_WB_W.x(), b.v_WB_W.y(), b.omega_WB_W.z());
    }
  }
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const physics::BodyTruth& b = vehicle.body_truth();
  PeerMeasurement out =
      window.Finish(b.p_WB.x(), b.p_WB.y(), b.yaw_rad, kPeerRun_s - kPeerSteadyFrom_s);
  out.steps_per_s = wall > 0 ? static_cast<double>(steps) / wall : 0;
  return out;
}

}  // namespace wheelhil::emulator::peers
