// Platforms from URDF (emulator/platforms/robot_description.h): the shipped URDF robots equal
// their hand-written YAML twins field by field; a URDF's chassis is lumped from its links;
// bad files and disagreements are errors that name the file, line and link or joint.

#include <filesystem>
#include <fstream>
#include <numbers>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "emulator/platforms/platform.h"
#include "tests/emulator/physics/physics_test_util.h"

namespace wheelhil::emulator::platforms {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using wheelhil::emulator::testing::LoadShipped;

// Every number of the physics the two platforms make, compared exactly.
void ExpectSamePlatform(const Platform& a, const Platform& b) {
  const physics::VehicleSpec& va = a.vehicle;
  const physics::VehicleSpec& vb = b.vehicle;
  EXPECT_EQ(va.mass_kg, vb.mass_kg);
  EXPECT_EQ(va.inertia_kg_m2, vb.inertia_kg_m2);
  EXPECT_EQ(va.half_extents_m, vb.half_extents_m);
  ASSERT_EQ(va.wheels.size(), vb.wheels.size());
  for (std::size_t i = 0; i < va.wheels.size(); ++i) {
    const physics::WheelSpec& x = va.wheels[i];
    const physics::WheelSpec& y = vb.wheels[i];
    SCOPED_TRACE(x.name);
    EXPECT_EQ(x.name, y.name);
    EXPECT_EQ(x.kind, y.kind);
    EXPECT_EQ(x.mount_B, y.mount_B);
    EXPECT_EQ(x.heading_rad, y.heading_rad);
    EXPECT_EQ(x.radius_m, y.radius_m);
    EXPECT_EQ(x.inertia_kg_m2, y.inertia_kg_m2);
    EXPECT_EQ(x.roller_angle_rad, y.roller_angle_rad);
    EXPECT_EQ(x.rolling_resistance, y.rolling_resistance);
    EXPECT_EQ(x.bearing_friction_nm, y.bearing_friction_nm);
    EXPECT_EQ(x.suspension.free_length_m, y.suspension.free_length_m);
    EXPECT_EQ(x.suspension.max_length_m, y.suspension.max_length_m);
    EXPECT_EQ(x.suspension.min_length_m, y.suspension.min_length_m);
    EXPECT_EQ(x.suspension.stiffness_n_m, y.suspension.stiffness_n_m);
    EXPECT_EQ(x.suspension.damping_n_s_m, y.suspension.damping_n_s_m);
    EXPECT_EQ(x.suspension.bump_stiffness_n_m, y.suspension.bump_stiffness_n_m);
    EXPECT_EQ(x.suspension.hub_mass_kg, y.suspension.hub_mass_kg);
    EXPECT_EQ(x.driven, y.driven);
    EXPECT_EQ(x.motor.gear_ratio, y.motor.gear_ratio);
    EXPECT_EQ(x.rollers.count, y.rollers.count);
    EXPECT_EQ(x.rollers.rows, y.rollers.rows);
  }
  EXPECT_EQ(a.drive_wheels, b.drive_wheels);
  EXPECT_EQ(a.encoder_wheels, b.encoder_wheels);
  EXPECT_EQ(a.parameters, b.parameters);
  EXPECT_EQ(a.tolerances.mount_m, b.tolerances.mount_m);
  ASSERT_EQ(a.sensors.size(), b.sensors.size());
}

TEST(UrdfPlatform, TheShippedUrdfAndSdfRobotsAreTheirYamlTwins) {
  ExpectSamePlatform(LoadShipped("diff2_urdf"), LoadShipped("diff2"));
  ExpectSamePlatform(LoadShipped("mecanum4_omni3_urdf"), LoadShipped("mecanum4_omni3"));
  ExpectSamePlatform(LoadShipped("diff2_sdf"), LoadShipped("diff2"));
  const Platform d = LoadShipped("diff2_urdf");
  EXPECT_TRUE(fs::is_regular_file(d.chassis_mesh)) << d.chassis_mesh;
}

// A scratch directory with a URDF and a platform file that reads it.
class UrdfFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("wheelhil-urdf-" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) +
            "-" + ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string Write(const std::string& name, const std::string& text) {
    const fs::path p = dir_ / name;
    fs::create_directories(p.parent_path());
    std::ofstream(p) << text;
    return p.string();
  }

