#include "emulator/peers/mujoco_mecanum.h"

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <numbers>
#include <stdexcept>
#include <string>

#include <fmt/format.h>
#include <mujoco/mujoco.h>
#include <Eigen/Geometry>

namespace wheelhil::emulator::peers {

namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kR = 0.05;      // wheel radius
constexpr double kWidth = 0.04;  // axial extent of the rollers
constexpr double kL2 = 0.25;     // half wheelbase
constexpr double kL1 = 0.22;     // half track
constexpr double kChassisZ = 0.10;

std::string WheelXml(const char* name, double x, double y, int hand, int n) {
  // Semi-axes (b, b, c): envelope radius R to second order (c^2 = b^2 + 2 rc b, rc = R - b)
  // and axial extent = width (b^2 + c^2 = 2 R b = width^2 / 2).
  const double b = kWidth * kWidth / (4 * kR);
  const double rc = kR - b;
  const double c = std::sqrt(b * b + 2 * rc * b);
  std::string out = fmt::format(
      "      <body name=\"{0}\" pos=\"{1} {2} {3}\">\n"
      "        <joint name=\"{0}_axle\" type=\"hinge\" axis=\"0 1 0\" armature=\"0.01\"/>\n"
      "        <geom name=\"{0}_hub\" type=\"cylinder\" size=\"{4:.4f} {5:.4f}\" "
      "quat=\"0.70710678 0.70710678 0 0\" mass=\"0.4\" contype=\"0\" conaffinity=\"0\"/>\n",
      name, x, y, kR - kChassisZ, rc - b, kWidth / 2 - 0.005);
  const Eigen::Vector3d a(0, 1, 0);
  for (int i = 0; i < n; ++i) {
    const double th = 2 * kPi * i / n;
    const Eigen::Vector3d u(-std::sin(th), 0, -std::cos(th));   // radial, i = 0 straight down
    const Eigen::Vector3d t(-std::cos(th), 0, std::sin(th));    // d u / d th
    const Eigen::Vector3d e = (t + hand * a) / std::sqrt(2.0);  // roller axis
    Eigen::Matrix3d m;
    m.col(0) = u;
    m.col(1) = e.cross(u);
    m.col(2) = e;
    const Eigen::Quaterniond q(m);
    const Eigen::Vector3d p = rc * u;
    out += fmt::format(
        "        <body name=\"{0}_r{1}\" pos=\"{2:.6f} {3:.6f} {4:.6f}\" "
        "quat=\"{5:.8f} {6:.8f} {7:.8f} {8:.8f}\">\n"
        "          <joint name=\"{0}_r{1}_j\" type=\"hinge\" axis=\"0 0 1\" class=\"roller\"/>\n"
        "          <geom type=\"ellipsoid\" size=\"{9:.5f} {9:.5f} {10:.5f}\" class=\"roller\"/>\n"
        "        </body>\n",
        name, i, p.x(), p.y(), p.z(), q.w(), q.x(), q.y(), q.z(), b, c);
  }
  out += "      </body>\n";
  return out;
}

double YawOf(const mjtNum* q) {  // w x y z
  return std::atan2(2 * (q[0] * q[3] + q[1] * q[2]), 1 - 2 * (q[2] * q[2] + q[3] * q[3]));
}

struct ModelDeleter {
  void operator()(mjModel* m) const { mj_deleteModel(m); }
};
struct DataDeleter {
  void operator()(mjData* d) const { mj_deleteData(d); }
};

}  // namespace

