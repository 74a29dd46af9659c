// RollerVehicle fault hooks (emulator/physics/roller_vehicle.h) used by scenario faults:
// SetWheelFriction (per-wheel mu scale / override) and SetWheelDisturbanceTorque.
#include <gtest/gtest.h>

#include <cmath>

#include "tests/emulator/physics/physics_test_util.h"

namespace wheelhil::emulator {
namespace {

using testing::Rig;

TEST(PhysicsFaultHooks, MuScaleZeroLetsTheDriveWheelsSpinInPlace) {
  Rig rig("diff2");
  rig.world.StepFor(1.0);
  const std::size_t left = rig.platform.wheel_index("left");
  const std::size_t right = rig.platform.wheel_index("right");
  ASSERT_TRUE(rig.vehicle->SetWheelFriction(left, 0.0));
  ASSERT_TRUE(rig.vehicle->SetWheelFriction(right, 0.0));
  const double x0 = rig.vehicle->body_truth().p_WB.x();
  const double rim0 = rig.vehicle->wheel_truth()[left].rim_travel_m;
  rig.Command(0.25, 0, 0);
  bool slipping = true;
  for (int k = 0; k < 1000; ++k) {
    rig.world.Step();
    if (k > 100) slipping = slipping && rig.vehicle->wheel_truth()[left].slipping;
  }
  EXPECT_TRUE(slipping);
  // The wheels turn at the commanded rim speed (~0.22 m in 1 s after the ramp) ...
  EXPECT_GT(rig.vehicle->wheel_truth()[left].rim_travel_m - rim0, 0.2);
  // ... and the robot does not move (only the casters' rolling resistance acts on it).
  EXPECT_LT(std::abs(rig.vehicle->body_truth().p_WB.x() - x0), 0.005);
  EXPECT_DOUBLE_EQ(rig.vehicle->wheel_truth()[left].mu, 0.0);

  // Friction back: traction again, the robot drives off.
  ASSERT_TRUE(rig.vehicle->SetWheelFriction(left, 1.0));
  ASSERT_TRUE(rig.vehicle->SetWheelFriction(right, 1.0));
  rig.world.StepFor(1.0);
  EXPECT_GT(rig.vehicle->body_truth().p_WB.x() - x0, 0.15);
}

TEST(PhysicsFaultHooks, FrictionOverrideReplacesTheFloorAndScaleMultipliesIt) {
  Rig rig("diff2");
  rig.world.StepFor(0.5);
  const std::size_t left = rig.platform.wheel_index("left");
  ASSERT_TRUE(rig.vehicle->SetWheelFriction(left, 0.5, Friction{0.3, 0.2}));
  rig.world.Step();
  // At rest (no slip): mu = scale * mu_peak of the override.
  EXPECT_NEAR(rig.vehicle->wheel_truth()[left].mu, 0.15, 1e-3);
  EXPECT_NEAR(rig.vehicle->wheel_truth()[rig.platform.wheel_index("right")].mu, 0.8, 1e-3);
  EXPECT_FALSE(rig.vehicle->SetWheelFriction(left, -1.0));
  EXPECT_FALSE(rig.vehicle->SetWheelFriction(99, 1.0));
  EXPECT_FALSE(rig.vehicle->SetWheelFriction(left, 1.0, Friction{0.1, 0.2}));  // slide > peak
  EXPECT_FALSE(rig.vehicle->SetWheelDisturbanceTorque(left, NAN));
}

TEST(PhysicsFaultHooks, DisturbanceTorqueOnAFreeWheelGivesAlphaTauOverI) {
  // No floor: the robot falls freely, every wheel hangs in the air. The left wheel made passive
  // (no motor servo), with no bearing friction/viscosity: tau alone spins it up.
  platforms::Platform p = testing::LoadShipped("diff2");
  const std::size_t left = p.wheel_index("left");
  p.vehicle.wheels[left].driven = false;
  p.vehicle.wheels[left].bearing_friction_nm = 0.0;
  p.vehicle.wheels[left].bearing_viscous_nm_s = 0.0;
  Rig rig(p, true);
  Eigen::Isometry3d X_WB = Eigen::Isometry3d::Identity();
  X_WB.translation() = Eigen::Vector3d(0, 0, 1.0);
  rig.vehicle = &rig.world.AddVehicleAt(rig.platform.vehicle, X_WB);
  const double inertia = rig.vehicle->wheel_spin_inertia(left);
  ASSERT_GT(inertia, 0.0);
  const double tau = 0.05;  // N*m
  ASSERT_TRUE(rig.vehicle->SetWheelDisturbanceTorque(left, tau));
  const double w0 = rig.vehicle->wheel_truth()[left].omega_rad_s;
  const int steps = 200;
  for (int k = 0; k < steps; ++k) rig.world.Step();
  const double t = steps * rig.world.step_s();
  EXPECT_FALSE(rig.vehicle->wheel_truth()[left].in_contact);
  EXPECT_NEAR((rig.vehicle->wheel_truth()[left].omega_rad_s - w0) / t, tau / inertia,
              1e-9 * tau / inertia);
  // Removing it: the wheel keeps its speed (nothing else acts on it).
  const double w1 = rig.vehicle->wheel_truth()[left].omega_rad_s;
  ASSERT_TRUE(rig.vehicle->SetWheelDisturbanceTorque(left, 0.0));
  for (int k = 0; k < 50; ++k) rig.world.Step();
  EXPECT_NEAR(rig.vehicle->wheel_truth()[left].omega_rad_s, w1, 1e-12);
}

}  // namespace
}  // namespace wheelhil::emulator
