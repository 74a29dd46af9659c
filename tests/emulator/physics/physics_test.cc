// Physics acceptance tests: kinematics of the three platforms, follower rim speeds (paper 001
// eq 2), rest without drift, slip on a low-mu patch, suspension over a bump, determinism.

#include <cmath>
#include <numbers>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/emulator/physics/physics_test_util.h"

namespace wheelhil::emulator {
namespace {

using physics::BodyTruth;
using physics::WheelTruth;
using testing::LoadShipped;
using testing::Rig;
using testing::SourcePath;

// Planar displacement of the body, expressed in the body frame at the start.
struct Planar {
  double fwd, left, dyaw;
};
Planar Displacement(const BodyTruth& a, const BodyTruth& b) {
  const Eigen::Vector3d d = b.p_WB - a.p_WB;
  const double c = std::cos(a.yaw_rad), s = std::sin(a.yaw_rad);
  return {c * d.x() + s * d.y(), -s * d.x() + c * d.y(), b.yaw_rad - a.yaw_rad};
}

// Runs twist for duration, then zero command for 1.5 s; returns the displacement.
Planar RunMotion(Rig& rig, double vx, double vy, double wz, double duration_s) {
  rig.world.StepFor(1.0);  // settle on the suspension
  const BodyTruth start = rig.vehicle->body_truth();
  rig.Command(vx, vy, wz);
  rig.world.StepFor(duration_s);
  rig.Command(0, 0, 0);
  rig.world.StepFor(1.5);
  return Displacement(start, rig.vehicle->body_truth());
}

TEST(PhysicsMecanumOmni3, ForwardReachesCommandedDistance) {
  Rig rig("mecanum4_omni3");
  const Planar d = RunMotion(rig, 0.3, 0, 0, 5.0);
  EXPECT_NEAR(d.fwd, 1.5, 0.03 * 1.5);
  EXPECT_LT(std::abs(d.left), 0.02 * 1.5);
  EXPECT_LT(std::abs(d.dyaw), 0.02);
}

TEST(PhysicsMecanumOmni3, SidewaysRightReachesCommandedDistance) {
  Rig rig("mecanum4_omni3");
  const Planar d = RunMotion(rig, 0, -0.3, 0, 5.0);
  EXPECT_NEAR(d.left, -1.5, 0.03 * 1.5);
  EXPECT_LT(std::abs(d.fwd), 0.02 * 1.5);
  EXPECT_LT(std::abs(d.dyaw), 0.02);
}

TEST(PhysicsMecanumOmni3, ClockwiseSpinReachesCommandedAngle) {
  Rig rig("mecanum4_omni3");
  const Planar d = RunMotion(rig, 0, 0, -0.5, 5.0);
  EXPECT_NEAR(d.dyaw, -2.5, 0.03 * 2.5);
  // Drift of the centre: under 2 % of the distance a wheel travels (2.5 rad * 0.32 m).
  EXPECT_LT(std::hypot(d.fwd, d.left), 0.02 * 2.5 * std::hypot(0.25, 0.20));
}

TEST(PhysicsMecanumOmni3, Diagonal45ReachesCommandedDisplacement) {
  Rig rig("mecanum4_omni3");
  const double v = 0.3, c = std::sqrt(0.5);
  const Planar d = RunMotion(rig, v * c, -v * c, 0, 5.0);  // forward-right at 45 deg
  const double along = (d.fwd - d.left) * c;
  const double across = (d.fwd + d.left) * c;
  EXPECT_NEAR(along, 1.5, 0.03 * 1.5);
  EXPECT_LT(std::abs(across), 0.02 * 1.5);
  EXPECT_LT(std::abs(d.dyaw), 0.02);
}

// Paper 001 eq 2 in the paper's frame (X right, Y forward): rim speeds of front, left, right.
Eigen::Vector3d Eq2(double vx_b, double vy_b, double wz, double d) {
  const double X = -vy_b, Y = vx_b;
  return {-X + d * wz, 0.5 * X - std::sqrt(3.0) / 2 * Y + d * wz,
          0.5 * X + std::sqrt(3.0) / 2 * Y + d * wz};
}

TEST(PhysicsMecanumOmni3, FollowerRimSpeedsMatchPaperEq2) {
  struct Case {
    double vx, vy, wz;
  };
  for (const Case c : {Case{0.3, 0, 0}, Case{0, -0.3, 0}, Case{0, 0, -0.5}, Case{0.2, 0.1, 0.3}}) {
    Rig rig("mecanum4_omni3");
    const double d = rig.platform.parameter("follower_radius_d_m");
    const std::size_t f0 = rig.platform.wheel_index("follower_front");
    rig.world.StepFor(1.0);
    rig.Command(c.vx, c.vy, c.wz);
    rig.world.StepFor(1.0);  // steady state
    Eigen::Vector3d sum_rim = Eigen::Vector3d::Zero(), sum_eq = Eigen::Vector3d::Zero();
    for (int k = 0; k < 1000; ++k) {
      rig.world.Step();
      const BodyTruth& b = rig.vehicle->body_truth();
      const Eigen::Matrix3d R = b.q_WB.toRotationMatrix();
      const Eigen::Vector3d v_B = R.transpose() * b.v_WB_W;
      const double wz = (R.transpose() * b.omega_WB_W).z();
      sum_eq += Eq2(v_B.x(), v_B.y(), wz, d);
      for (int j = 0; j < 3; ++j) {
        const auto& t = rig.vehicle->wheel_truth()[f0 + static_cast<std::size_t>(j)];
        sum_rim[j] += t.omega_rad_s * t.effective_radius_m;
      }
    }
    const double scale = sum_eq.cwiseAbs().maxCoeff();
    for (int j = 0; j < 3; ++j) {
      EXPECT_NEAR(sum_rim[j], sum_eq[j], 0.01 * scale)
          << "follower " << j << " twist " << c.vx << " " << c.vy << " " << c.wz;
    }
  }
}

TEST(PhysicsDiff2, StraightTenMetresDriftsUnderFiveMillimetres) {
  Rig rig("diff2");
  const Planar d = RunMotion(rig, 0.25, 0, 0, 40.0);
  EXPECT_NEAR(d.fwd, 10.0, 0.03 * 10.0);
  EXPECT_LT(std::abs(d.left), 0.005);
}

TEST(PhysicsDiff2, ArcsMatchKinematicRadius) {
  for (const double radius : {0.5, 1.0, -2.0}) {
    Rig rig("diff2");
    rig.world.StepFor(1.0);
    const double v = 0.25;
    rig.Command(v, 0, v / radius);
    rig.world.StepFor(2.0);
    // Fit: speed / yaw rate averaged over 4 s of steady motion.
    double s = 0, yaw = 0;
    const BodyTruth a = rig.vehicle->body_truth();
    Eigen::Vector3d prev = a.p_WB;
    for (int k = 0; k < 4000; ++k) {
      rig.world.Step();
      s += (rig.vehicle->body_truth().p_WB - prev).norm();
      prev = rig.vehicle->body_truth().p_WB;
    }
    yaw = rig.vehicle->body_truth().yaw_rad - a.yaw_rad;
    EXPECT_NEAR(s / yaw, radius, 0.01 * std::abs(radius)) << "radius " << radius;
  }
}

void ExpectRestWithoutDrift(const std::string& platform, double slope_deg, double yaw) {
  Rig rig(platform, 0.8, 0.7, slope_deg, yaw);
  rig.world.StepFor(2.0);  // settle
  const BodyTruth a = rig.vehicle->body_truth();
  rig.world.StepFor(10.0);
  const BodyTruth b = rig.vehicle->body_truth();
  EXPECT_LT((b.p_WB - a.p_WB).norm(), 1e-3) << platform << " slope " << slope_deg;
  EXPECT_LT(std::abs(b.yaw_rad - a.yaw_rad), 1e-3) << platform << " slope " << slope_deg;
  for (const auto& w : rig.vehicle->wheel_truth()) {
    if (rig.platform.vehicle.wheels.size() > 0 && w.normal_load_n > 0) {
      EXPECT_LT(w.slip_speed_m_s, 1e-3);
    }
  }
}

TEST(PhysicsRest, FlatFloorNoDrift) {
  ExpectRestWithoutDrift("diff2", 0, 0);
  ExpectRestWithoutDrift("mecanum4_omni3", 0, 0);
  ExpectRestWithoutDrift("ortho3", 0, 0);
}

TEST(PhysicsRest, FiveDegreeRampNoDrift) {
  ExpectRestWithoutDrift("diff2", 5, 0);
  ExpectRestWithoutDrift("diff2", 5, M_PI / 2);
  ExpectRestWithoutDrift("mecanum4_omni3", 5, 0);
  ExpectRestWithoutDrift("mecanum4_omni3", 5, M_PI / 2);
  ExpectRestWithoutDrift("ortho3", 5, 0.3);
}

TEST(PhysicsSlip, LowMuPatchMakesDriveWheelSlipAndRecoverOffIt) {
  Rig rig("diff2");
  // mu = 0.05 patch under the start position, up to x = 0.6 m.
  rig.world.terrain().AddPatch(
      FrictionPatch{"oil", {{-1, -1}, {0.6, -1}, {0.6, 1}, {-1, 1}}, Friction{0.05, 0.04}});
  rig.world.StepFor(1.0);
  const std::size_t left = rig.platform.wheel_index("left");
  const WheelTruth w0 = rig.vehicle->wheel_truth()[left];
  rig.Command(0.25, 0, 0);
  bool slipped = false;
  for (int k = 0; k < 300; ++k) {
    rig.world.Step();
    slipped = slipped || rig.vehicle->wheel_truth()[left].slipping;
  }
  EXPECT_TRUE(slipped);
  const WheelTruth& w1 = rig.vehicle->wheel_truth()[left];
  EXPECT_GT((w1.rim_travel_m - w0.rim_travel_m) - (w1.ground_travel_m - w0.ground_travel_m), 0.01);
  // Leave the patch, then no slip for the rest of the run.
  while (rig.vehicle->body_truth().p_WB.x() < 1.2) rig.world.Step();
  const WheelTruth w2 = rig.vehicle->wheel_truth()[left];
  for (int k = 0; k < 2000; ++k) {
    rig.world.Step();
    EXPECT_FALSE(rig.vehicle->wheel_truth()[left].slipping) << "step " << k;
    if (rig.vehicle->wheel_truth()[left].slipping) break;
  }
  const WheelTruth& w3 = rig.vehicle->wheel_truth()[left];
  EXPECT_NEAR(w3.rim_travel_m - w2.rim_travel_m, w3.ground_travel_m - w2.ground_travel_m, 1e-3);
}

// Paper 000: at constant speed one drive wheel crosses an oily spot that cannot carry its share
// of the casters' rolling resistance. The other wheel pushes harder, the robot yaws toward the
// oily side and the wheel on the spot spins faster than the ground passes (its encoder
// over-counts). The swivel casters must not hold the heading: their rolling resistance opposes
// their velocity (a circle), it is no sideways stiction.
TEST(PhysicsSlip, OilySpotUnderOneDriveWheelAtCruiseTurnsRobotAndOverCounts) {
  Rig rig("diff2");
  // Left track (y = +0.16), x = 1.0 .. 1.2 m; mu N = 0.004 * 42 N < the ~0.4 N the wheel carries.
  rig.world.terrain().AddPatch(FrictionPatch{
      "oil", {{1.0, 0.10}, {1.2, 0.10}, {1.2, 0.22}, {1.0, 0.22}}, Friction{0.004, 0.003}});
  rig.world.StepFor(1.0);
  rig.Command(0.25, 0, 0);
  const std::size_t left = rig.platform.wheel_index("left");
  const std::size_t right = rig.platform.wheel_index("right");
  while (rig.vehicle->body_truth().p_WB.x() < 0.9) rig.world.Step();
  const WheelTruth l0 = rig.vehicle->wheel_truth()[left];
  const WheelTruth r0 = rig.vehicle->wheel_truth()[right];
  const double yaw0 = rig.vehicle->body_truth().yaw_rad;
  EXPECT_LT(std::abs(yaw0), 1e-4);
  while (rig.vehicle->body_truth().p_WB.x() < 1.6 && rig.world.time_s() < 20) rig.world.Step();
  const WheelTruth& l1 = rig.vehicle->wheel_truth()[left];
  const WheelTruth& r1 = rig.vehicle->wheel_truth()[right];
  const double slip_l =
      (l1.rim_travel_m - l0.rim_travel_m) - (l1.ground_travel_m - l0.ground_travel_m);
  const double slip_r =
      (r1.rim_travel_m - r0.rim_travel_m) - (r1.ground_travel_m - r0.ground_travel_m);
  const double dyaw = rig.vehicle->body_truth().yaw_rad - yaw0;
  EXPECT_GT(slip_l, 0.005) << "the wheel on the spot must spin ahead of the ground";
  EXPECT_LT(std::abs(slip_r), 1e-3);
  EXPECT_GT(dyaw, 0.01) << "the robot turns toward the oily (left) side";
  // The encoders miss exactly the heading the slip causes: dyaw = (slip_l - slip_r) / B.
  EXPECT_NEAR(dyaw, (slip_l - slip_r) / 0.32, 0.1 * dyaw);
}

TEST(PhysicsSuspension, BumpKeepsSprungDriveWheelsOnFloorWeakFollowerLifts) {
  platforms::Platform p = LoadShipped("mecanum4_omni3");
  // The springs' reach alone: continuous followers, whose rolling radius does not ripple.
  for (physics::WheelSpec& w : p.vehicle.wheels) w.rollers = physics::RollerSpec{};
  const std::size_t weak = p.wheel_index("follower_left");
  // Too weak a follower spring (with its slider's damping): it cannot follow the floor down.
  p.vehicle.wheels[weak].suspension.stiffness_n_m = 20;
  p.vehicle.wheels[weak].suspension.free_length_m = 0.06;
  p.vehicle.wheels[weak].suspension.damping_n_s_m = 40;
  physics::PhysicsWorld world;
  world.terrain().AddMesh(SourcePath("meshes/bump.obj"), MeshOptions{});
  auto& v = world.AddVehicle(p.vehicle, 0, 0, 0);
  world.StepFor(1.0);
  platforms::CommandTwist(v, p, platforms::BodyTwist{0.3, 0, 0});
  int drive_lost = 0, weak_lost = 0, strong_lost = 0;
  const std::size_t strong = p.wheel_index("follower_right");
  const double weak_rim0 = v.wheel_truth()[weak].rim_travel_m;
  const double strong_rim0 = v.wheel_truth()[strong].rim_travel_m;
  double weak_expected = 0, strong_expected = 0;  // rim travel the body motion implies
  const double x_end = 2.0;
  while (v.body_truth().p_WB.x() < x_end && world.time_s() < 12) {
    world.Step();
    for (std::size_t i : p.drive_wheels) drive_lost += v.wheel_truth()[i].in_contact ? 0 : 1;
    weak_lost += v.wheel_truth()[weak].in_contact ? 0 : 1;
    strong_lost += v.wheel_truth()[strong].in_contact ? 0 : 1;
    const auto& b = v.body_truth();
    const Eigen::Matrix3d R = b.q_WB.toRotationMatrix();
    const Eigen::Vector3d v_B = R.transpose() * b.v_WB_W;
    const platforms::BodyTwist twist{v_B.x(), v_B.y(), (R.transpose() * b.omega_WB_W).z()};
    weak_expected += platforms::RimSpeedForTwist(p.vehicle.wheels[weak], twist) * world.step_s();
    strong_expected +=
        platforms::RimSpeedForTwist(p.vehicle.wheels[strong], twist) * world.step_s();
  }
  EXPECT_GT(v.body_truth().p_WB.x(), x_end - 0.01);
  EXPECT_EQ(drive_lost, 0);
  EXPECT_EQ(strong_lost, 0);
  EXPECT_GT(weak_lost, 20);  // > 20 ms off the floor
  // The followers (at 120 and 240 deg) roll |vl| = |vr| = 0.3 * sqrt(3)/2 m/s. The sprung one's
  // encoder follows the body within 1 %; the weak one's misses travel while it is in the air.
  const double strong_rim = v.wheel_truth()[strong].rim_travel_m - strong_rim0;
  const double weak_rim = v.wheel_truth()[weak].rim_travel_m - weak_rim0;
  EXPECT_NEAR(strong_rim, strong_expected, 0.01 * std::abs(strong_expected));
  EXPECT_GT(std::abs(weak_rim - weak_expected), 0.002) << weak_rim << " vs " << weak_expected;
}

TEST(PhysicsDeterminism, SameInputsGiveBitIdenticalTrajectories) {
  auto run = [] {
    Rig rig("mecanum4_omni3");
    rig.world.terrain().AddPatch(
        FrictionPatch{"wet", {{0.3, -1}, {0.8, -1}, {0.8, 1}, {0.3, 1}}, Friction{0.2, 0.15}});
    rig.Command(0.3, 0.1, 0.2);
    rig.world.StepFor(3.0);
    std::vector<double> out;
    const auto& b = rig.vehicle->body_truth();
    out = {b.p_WB.x(), b.p_WB.y(), b.p_WB.z(), b.yaw_rad};
    for (const auto& w : rig.vehicle->wheel_truth()) out.push_back(w.angle_rad);
    return out;
  };
  const auto a = run();
  const auto b = run();
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) EXPECT_EQ(a[i], b[i]) << i;
}

// ortho3's halves are spherical except within handover_zone_deg around each hand-over: the
// rolling radius the truth reports is r away from the hand-overs and r - dip*(1 - psi/(zone/2))^2
// at angle psi < zone/2 from the nearest one (docs/physics.md, Orthogonal wheels).
TEST(PhysicsOrtho3, RollingRadiusDipsOnlyNearTheHandover) {
  Rig rig("ortho3");
  const auto& spec = rig.platform.vehicle.wheels[1];
  ASSERT_NEAR(spec.handover_zone_rad, 20 * M_PI / 180, 1e-12);
  const double r = spec.radius_m, dip = spec.handover_dip_m, half = 0.5 * spec.handover_zone_rad;
  ASSERT_GT(dip, 0.0);
  rig.world.StepFor(0.5);
  rig.Command(0.1, 0, 0);
  int full = 0, dipped = 0;
  double r_min = r;
  for (int k = 0; k < 3000; ++k) {
    // The step rolls on the radius at the angle it starts from.
    const double angle = rig.vehicle->wheel_truth()[1].angle_rad;
    rig.world.Step();
    const auto& t = rig.vehicle->wheel_truth()[1];
    // Angle to the nearest hand-over (at odd multiples of pi/4).
    const double a = std::remainder(angle - M_PI / 4, M_PI / 2);
    const double psi = std::abs(a);
    const double u = psi < half ? 1 - psi / half : 0.0;
    EXPECT_NEAR(t.effective_radius_m, r - dip * u * u, 1e-12) << angle;
    if (psi >= half) ++full;
    if (psi < 0.5 * half) ++dipped;
    r_min = std::min(r_min, t.effective_radius_m);
  }
  // 3 s at ~1.7 rad/s: several hand-overs, mostly on the full radius.
  EXPECT_GT(full, 2000);
  EXPECT_GT(dipped, 100);
  EXPECT_LT(r_min, r - 0.8 * dip);
}

TEST(PhysicsOrtho3, HandoverDisturbsBodyPeriodically) {
  Rig rig("ortho3");
  rig.world.StepFor(1.0);
  rig.Command(0.1, 0, 0);
  rig.world.StepFor(1.0);
  double zmin = 1e9, zmax = -1e9;
  for (int k = 0; k < 2000; ++k) {
    rig.world.Step();
    const double z = rig.vehicle->body_truth().p_WB.z();
    zmin = std::min(zmin, z);
    zmax = std::max(zmax, z);
  }
  EXPECT_GT(zmax - zmin, 2e-4);  // the radius dip bounces the body
  const Planar d{rig.vehicle->body_truth().p_WB.x(), 0, 0};
  EXPECT_GT(d.fwd, 0.25);
}

// Discrete rollers (platform mecanum4_mujoco_peer: 10 ellipsoid rollers per wheel).
struct PeerRig {
  explicit PeerRig(const char* overrides = "{}")
      : platform(platforms::LoadPlatformFile(
            SourcePath("scenarios/platforms/mecanum4_mujoco_peer.yaml"), YAML::Load(overrides))) {
    world.terrain().AddPlane(Eigen::Vector3d::UnitZ(), Eigen::Vector3d::Zero(), Friction{0.8, 0.8});
    vehicle = &world.AddVehicle(platform.vehicle, 0, 0, 0);
    world.StepFor(0.5);
  }
  void Wheels(double fl, double fr, double rl, double rr) {
    const double w[4] = {fl, fr, rl, rr};
    for (std::size_t k = 0; k < 4; ++k) (void)vehicle->SetWheelSpeedCommand(k, w[k]);
  }
  physics::PhysicsWorld world;
  platforms::Platform platform;
  physics::RollerVehicle* vehicle = nullptr;
};

TEST(PhysicsDiscreteRollers, ContactHandsOverOncePerRollerPitch) {
  PeerRig rig;
  rig.Wheels(6, 6, 6, 6);
  rig.world.StepFor(1.0);
  int handovers = 0;
  int last = rig.vehicle->wheel_truth()[0].roller;
  const double a0 = rig.vehicle->wheel_truth()[0].angle_rad;
  double zmin = 1e9, zmax = -1e9;
  for (int k = 0; k < 3000; ++k) {
    rig.world.Step();
    const WheelTruth& t = rig.vehicle->wheel_truth()[0];
    if (t.roller != last) ++handovers;
    last = t.roller;
    zmin = std::min(zmin, rig.vehicle->body_truth().p_WB.z());
    zmax = std::max(zmax, rig.vehicle->body_truth().p_WB.z());
  }
  // One hand-over per 36 deg of wheel angle.
  const double turned = rig.vehicle->wheel_truth()[0].angle_rad - a0;
  EXPECT_NEAR(handovers, turned / (2 * std::numbers::pi / 10), 1.0);
  // The body rides the rolling radius: 0.258 mm deep at the hand-over (RollerGeometry test).
  EXPECT_GT(zmax - zmin, 0.15e-3);
  EXPECT_LT(zmax - zmin, 0.40e-3);
}

TEST(PhysicsDiscreteRollers, SidewaysTurnsTheRollerInContactAtTheKinematicRate) {
  // Sideways at omega: the roller in contact spins at omega h / (rho cos(alpha_eff)); at the
  // roller's centre h = R (loaded), rho = 8 mm, alpha_eff = 45 deg: 53 rad/s at 6 rad/s.
  PeerRig rig;
  rig.Wheels(6, -6, -6, 6);
  rig.world.StepFor(1.5);
  int checked = 0;
  for (int k = 0; k < 2000; ++k) {
    rig.world.Step();
    const WheelTruth& t = rig.vehicle->wheel_truth()[0];
    const double pitch = 2 * std::numbers::pi / 10;
    const double phase = std::remainder(t.angle_rad - t.roller * pitch, 2 * std::numbers::pi);
    if (std::abs(phase) > 0.02) continue;
    ++checked;
    const double expected =
        std::abs(t.omega_rad_s) * t.effective_radius_m / (0.008 * std::cos(std::numbers::pi / 4));
    EXPECT_NEAR(std::abs(t.roller_omega_rad_s), expected, 0.03 * expected) << k;
    EXPECT_NEAR(std::abs(t.roller_angle_rad), std::numbers::pi / 4, 0.001);
  }
  EXPECT_GT(checked, 20);
}

TEST(PhysicsDiscreteRollers, RollerBearingFrictionCostsSidewaysSpeedNotForward) {
  auto run = [](const char* over, double fl, double fr) {
    PeerRig rig(over);
    rig.Wheels(fl, fr, fr, fl);
    rig.world.StepFor(1.0);
    const BodyTruth a = rig.vehicle->body_truth();
    rig.world.StepFor(3.0);
    return Displacement(a, rig.vehicle->body_truth());
  };
  const char* stiff = "{wheel_defaults: {rollers: {bearing_friction_nm: 0.05}}}";
  const Planar side_free = run("{}", 6, -6), side_stiff = run(stiff, 6, -6);
  const Planar fwd_free = run("{}", 6, 6), fwd_stiff = run(stiff, 6, 6);
  // Forward the rollers do not turn: their bearings do not matter.
  EXPECT_NEAR(fwd_stiff.fwd, fwd_free.fwd, 1e-4);
  // Sideways every roller in contact is driven against its bearing: the robot lags.
  EXPECT_LT(-side_stiff.left, -side_free.left - 0.003);
  EXPECT_GT(-side_stiff.left, 0.5 * -side_free.left);
}

TEST(PhysicsTolerances, UnequalWheelDiametersCurveTheStraightRunAsUmbmarkPredicts) {
  // Borenstein & Feng's E_d: the same wheel speed on radii r + d_l and r + d_r turns the robot
  // at omega (d_r - d_l) / track.
  platforms::Platform p = LoadShipped("diff2");
  std::vector<platforms::WheelDeviation> dev(p.vehicle.wheels.size());
  dev[0].radius_m = +0.0004;  // left
  dev[1].radius_m = -0.0004;  // right
  physics::PhysicsWorld world;
  world.terrain().AddPlane(Eigen::Vector3d::UnitZ(), Eigen::Vector3d::Zero(), Friction{0.8, 0.7});
  physics::RollerVehicle& v = world.AddVehicle(platforms::AsBuilt(p.vehicle, dev), 0, 0, 0);
  world.StepFor(1.0);
  const double r = p.vehicle.wheels[0].radius_m, track = p.parameter("track_m");
  const double omega = 0.3 / r;
  (void)v.SetWheelSpeedCommand(0, omega);
  (void)v.SetWheelSpeedCommand(1, omega);
  world.StepFor(1.0);
  const double yaw0 = v.body_truth().yaw_rad;
  const double a0 = v.wheel_truth()[0].angle_rad;
  world.StepFor(5.0);
  const double turned = v.wheel_truth()[0].angle_rad - a0;  // the wheels' angle over the window
  const double expected = turned * (dev[1].radius_m - dev[0].radius_m) / track;
  EXPECT_NEAR(v.body_truth().yaw_rad - yaw0, expected, 0.05 * std::abs(expected));
  EXPECT_LT(v.body_truth().yaw_rad - yaw0, -0.02);  // clockwise: the left wheel is larger
}

}  // namespace
}  // namespace wheelhil::emulator