std::string MujocoMecanumModel(const MujocoPeerOptions& o) {
  const int rollers = o.rollers;
  std::string wheels;
  // Floor roller axis (1,-1) on FL and RR (hand +1), (1,1) on FR and RL: the usual
  // w_FL = (vx - vy - k wz) / R ... of the peer study.
  wheels += WheelXml("fl", kL2, kL1, +1, rollers);
  wheels += WheelXml("fr", kL2, -kL1, -1, rollers);
  wheels += WheelXml("rl", -kL2, kL1, -1, rollers);
  wheels += WheelXml("rr", -kL2, -kL1, +1, rollers);
  return fmt::format(R"(<mujoco model="mecanum4">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{0}" integrator="Euler" cone="{4}" gravity="0 0 -9.81"/>
  <default>
    <geom friction="{1} 0.005 0.0001"/>
    <default class="roller">
      <joint damping="1e-05" armature="1e-06"/>
      <geom mass="0.01" contype="1" conaffinity="0"/>
    </default>
  </default>
  <worldbody>
    <geom name="floor" type="plane" size="20 20 0.1" friction="{1} 0.005 0.0001" contype="0" conaffinity="3"/>
    <body name="chassis" pos="0 0 {2:.3f}">
      <freejoint name="root"/>
      <geom name="chassis" type="box" size="0.3 0.25 0.05" mass="20" contype="2" conaffinity="0"/>
{3}    </body>
  </worldbody>
  <actuator>
    <velocity name="m_fl" joint="fl_axle" kv="5"/>
    <velocity name="m_fr" joint="fr_axle" kv="5"/>
    <velocity name="m_rl" joint="rl_axle" kv="5"/>
    <velocity name="m_rr" joint="rr_axle" kv="5"/>
  </actuator>
</mujoco>
)",
                     o.dt_s, o.mu, kChassisZ + 0.002, wheels,
                     o.elliptic_cone ? "elliptic" : "pyramidal");
}

PeerMeasurement MeasureMujoco(const PeerMotion& motion, const MujocoPeerOptions& options) {
  const double dt_s = options.dt_s;
  const char* tmp = std::getenv("TMPDIR");
  std::string path = fmt::format("{}/wheelhil-mujoco-XXXXXX", tmp != nullptr ? tmp : "/tmp");
  const int fd = ::mkstemp(path.data());
  if (fd < 0) throw std::runtime_error(fmt::format("mujoco peer: cannot create {}", path));
  const std::string xml = MujocoMecanumModel(options);
  const bool written = ::write(fd, xml.data(), xml.size()) == static_cast<ssize_t>(xml.size());
  ::close(fd);
  char err[1000] = "";
  std::unique_ptr<mjModel, ModelDeleter> m(
      written ? mj_loadXML(path.c_str(), nullptr, err, sizeof(err)) : nullptr);
  ::unlink(path.c_str());
  if (!m) {
    throw std::runtime_error(fmt::format("mujoco peer: model not loaded: {}",
                                         written ? err : "cannot write the model file"));
  }
  std::unique_ptr<mjData, DataDeleter> d(mj_makeData(m.get()));
  mj_forward(m.get(), d.get());
  const long nsettle = std::lround(kPeerSettle_s / dt_s);
  const long nsteps = std::lround(kPeerRun_s / dt_s);
  const long steady_from = std::lround(kPeerSteadyFrom_s / dt_s);
  for (long i = 0; i < nsettle; ++i) mj_step(m.get(), d.get());
  for (int i = 0; i < 4; ++i) d->ctrl[i] = motion.wheel_rad_s[static_cast<std::size_t>(i)];
  double yaw_prev = YawOf(d->qpos + 3);
  double yaw = yaw_prev;  // unwrapped
  SteadyWindow window(motion, yaw);
  const auto t0 = std::chrono::steady_clock::now();
  for (long i = 0; i < nsteps; ++i) {
    mj_step(m.get(), d.get());
    const double y = YawOf(d->qpos + 3);
    yaw += std::remainder(y - yaw_prev, 2 * kPi);
    yaw_prev = y;
    if (i + 1 == steady_from) window.Start(d->qpos[0], d->qpos[1], yaw);
    // Free joint: linear velocity in the world frame, angular in the body frame (z ~ world z
    // on a flat floor).
    if (i + 1 > steady_from) window.Sample(d->qvel[0], d->qvel[1], d->qvel[5]);
  }
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  for (int j = 0; j < m->nq; ++j) {
    if (!std::isfinite(d->qpos[j])) {
      throw std::runtime_error(fmt::format("mujoco peer: {}: state is not finite", motion.name));
    }
  }
  PeerMeasurement out = window.Finish(d->qpos[0], d->qpos[1], yaw, kPeerRun_s - kPeerSteadyFrom_s);
  out.steps_per_s = wall > 0 ? static_cast<double>(nsteps) / wall : 0;
  return out;
}

}  // namespace wheelhil::emulator::peers
