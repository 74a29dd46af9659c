// Platform files: the three shipped platforms load, their inverse kinematics equal the papers'
// closed forms (paper 001 eq 1, differential drive, 3-wheel omni), and bad files fail with the
// file, line and field in the message.

#include "emulator/platforms/platform.h"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <numbers>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/bus/yaml_fields_test_util.h"
#include "tests/emulator/physics/physics_test_util.h"

namespace wheelhil::emulator::platforms {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::ThrowsMessage;
using wheelhil::emulator::testing::LoadShipped;
using wheelhil::emulator::testing::SourcePath;

TEST(PlatformFile, ShippedPlatformsLoadWithTheirParts) {
  const Platform diff2 = LoadShipped("diff2");
  EXPECT_EQ(diff2.kinematics, KinematicsKind::kDiffDrive);
  EXPECT_EQ(diff2.drive_wheels.size(), 2u);
  EXPECT_EQ(diff2.vehicle.wheels.size(), 4u);
  EXPECT_EQ(diff2.sensors.size(), 1u);
  const Platform m = LoadShipped("mecanum4_omni3");
  EXPECT_EQ(m.drive_wheels.size(), 4u);
  EXPECT_EQ(m.encoder_wheels.size(), 7u);
  const Platform o = LoadShipped("ortho3");
  EXPECT_EQ(o.drive_wheels.size(), 3u);
  EXPECT_EQ(o.sensors.size(), 4u);
  for (const Platform* p : {&diff2, &m, &o}) {
    std::ifstream mesh(SourcePath(p->chassis_mesh));
    EXPECT_TRUE(mesh.good()) << p->chassis_mesh;
  }
}

TEST(PlatformFile, MecanumInverseKinematicsIsPaper001Eq1) {
  const Platform p = LoadShipped("mecanum4_omni3");
  const double l1 = p.parameter("l1_m"), l2 = p.parameter("l2_m");
  const double R = p.parameter("wheel_radius_m");
  const double a = p.parameter("roller_angle_deg") * std::numbers::pi / 180;
  const double k = (l1 * std::tan(a) + l2) / std::tan(a);
  for (const BodyTwist t : {BodyTwist{0.3, 0, 0}, BodyTwist{0, -0.3, 0}, BodyTwist{0, 0, -0.5},
                            BodyTwist{0.2, 0.1, 0.3}}) {
    // Paper frame: X right, Y forward.
    const double X = -t.vy_m_s, Y = t.vx_m_s, th = t.wz_rad_s;
    const double w1 = (X / std::tan(a) + Y - k * th) / R;
    const double w2 = (-X / std::tan(a) + Y + k * th) / R;
    const double w3 = (-X / std::tan(a) + Y - k * th) / R;
    const double w4 = (X / std::tan(a) + Y + k * th) / R;
    const auto w = InverseKinematics(p, t);
    EXPECT_NEAR(w[p.wheel_index("front_left")], w1, 1e-9);
    EXPECT_NEAR(w[p.wheel_index("front_right")], w2, 1e-9);
    EXPECT_NEAR(w[p.wheel_index("rear_left")], w3, 1e-9);
    EXPECT_NEAR(w[p.wheel_index("rear_right")], w4, 1e-9);
    EXPECT_EQ(w[p.wheel_index("follower_front")], 0.0);  // passive
  }
}

TEST(PlatformFile, DiffDriveInverseKinematics) {
  const Platform p = LoadShipped("diff2");
  const double B = p.parameter("track_m"), r = p.parameter("wheel_radius_m");
  const BodyTwist t{0.25, 0, 0.4};
  const auto w = InverseKinematics(p, t);
  EXPECT_NEAR(w[p.wheel_index("left")], (0.25 - 0.4 * B / 2) / r, 1e-9);
  EXPECT_NEAR(w[p.wheel_index("right")], (0.25 + 0.4 * B / 2) / r, 1e-9);
}

TEST(PlatformFile, Omni3InverseKinematics) {
  const Platform p = LoadShipped("ortho3");
  const double L = p.parameter("base_radius_m"), r = p.parameter("wheel_radius_m");
  const BodyTwist t{0.1, -0.2, 0.3};
  const auto w = InverseKinematics(p, t);
  for (int i = 0; i < 3; ++i) {
    const double th = i * 2 * std::numbers::pi / 3;
    const double expected =
        (-std::sin(th) * t.vx_m_s + std::cos(th) * t.vy_m_s + L * t.wz_rad_s) / r;
    EXPECT_NEAR(w[static_cast<std::size_t>(i)], expected, 1e-5) << i;  // mounts have 6 digits
  }
}

TEST(PlatformFile, MissingFileNamesTheFile) {
  EXPECT_THAT([] { LoadPlatformFile("/nonexistent/robot.yaml"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("/nonexistent/robot.yaml")));
}

std::string Shipped(const std::string& name) {
  std::ifstream in(SourcePath("scenarios/platforms/" + name + ".yaml"));
  return std::string(std::istreambuf_iterator<char>(in), {});
}

TEST(PlatformFile, BadFieldNamesFileLineAndField) {
  std::string text = Shipped("diff2");
  const auto pos = text.find("radius_m: 0.075");
  ASSERT_NE(pos, std::string::npos);
  text.replace(pos, 15, "radius_m: -0.075");
  EXPECT_THAT([&] { LoadPlatformYaml(text, "bad.yaml"); },
              ThrowsMessage<std::invalid_argument>(
                  AllOf(HasSubstr("bad.yaml:"), HasSubstr("radius_m"), HasSubstr("must be in ["))));
  std::string typo = Shipped("diff2");
  typo.replace(typo.find("heading_deg"), 11, "headin_deg");
  EXPECT_THAT([&] { LoadPlatformYaml(typo, "typo.yaml"); },
              ThrowsMessage<std::invalid_argument>(AllOf(
                  HasSubstr("typo.yaml:"), HasSubstr("headin_deg"), HasSubstr("unknown key"))));
  std::string nan = Shipped("mecanum4_omni3");
  nan.replace(nan.find("mass_kg: 25.0"), 13, "mass_kg: abc");
  EXPECT_THAT([&] { LoadPlatformYaml(nan, "nan.yaml"); },
              ThrowsMessage<std::invalid_argument>(
                  AllOf(HasSubstr("nan.yaml:"), HasSubstr("chassis.mass_kg"))));
  std::string zone = Shipped("ortho3");
  zone.replace(zone.find("handover_zone_deg: 20"), 21, "handover_zone_deg: 120");
  EXPECT_THAT(
      [&] { LoadPlatformYaml(zone, "zone.yaml"); },
      ThrowsMessage<std::invalid_argument>(AllOf(
          HasSubstr("zone.yaml:"), HasSubstr("handover_zone_deg"), HasSubstr("must be in ["))));
  EXPECT_THAT([&] { LoadPlatformYaml("name: [unclosed", "syntax.yaml"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("syntax.yaml:")));
}

TEST(PlatformFile, DamagedShippedPlatformsGiveOnlyLocatedInputErrors) {
  for (const char* name : {"diff2", "mecanum4_omni3", "ortho3", "mecanum4_mujoco_peer"}) {
    SCOPED_TRACE(name);
    const std::string file = std::string(name) + ".yaml";
    yaml_mutation::ExpectOnlyLocatedInputErrors(
        Shipped(name), file, [&](const std::string& text) { (void)LoadPlatformYaml(text, file); });
  }
}

TEST(PlatformFile, DiscreteRollersMergeFromTheDefaultsAndFailWithTheField) {
  const Platform peer = LoadShipped("mecanum4_mujoco_peer");
  for (const physics::WheelSpec& w : peer.vehicle.wheels) {
    EXPECT_EQ(w.rollers.count, 10);
    EXPECT_DOUBLE_EQ(w.rollers.length_m, 0.054259);
    EXPECT_DOUBLE_EQ(w.rollers.inertia_kg_m2, 1.256e-6);
    EXPECT_EQ(w.rollers.rows, 1);
  }
  // A wheel's own rollers block takes the defaults' missing keys; `continuous` switches off.
  const Platform mixed = LoadPlatformFile(
      SourcePath("scenarios/platforms/mecanum4_mujoco_peer.yaml"),
      YAML::Load("wheels: {front_left: {rollers: {count: 12}}, rear_*: {rollers: continuous}}"));
  EXPECT_EQ(mixed.vehicle.wheels[0].rollers.count, 12);
  EXPECT_DOUBLE_EQ(mixed.vehicle.wheels[0].rollers.length_m, 0.054259);
  EXPECT_EQ(mixed.vehicle.wheels[1].rollers.count, 10);
  EXPECT_EQ(mixed.vehicle.wheels[2].rollers.count, 0);
  EXPECT_EQ(mixed.vehicle.wheels[3].rollers.count, 0);
  // Paper 001's followers are double omni wheels (2 x 5 rollers); its Mecanum drive wheels keep
  // the continuous limit.
  for (const physics::WheelSpec& w : LoadShipped("mecanum4_omni3").vehicle.wheels) {
    const bool follower = w.kind == physics::WheelKind::kOmni;
    EXPECT_EQ(w.rollers.count, follower ? 5 : 0) << w.name;
    EXPECT_EQ(w.rollers.rows, follower ? 2 : 1) << w.name;
  }
  const std::string path = SourcePath("scenarios/platforms/mecanum4_mujoco_peer.yaml");
  auto load = [&](const char* over) { (void)LoadPlatformFile(path, YAML::Load(over)); };
  EXPECT_THAT([&] { load("wheel_defaults: {rollers: {count: 10.5}}"); },
              ThrowsMessage<std::invalid_argument>(
                  HasSubstr("wheels[0].rollers.count: must be an integer")));
  EXPECT_THAT([&] { load("wheel_defaults: {rollers: {spokes: 3}}"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("spokes")));
  EXPECT_THAT([&] { load("wheel_defaults: {rollers: discrete}"); },
              ThrowsMessage<std::invalid_argument>(
                  HasSubstr("rollers: must be 'continuous' or a mapping")));
  EXPECT_THAT([&] { load("wheel_defaults: {rollers: {length_m: 0.15}}"); },
              ThrowsMessage<std::invalid_argument>(
                  AllOf(HasSubstr("mecanum4_mujoco_peer.yaml:"),
                        HasSubstr("wheels[0].rollers: length_m (0.15) is too long"))));
  EXPECT_THAT([&] { load("wheel_defaults: {rollers: {rows: 2}}"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("row_offset_m: is required")));
  EXPECT_THAT(
      [&] { load("wheels: {front_left: {kind: conventional, rollers: {count: 8}}}"); },
      ThrowsMessage<std::invalid_argument>(HasSubstr("only mecanum and omni wheels have rollers")));
}

TEST(PlatformFile, TolerancesAreDrawnWithinTheirLimitsFromTheSeed) {
  const std::string path = SourcePath("scenarios/platforms/mecanum4_omni3.yaml");
  const Platform p = LoadPlatformFile(
      path, YAML::Load("tolerances: {radius_m: 0.0003, mount_m: 0.001, heading_deg: 0.2, "
                       "roller_angle_deg: 0.5}"));
  EXPECT_DOUBLE_EQ(p.tolerances.radius_m, 0.0003);
  EXPECT_NEAR(p.tolerances.roller_angle_rad, 0.5 * std::numbers::pi / 180, 1e-15);
  const auto a = DrawWheelDeviations(p, 7), b = DrawWheelDeviations(p, 7),
             c = DrawWheelDeviations(p, 8);
  ASSERT_EQ(a.size(), p.vehicle.wheels.size());
  double spread = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].radius_m, b[i].radius_m);  // same seed, same robot
    EXPECT_EQ(a[i].mount_y_m, b[i].mount_y_m);
    EXPECT_NE(a[i].radius_m, c[i].radius_m);
    EXPECT_LE(std::abs(a[i].radius_m), 0.0003);
    EXPECT_LE(std::abs(a[i].mount_x_m), 0.001);
    EXPECT_LE(std::abs(a[i].heading_rad), 0.2 * std::numbers::pi / 180);
    spread = std::max(spread, std::abs(a[i].radius_m));
  }
  EXPECT_GT(spread, 0.0);
  // The omni followers and the Mecanum wheels get roller-angle errors; the built vehicle
  // carries every deviation, the platform's kinematics stay nominal.
  const physics::VehicleSpec built = AsBuilt(p.vehicle, a);
  EXPECT_DOUBLE_EQ(built.wheels[0].radius_m, p.vehicle.wheels[0].radius_m + a[0].radius_m);
  EXPECT_DOUBLE_EQ(built.wheels[4].mount_B.y(), p.vehicle.wheels[4].mount_B.y() + a[4].mount_y_m);
  EXPECT_NE(a[4].roller_angle_rad, 0.0);
  EXPECT_DOUBLE_EQ(p.parameter("wheel_radius_m"), 0.076);
  // A platform without the block draws nothing.
  for (const auto& d : DrawWheelDeviations(LoadShipped("diff2"), 7)) EXPECT_EQ(d.radius_m, 0.0);
  EXPECT_THAT([&] { (void)LoadPlatformFile(path, YAML::Load("tolerances: {radius_m: 0.004}")); },
              ThrowsMessage<std::invalid_argument>(
                  HasSubstr("tolerances.radius_m: must be below a tenth")));
  EXPECT_THAT([&] { (void)LoadPlatformFile(path, YAML::Load("tolerances: {track_m: 0.01}")); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("track_m")));
}

TEST(PlatformFile, LineNumberPointsAtTheBadValue) {
  const std::string text =
      "name: x\nchassis:\n  mass_kg: 1\n  inertia_kg_m2: [1, 1, 1]\n"
      "  half_extents_m: [0.1, 0.1, 0.1]\nwheels:\n  - name: a\n    kind: squircle\n";
  EXPECT_THAT([&] { LoadPlatformYaml(text, "k.yaml"); },
              ThrowsMessage<std::invalid_argument>(
                  AllOf(HasSubstr("k.yaml:8:"), HasSubstr("wheels[0].kind"))));
}

TEST(PlatformFile, OverridesMergeIntoTheFileAndWheelsByNameOrGlob) {
  const std::string text = Shipped("mecanum4_omni3");
  const YAML::Node over = YAML::Load(
      "chassis: {mass_kg: 30}\n"
      "wheels:\n"
      "  follower_*: {suspension: {stiffness_n_m: 900}}\n"
      "  front_left: {radius_m: 0.08}\n");
  const Platform base = LoadPlatformYaml(text, "m.yaml");
  const Platform p = LoadPlatformYaml(text, "m.yaml", over);
  EXPECT_DOUBLE_EQ(p.vehicle.mass_kg, 30.0);
  ASSERT_EQ(p.vehicle.wheels.size(), base.vehicle.wheels.size());
  int followers = 0;
  for (std::size_t i = 0; i < p.vehicle.wheels.size(); ++i) {
    const auto& w = p.vehicle.wheels[i];
    const auto& b = base.vehicle.wheels[i];
    // Untouched keys of a merged mapping keep the file's values.
    EXPECT_DOUBLE_EQ(w.suspension.damping_n_s_m, b.suspension.damping_n_s_m) << w.name;
    if (w.name.rfind("follower_", 0) == 0) {
      ++followers;
      EXPECT_DOUBLE_EQ(w.suspension.stiffness_n_m, 900.0) << w.name;
      EXPECT_NE(b.suspension.stiffness_n_m, 900.0);
    } else {
      EXPECT_DOUBLE_EQ(w.suspension.stiffness_n_m, b.suspension.stiffness_n_m) << w.name;
      EXPECT_DOUBLE_EQ(w.radius_m, w.name == "front_left" ? 0.08 : b.radius_m) << w.name;
    }
  }
  EXPECT_EQ(followers, 3);
  // A null override changes nothing; unknown wheels, bad values and typos are errors.
  EXPECT_DOUBLE_EQ(LoadPlatformYaml(text, "m.yaml", YAML::Node(YAML::NodeType::Null))
                       .vehicle.wheels[4]
                       .suspension.stiffness_n_m,
                   base.vehicle.wheels[4].suspension.stiffness_n_m);
  EXPECT_THAT(
      [&] { LoadPlatformYaml(text, "m.yaml", YAML::Load("wheels: {caster_*: {}}")); },
      ThrowsMessage<std::invalid_argument>(AllOf(
          HasSubstr("m.yaml:1:"), HasSubstr("wheels.caster_*"), HasSubstr("matches no wheel"))));
  EXPECT_THAT(
      [&] {
        LoadPlatformYaml(text, "m.yaml",
                         YAML::Load("wheels: {follower_front: {suspension: {stiffness_n_m: -1}}}"));
      },
      ThrowsMessage<std::invalid_argument>(
          AllOf(HasSubstr("suspension.stiffness_n_m"), HasSubstr("must be in ["))));
  EXPECT_THAT([&] { LoadPlatformYaml(text, "m.yaml", YAML::Load("chassis: {mass_kgg: 3}")); },
              ThrowsMessage<std::invalid_argument>(
                  AllOf(HasSubstr("chassis.mass_kgg"), HasSubstr("unknown key"))));
  EXPECT_THAT([&] { LoadPlatformYaml(text, "m.yaml", YAML::Load("[1, 2]")); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("must be a mapping")));
}

}  // namespace
}  // namespace wheelhil::emulator::platforms