  // The overlay every case shares: two driven wheels and what URDF cannot say.
  static std::string Overlay(const std::string& extra_wheel_keys = "",
                             const std::string& top = "") {
    return "urdf: robot.urdf\n" + top +
           "wheel_defaults:\n"
           "  kind: conventional\n"
           "  suspension: {free_length_m: 0.05, min_length_m: 0.01, max_length_m: 0.06,\n"
           "               stiffness_n_m: 20000, damping_n_s_m: 300}\n"
           "  motor: {gear_ratio: 10, torque_constant_nm_a: 0.05, max_current_a: 5}\n"
           "wheels:\n"
           "  - {joint: left_joint, motor: {}" +
           extra_wheel_keys +
           "}\n"
           "  - {joint: right_joint, motor: {}}\n"
           "kinematics: {type: diff_drive, track_m: 0.4, wheel_radius_m: 0.1}\n";
  }

  // A robot whose base link is offset from its centre of mass and carries a fixed battery,
  // with wheels whose joints are rotated the ROS way (axis z, rolled -90 deg about x).
  static std::string Robot(const std::string& left_joint_type = "continuous",
                           const std::string& left_radius = "0.1") {
    return R"(<?xml version="1.0"?>
<robot name="scratch">
  <link name="base_link">
    <inertial>
      <origin xyz="0.1 0 0.05"/>
      <mass value="8"/>
      <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.2" iyz="0" izz="0.25"/>
    </inertial>
    <collision><geometry><box size="0.5 0.4 0.1"/></geometry></collision>
  </link>
  <link name="battery">
    <inertial>
      <mass value="2"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/>
    </inertial>
  </link>
  <joint name="battery_mount" type="fixed">
    <parent link="base_link"/><child link="battery"/>
    <origin xyz="-0.15 0 0.05"/>
  </joint>
  <link name="left">
    <inertial><mass value="0.5"/>
      <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.0025"/></inertial>
    <collision><geometry><cylinder radius=")" +
           left_radius + R"(" length="0.04"/></geometry></collision>
  </link>
  <joint name="left_joint" type=")" +
           left_joint_type + R"(">
    <parent link="base_link"/><child link="left"/>
    <origin xyz="0.05 0.2 -0.06" rpy="-1.5707963267948966 0 0"/>
    <axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
  <link name="right">
    <inertial><mass value="0.5"/>
      <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.0025"/></inertial>
    <collision><geometry><sphere radius="0.1"/></geometry></collision>
  </link>
  <joint name="right_joint" type="continuous">
    <parent link="base_link"/><child link="right"/>
    <origin xyz="0.05 -0.2 -0.06" rpy="-1.5707963267948966 0 0"/>
    <axis xyz="0 0 1"/>
  </joint>
</robot>
)";
  }

  fs::path dir_;
};

TEST_F(UrdfFiles, TheChassisIsEveryLinkButTheWheelsLumpedAtItsCentreOfMass) {
  Write("robot.urdf", Robot());
  const Platform p = LoadPlatformFile(Write("p.yaml", Overlay()));
  EXPECT_EQ(p.name, "scratch");
  const physics::VehicleSpec& v = p.vehicle;
  EXPECT_DOUBLE_EQ(v.mass_kg, 10.0);
  // COM: (8 * (0.1, 0, 0.05) + 2 * (-0.15, 0, 0.05)) / 10 = (0.05, 0, 0.05).
  // About it, by the parallel-axis theorem: both bodies sit at the COM's height.
  const double d_base = 0.05, d_bat = 0.2;  // x distances of the two bodies from the COM
  EXPECT_NEAR(v.inertia_kg_m2.x(), 0.1 + 0.01, 1e-12);
  EXPECT_NEAR(v.inertia_kg_m2.y(), 0.2 + 0.01 + 8 * d_base * d_base + 2 * d_bat * d_bat, 1e-12);
  EXPECT_NEAR(v.inertia_kg_m2.z(), 0.25 + 0.01 + 8 * d_base * d_base + 2 * d_bat * d_bat, 1e-12);
  EXPECT_EQ(v.half_extents_m, Eigen::Vector3d(0.25, 0.2, 0.05));
  ASSERT_EQ(v.wheels.size(), 2u);
  const physics::WheelSpec& left = v.wheels[0];
  EXPECT_EQ(left.name, "left_joint");
  // Wheel centre (0.05, 0.2, -0.06) in the base frame, COM (0.05, 0, 0.05): (0, 0.2, -0.11),
  // the mount 0.06 (max_length_m) above it.
  EXPECT_EQ(left.mount_B, Eigen::Vector3d(0, 0.2, -0.05));
  EXPECT_NEAR(left.heading_rad, 0.0, 1e-15);  // axis z rolled -90 deg about x: +y
  EXPECT_EQ(left.radius_m, 0.1);
  EXPECT_EQ(left.inertia_kg_m2, 0.0025);  // izz of the link: its joint axis
  EXPECT_EQ(left.suspension.hub_mass_kg, 0.5);
  EXPECT_EQ(v.wheels[1].radius_m, 0.1);  // from the sphere
}

TEST_F(UrdfFiles, AValueBothGiveMustAgreeAndTheErrorNamesBoth) {
  Write("robot.urdf", Robot());
  // The same radius in both: fine.
  EXPECT_NO_THROW(LoadPlatformFile(Write("same.yaml", Overlay(", radius_m: 0.1"))));
  try {
    LoadPlatformFile(Write("p.yaml", Overlay(", radius_m: 0.12")));
    FAIL() << "no error";
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("p.yaml:8:"));
    EXPECT_THAT(e.what(), HasSubstr("wheels[0].radius_m: 0.12 here, but robot.urdf:"));
    EXPECT_THAT(e.what(), HasSubstr("link 'left' collision cylinder says 0.1"));
  }
}

TEST_F(UrdfFiles, ErrorsNameTheFileTheLineAndTheLinkOrJoint) {
  struct Case {
    std::string urdf, overlay, expect;
  };
  const std::vector<Case> cases = {
      {Robot("revolute"), Overlay(),
       "wheels[0].joint: robot.urdf:26: joint 'left_joint' is revolute, not a continuous joint"},
      {Robot(), Overlay().replace(Overlay().find("left_joint"), 10, "lfet_joint"),
       "robot.urdf has no joint 'lfet_joint' (its continuous joints: left_joint, right_joint)"},
      {"<robot name='x'><link name='a'></robot>", Overlay(),
       "urdf: robot.urdf:1:"},  // not well-formed: the XML's own line
      {"<robot name='x'/>", Overlay(), "urdf: robot.urdf: urdfdom cannot read it"},
      {Robot(), Overlay("", "base_link: nope\n"), "base_link: robot.urdf has no link 'nope'"},
      {Robot(), "wheels:\n  - {joint: left_joint}\n", "only with urdf:"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.expect);
    Write("robot.urdf", c.urdf);
    try {
      LoadPlatformFile(Write("p.yaml", "name: t\n" + c.overlay));
      ADD_FAILURE() << "no error";
    } catch (const std::invalid_argument& e) {
      EXPECT_THAT(e.what(), HasSubstr("p.yaml:"));
      EXPECT_THAT(e.what(), HasSubstr(c.expect));
    }
  }
  // A URDF that is not there names the path it looked at.
  try {
    LoadPlatformFile(Write("q.yaml", "urdf: missing.urdf\n"));
    ADD_FAILURE() << "no error";
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("q.yaml:1:7: urdf: missing.urdf ("));
    EXPECT_THAT(e.what(), HasSubstr("does not exist"));
  }
}

TEST_F(UrdfFiles, SdfErrorsNameTheFileTheLineAndTheModelOrJoint) {
  const std::string model = R"(<?xml version="1.0"?>
<sdf version="1.8">
  <model name="bot">
    <link name="base"><inertial><mass>5</mass></inertial></link>
    <link name="w"><pose>0 0.2 -0.1 0 0 0</pose>
      <collision name="c"><geometry><sphere><radius>0.1</radius></sphere></geometry></collision>
    </link>
    <joint name="wj" type="revolute">
      <parent>base</parent><child>w</child>
      <axis><xyz>0 1 0</xyz><limit><lower>-1</lower><upper>1</upper></limit></axis>
    </joint>
  </model>
</sdf>
)";
  Write("bot.sdf", model);
  const std::string overlay =
      "sdf: bot.sdf\n"
      "wheel_defaults: {kind: conventional, inertia_kg_m2: 0.01,\n"
      "  suspension: {free_length_m: 0.05, min_length_m: 0.01, max_length_m: 0.06,\n"
      "               stiffness_n_m: 20000, damping_n_s_m: 300, hub_mass_kg: 0.3}}\n"
      "wheels:\n  - {joint: wj}\n";
  try {
    LoadPlatformFile(Write("p.yaml", overlay));
    ADD_FAILURE() << "no error";
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("wheels[0].joint: bot.sdf:8: joint 'wj' is revolute, not a "
                                    "continuous joint"));
  }
  try {
    LoadPlatformFile(Write("q.yaml", overlay + "model: other\n"));
    ADD_FAILURE() << "no error";
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("sdf: bot.sdf has no model 'other' (its models: bot)"));
  }
  Write("bad.sdf",
        "<sdf version=\"1.8\"><model name=\"x\"><link name=\"a\"><pose>1 2</pose>"
        "</link></model></sdf>\n");
  try {
    LoadPlatformFile(Write("r.yaml", "sdf: bad.sdf\n"));
    ADD_FAILURE() << "no error";
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("r.yaml:1:6: sdf: not a valid SDF file: bad.sdf"));
  }
  try {
    LoadPlatformFile(Write("s.yaml", "urdf: a.urdf\nsdf: bot.sdf\n"));
    ADD_FAILURE() << "no error";
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("a platform reads one description"));
  }
}

// Four Mecanum wheels modelled Gazebo's way: friction only along fdir1 (mu2 0), the roller
// axis. Paper 001's handedness: front-left and rear-right right-handed (-45 deg).
TEST_F(UrdfFiles, GazebosFrictionDirectionIsTheMecanumRollerAngle) {
  struct Wheel {
    const char* name;
    const char* xyz;
    const char* fdir1_urdf;  // link frame = base frame
    const char* fdir1_sdf;   // link rolled -90 deg about x: base (x, y, 0) is link (x, 0, y)
    double roller_deg;
  };
  const std::vector<Wheel> wheels = {{"fl", "0.25 0.2 -0.075", "-1 1 0", "-1 0 1", -45},
                                     {"fr", "0.25 -0.2 -0.075", "1 1 0", "1 0 1", 45},
                                     {"rl", "-0.25 0.2 -0.075", "1 1 0", "1 0 1", 45},
                                     {"rr", "-0.25 -0.2 -0.075", "-1 1 0", "-1 0 1", -45}};
  std::string urdf = R"(<robot name="m"><link name="base"><inertial><mass value="20"/>
    <inertia ixx="0.4" ixy="0" ixz="0" iyy="0.6" iyz="0" izz="0.9"/></inertial>
    <collision><geometry><box size="0.6 0.44 0.12"/></geometry></collision></link>)";
  std::string sdf = R"(<sdf version="1.8"><model name="m"><link name="base"><inertial>
    <mass>20</mass><inertia><ixx>0.4</ixx><iyy>0.6</iyy><izz>0.9</izz></inertia></inertial>
    <collision name="c"><geometry><box><size>0.6 0.44 0.12</size></box></geometry></collision>
    </link>)";
  std::string overlay_wheels;
  for (const Wheel& w : wheels) {
    const std::string n = w.name;
    urdf += "<link name='" + n +
            "'><inertial><mass value='0.8'/><inertia ixx='0.002' ixy='0' "
            "ixz='0' iyy='0.004' iyz='0' izz='0.002'/></inertial><collision><geometry><sphere "
            "radius='0.076'/></geometry></collision></link><joint name='" +
            n +
            "_j' "
            "type='continuous'><parent link='base'/><child link='" +
            n + "'/><origin xyz='" + w.xyz + "'/><axis xyz='0 1 0'/></joint><gazebo reference='" +
            n +
            "'><mu1>1.0</mu1>"
            "<mu2>0</mu2><fdir1>" +
            w.fdir1_urdf + "</fdir1></gazebo>\n";
    sdf += "<link name='" + n + "'><pose>" + w.xyz +
           " -1.5707963267948966 0 0</pose><inertial>"
           "<mass>0.8</mass><inertia><ixx>0.002</ixx><iyy>0.002</iyy><izz>0.004</izz></inertia>"
           "</inertial><collision name='c'><geometry><sphere><radius>0.076</radius></sphere>"
           "</geometry><surface><friction><ode><mu>1</mu><mu2>0</mu2><fdir1>" +
           w.fdir1_sdf + "</fdir1></ode></friction></surface></collision></link><joint name='" + n +
           "_j' "
           "type='continuous'><parent>base</parent><child>" +
           n +
           "</child><axis><xyz>0 0 1"
           "</xyz></axis></joint>\n";
    overlay_wheels += "  - {joint: " + n + "_j, motor: {}}\n";
  }
  urdf += "</robot>\n";
  sdf += "</model></sdf>\n";
  const std::string overlay =
      "wheel_defaults: {kind: mecanum, suspension: {free_length_m: 0.06, min_length_m: 0.02,\n"
      "  max_length_m: 0.075, stiffness_n_m: 20000, damping_n_s_m: 400},\n"
      "  motor: {gear_ratio: 25, torque_constant_nm_a: 0.04, max_current_a: 10}}\n"
      "kinematics: {type: mecanum4, l1_m: 0.2, l2_m: 0.25, wheel_radius_m: 0.076,\n"
      "  roller_angle_deg: 45}\n"
      "wheels:\n" +
      overlay_wheels;
  Write("m.urdf", urdf);
  Write("m.sdf", sdf);
  for (const char* source : {"urdf: m.urdf\n", "sdf: m.sdf\n"}) {
    SCOPED_TRACE(source);
    const Platform p = LoadPlatformFile(Write("p.yaml", source + overlay));
    ASSERT_EQ(p.vehicle.wheels.size(), 4u);
    for (std::size_t i = 0; i < 4; ++i) {
      EXPECT_NEAR(p.vehicle.wheels[i].roller_angle_rad * 180 / std::numbers::pi,
                  wheels[i].roller_deg, 1e-9)
          << wheels[i].name;
      EXPECT_NEAR(p.vehicle.wheels[i].heading_rad, 0, 1e-12) << wheels[i].name;
    }
    EXPECT_EQ(p.vehicle.wheels[0].radius_m, 0.076);
  }
  // The overlay saying the other hand disagrees with the description.
  std::string wrong = overlay;
  wrong.replace(wrong.find("{joint: fl_j,"), 13, "{joint: fl_j, roller_angle_deg: 45,");
  try {
    LoadPlatformFile(Write("q.yaml", "urdf: m.urdf\n" + wrong));
    ADD_FAILURE() << "no error";
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("wheels[0].roller_angle_deg: 45 here, but m.urdf:"));
    EXPECT_THAT(e.what(), HasSubstr("<gazebo reference='fl'> fdir1 (mu along it, mu2 0) says -45"));
  }
}

TEST_F(UrdfFiles, PackageUrisResolveThroughThePackagePaths) {
  Write("pkgs/my_robot/meshes/body.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  std::string robot = Robot();
  robot.replace(robot.find("<collision><geometry><box"), 0,
                "<visual><geometry><mesh filename=\"package://my_robot/meshes/body.obj\"/>"
                "</geometry></visual>");
  Write("robot.urdf", robot);
  const Platform p = LoadPlatformFile(Write("p.yaml", Overlay("", "package_paths: [pkgs]\n")));
  EXPECT_EQ(fs::path(p.chassis_mesh), (dir_ / "pkgs/my_robot/meshes/body.obj").lexically_normal());
  // Without the path: the error lists where it looked.
  try {
    LoadPlatformFile(Write("q.yaml", Overlay()));
    ADD_FAILURE() << "no error";
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("its mesh 'package://my_robot/meshes/body.obj' is not found"));
    EXPECT_THAT(e.what(), HasSubstr("package_paths lists"));
  }
}

}  // namespace
}  // namespace wheelhil::emulator::platforms
