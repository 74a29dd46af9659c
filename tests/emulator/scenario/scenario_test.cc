// Scenario files (emulator/scenario/scenario.h): validation errors name file:line:column and the
// field; motion profiles; the shipped scenarios load.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <stdexcept>
#include <string>

#include "emulator/scenario/scenario.h"
#include "tests/bus/yaml_fields_test_util.h"

namespace wheelhil::emulator::scenario {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

const std::string kFile = std::string(WHEELHIL_SOURCE_DIR) + "/scenarios/inline.yaml";

std::string Minimal(const std::string& extra = "") {
  return "name: t\n"
         "platform: platforms/diff2.yaml\n"
         "motion:\n"
         "  - {type: twist, duration_s: 1, vx_m_s: 0.2}\n"
         "sensors:\n"
         "  encoders:\n"
         "    nodes:\n"
         "      - {wheel: left, node_id: 1}\n"
         "      - {wheel: right, node_id: 2}\n" +
         extra;
}

TEST(ScenarioLoader, MinimalLoadsWithDefaults) {
  const Scenario s = ParseScenario(Minimal(), kFile);
  EXPECT_EQ(s.name, "t");
  EXPECT_EQ(s.platform.name, "diff2");
  ASSERT_EQ(s.sensors.encoders.size(), 2u);
  EXPECT_TRUE(s.timing.lockstep);
  EXPECT_DOUBLE_EQ(s.timing.duration_s, 1.0);
  EXPECT_DOUBLE_EQ(s.timing.physics_rate_hz, 1000.0);
}

TEST(ScenarioLoader, ScoringSelectsMetricComponentsGenericByDefault) {
  EXPECT_EQ(
      ParseScenario(Minimal(), kFile).metric_components,
      (std::vector<std::string>{"pose", "velocity", "truth", "contact", "frames", "closed_loop"}));
  const Scenario s =
      ParseScenario(Minimal("scoring: {metrics: [pose, correction_ratio]}\n"), kFile);
  EXPECT_EQ(s.metric_components, (std::vector<std::string>{"pose", "correction_ratio"}));
}

TEST(ScenarioLoader, UnknownOrRepeatedMetricComponentIsNamed) {
  EXPECT_THAT([] { (void)ParseScenario(Minimal("scoring: {metrics: [pose, ratio]}\n"), kFile); },
              ThrowsMessage<std::invalid_argument>(
                  AllOf(HasSubstr("inline.yaml:10:27: scoring.metrics[1]: 'ratio' is not one of"),
                        HasSubstr("residual_normality"))));
  EXPECT_THAT([] { (void)ParseScenario(Minimal("scoring: {metrics: [pose, pose]}\n"), kFile); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("'pose' is listed twice")));
}

TEST(ScenarioLoader, LogsNameTheOtherFormatsOfTheBusLog) {
  EXPECT_TRUE(ParseScenario(Minimal(), kFile).log_formats.empty());
  EXPECT_EQ(ParseScenario(Minimal("logs: [blf, asc]\n"), kFile).log_formats,
            (std::vector<std::string>{"blf", "asc"}));
  EXPECT_THAT([] { (void)ParseScenario(Minimal("logs: [asc, trc]\n"), kFile); },
              ThrowsMessage<std::invalid_argument>(
                  HasSubstr("inline.yaml:10:13: logs[1]: 'trc' is not one of the run's other logs")));
  EXPECT_THAT([] { (void)ParseScenario(Minimal("logs: [asc, asc]\n"), kFile); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("'asc' is listed twice")));
  EXPECT_THAT([] { (void)ParseScenario(Minimal("logs: asc\n"), kFile); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("logs: must be a list")));
}

std::string DbcImu(const std::string& signal) {
  return "  dbc_imu:\n"
         "    dbc: ../tests/data/dbc/user_imu.dbc\n"
         "    mount_m: [0.1, 0, 0.05]\n"
         "    channels:\n"
         "      - {quantity: rate_z, message: IMU_Rates, signal: " +
         signal +
         "}\n"
         "    messages:\n"
         "      - {message: IMU_Rates, counter: IMU_Counter, checksum: IMU_Crc, "
         "checksum_kind: crc8_sae_j1850}\n"
         "    gyro: {noise_density_rad_s_sqrt_hz: 0.001}\n";
}

TEST(ScenarioLoader, DbcImuIsReadAndCheckedAgainstItsDbc) {
  const Scenario s = ParseScenario(Minimal(DbcImu("IMU_RateZ")), kFile);
  ASSERT_TRUE(s.sensors.dbc_imu.has_value());
  EXPECT_THAT(s.sensors.dbc_imu->dbc, ::testing::EndsWith("tests/data/dbc/user_imu.dbc"));
  EXPECT_DOUBLE_EQ(s.sensors.dbc_imu->mount_m.x(), 0.1);
  ASSERT_EQ(s.sensors.dbc_imu->node.message_options.size(), 1u);
  EXPECT_EQ(s.sensors.dbc_imu->node.message_options[0].checksum, ChecksumKind::kCrc8SaeJ1850);
  EXPECT_DOUBLE_EQ(s.sensors.dbc_imu->gyro_noise_density_rad_s_sqrt_hz, 0.001);
  // A DBC file that is not there: named at its key.
  std::string missing = DbcImu("IMU_RateZ");
  missing.replace(missing.find("user_imu.dbc"), 12, "no_such.dbc");
  EXPECT_THAT([&] { (void)ParseScenario(Minimal(missing), kFile); },
              ThrowsMessage<std::invalid_argument>(
                  AllOf(HasSubstr("inline.yaml:11:10: sensors.dbc_imu.dbc:"),
                        HasSubstr("no_such.dbc:0: cannot open DBC file"))));
  // A signal the DBC does not have: the entry and the node's own reason.
  EXPECT_THAT([] { (void)ParseScenario(Minimal(DbcImu("IMU_Yaw")), kFile); },
              ThrowsMessage<std::invalid_argument>(
                  HasSubstr("inline.yaml:11:5: sensors.dbc_imu.channels[0].signal: message "
                            "'IMU_Rates' has no signal 'IMU_Yaw'")));
}

// `devices:` (docs/own-hardware.md): the shipped MM7.10 example loads; a binding the DBC cannot
// carry is an error at the binding's own line.
TEST(ScenarioLoader, DevicesAreReadAndTheirBindingsCheckedAgainstTheDbc) {
  const Scenario s = LoadScenarioFile(std::string(WHEELHIL_SOURCE_DIR) +
                                      "/scenarios/own_hardware/robot_mm7_imu.yaml");
  ASSERT_EQ(s.devices.size(), 3u);
  EXPECT_TRUE(s.sensors.encoders.empty());
  EXPECT_EQ(s.devices[1].encoder.node_id, 2);
  EXPECT_EQ(s.devices[2].dbc_device.name, "imu");
  EXPECT_EQ(s.devices[2].dbc_device.signals.size(), 13u);
  const std::string head =
      "name: t\nplatform: platforms/diff2.yaml\nmotion:\n"
      "  - {type: twist, duration_s: 1, vx_m_s: 0.2}\n"
      "devices:\n"
      "  - kind: dbc\n"
      "    dbc: own_hardware/bosch_mm7_10.dbc\n"
      "    node: MM7_10\n"
      "    signals:\n";
  EXPECT_THAT(
      [&] { (void)ParseScenario(head + "      YawRate: rate_z\n      AY: rate_y\n", kFile); },
      ThrowsMessage<std::invalid_argument>(
          HasSubstr("inline.yaml:11:7: devices[0].signals.AY: AY's unit 'g' is not a unit of "
                    "angular rate")));
  EXPECT_THAT([&] { (void)ParseScenario(head + "      Yaw: rate_z\n", kFile); },
              ThrowsMessage<std::invalid_argument>(HasSubstr(
                  "inline.yaml:10:7: devices[0].signals.Yaw: no message node MM7_10 sends")));
  EXPECT_THAT([&] { (void)ParseScenario(head + "      YawRate: spin\n", kFile); },
              ThrowsMessage<std::invalid_argument>(
                  HasSubstr("devices[0].signals.YawRate: 'spin' is not one of rate_x")));
  EXPECT_THAT(
      [&] {
        (void)ParseScenario(head +
                                "      YawRate: rate_z\n"
                                "  - {kind: canopen_cia406, wheel: left, node_id: 1}\n"
                                "  - {kind: canopen_cia406, wheel: right, node_id: 1}\n",
                            kFile);
      },
      ThrowsMessage<std::invalid_argument>(HasSubstr("devices[2].node_id: node id 1 is taken")));
  EXPECT_THAT(
      [&] {
        (void)ParseScenario(head + "      CRC_TX1: {quantity: checksum, type: e2e_p11}\n", kFile);
      },
      ThrowsMessage<std::invalid_argument>(
          HasSubstr("devices[0].signals.CRC_TX1.data_id: is required")));
  EXPECT_THAT(
      [&] {
        (void)ParseScenario(
            head + "      CRC_TX1: {quantity: checksum, type: crc8_h2f, data_id: 3}\n", kFile);
      },
      ThrowsMessage<std::invalid_argument>(HasSubstr("data_id: is for e2e_p11 only")));
  EXPECT_THAT(
      [&] {
        (void)ParseScenario(
            head + "      CRC_TX1: {quantity: checksum, type: e2e_p11, data_id: 0x174}\n", kFile);
      },
      ThrowsMessage<std::invalid_argument>(HasSubstr(
          "CRC_TX1 is the last byte of MM7_10_TX1_z_ay: a e2e_p11 counter follows its CRC byte")));
  EXPECT_THAT(
      [&] { (void)ParseScenario(head + "      YawRate: rate_z\n  - {kind: lidar}\n", kFile); },
      ThrowsMessage<std::invalid_argument>(
          HasSubstr("devices[1].kind: 'lidar' is not one of dbc, mm5_10, canopen_cia406")));
}

TEST(ScenarioLoader, UnknownTopLevelKeyNamesLineAndColumn) {
  EXPECT_THAT(
      [] { (void)ParseScenario(Minimal("speed: 3\n"), kFile); },
      ThrowsMessage<std::invalid_argument>(HasSubstr("inline.yaml:10:1: speed: unknown key")));
}

TEST(ScenarioLoader, BadNumberNamesTheField) {
  const std::string text = Minimal("timing: {sync_period_s: -1}\n");
  EXPECT_THAT([&] { (void)ParseScenario(text, kFile); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("timing.sync_period_s")));
}

TEST(ScenarioLoader, ColumnPointsAtTheValue) {
  const std::string text = Minimal("timing: {mode: fast}\n");
  EXPECT_THAT([&] { (void)ParseScenario(text, kFile); },
              ThrowsMessage<std::invalid_argument>(HasSubstr(":10:16: timing.mode: 'fast'")));
}

TEST(ScenarioLoader, ClockAndSyncProducer) {
  // The virtual clock, the only one, with the firmware producing SYNC unless asked otherwise.
  const Scenario plain = ParseScenario(Minimal(), kFile);
  EXPECT_TRUE(plain.timing.firmware_produces_sync);
  EXPECT_FALSE(plain.timing.sync_producer_named);
  const Scenario v = ParseScenario(Minimal("timing: {clock: virtual}\n"), kFile);
  EXPECT_TRUE(v.timing.firmware_produces_sync);
  const Scenario ve =
      ParseScenario(Minimal("timing: {clock: virtual, sync_producer: emulator}\n"), kFile);
  EXPECT_FALSE(ve.timing.firmware_produces_sync);
  EXPECT_TRUE(ve.timing.sync_producer_named);
  // The retired handshake is named, with what replaced it and the fix.
  EXPECT_THAT(
      [] { (void)ParseScenario(Minimal("timing: {clock: cooperative}\n"), kFile); },
      ThrowsMessage<std::invalid_argument>(
          AllOf(HasSubstr(":10:17: timing.clock: the cooperative FW_Status handshake was retired"),
                HasSubstr("virtual clock"), HasSubstr("(remove the key)"))));
  EXPECT_THAT([] { (void)ParseScenario(Minimal("timing: {clock: fast}\n"), kFile); },
              ThrowsMessage<std::invalid_argument>(
                  HasSubstr(":10:17: timing.clock: 'fast' is not virtual")));
  EXPECT_THAT([] { (void)ParseScenario(Minimal("timing: {sync_producer: master}\n"), kFile); },
              ThrowsMessage<std::invalid_argument>(
                  HasSubstr("timing.sync_producer: 'master' is not firmware or emulator")));
  // Real time as well: the firmware is the master unless the scenario names the emulator.
  EXPECT_TRUE(
      ParseScenario(Minimal("timing: {mode: realtime}\n"), kFile).timing.firmware_produces_sync);
  EXPECT_TRUE(ParseScenario(Minimal("timing: {mode: realtime, sync_producer: firmware}\n"), kFile)
                  .timing.firmware_produces_sync);
  // The spin cost: off unless given, at most 10 ms.
  EXPECT_EQ(plain.timing.spin_cost_s, 0.0);
  EXPECT_DOUBLE_EQ(
      ParseScenario(Minimal("timing: {spin_cost_s: 0.0001}\n"), kFile).timing.spin_cost_s, 1e-4);
  EXPECT_THAT([] { (void)ParseScenario(Minimal("timing: {spin_cost_s: -1}\n"), kFile); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("timing.spin_cost_s")));
}

TEST(ScenarioLoader, UnknownWheelIsRejected) {
  std::string text = Minimal();
  text.replace(text.find("wheel: right"), 12, "wheel: front");
  EXPECT_THAT([&] { (void)ParseScenario(text, kFile); },
              ThrowsMessage<std::invalid_argument>(HasSubstr(
                  "sensors.encoders.nodes[1].wheel: platform diff2 has no wheel 'front'")));
}

TEST(ScenarioLoader, RepeatedNodeIdIsRejected) {
  std::string text = Minimal();
  text.replace(text.find("node_id: 2"), 10, "node_id: 1");
  EXPECT_THAT([&] { (void)ParseScenario(text, kFile); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("nodes[1].node_id: repeated")));
}

TEST(ScenarioLoader, MotionTypeMustBeKnown) {
  std::string text = Minimal();
  text.replace(text.find("type: twist"), 11, "type: dance");
  EXPECT_THAT([&] { (void)ParseScenario(text, kFile); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("motion[0].type: 'dance'")));
}

TEST(ScenarioLoader, ExpectationNeedsOneOperator) {
  const std::string text = Minimal("expectations:\n  - {metric: pose.ape_rmse_m}\n");
  EXPECT_THAT(
      [&] { (void)ParseScenario(text, kFile); },
      ThrowsMessage<std::invalid_argument>(HasSubstr("expectations[0]: needs exactly one")));
}

TEST(ScenarioLoader, ExpectationAgainstAnotherMetric) {
  const Scenario s = ParseScenario(
      Minimal(
          "expectations:\n  - {metric: pose.x, \"<\": pose_raw.x}\n  - {metric: a, \">=\": 2}\n"),
      kFile);
  ASSERT_EQ(s.expectations.size(), 2u);
  EXPECT_EQ(s.expectations[0].other_metric, "pose_raw.x");
  EXPECT_EQ(s.expectations[0].op, "<");
  EXPECT_FALSE(s.expectations[0].value.has_value());
  EXPECT_DOUBLE_EQ(*s.expectations[1].value, 2.0);
}

TEST(ScenarioLoader, ConfigPlaceholderNeedsConfig) {
  const std::string text = Minimal("firmware: {command: \"fw --config ${CONFIG}\"}\n");
  EXPECT_THAT([&] { (void)ParseScenario(text, kFile); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("firmware.command")));
}

TEST(ScenarioLoader, SyntaxErrorHasPosition) {
  EXPECT_THAT([] { (void)ParseScenario("name: [unclosed\n", kFile); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("inline.yaml:")));
}

// A required key missing inside a section used to escape as YAML::InvalidNode (the process
// aborted in `wheelhil run`); it is an input error at the section, naming the field.
TEST(ScenarioLoader, MissingTrackYIsAnInputErrorAtItsSection) {
  const std::string path =
      std::string(WHEELHIL_SOURCE_DIR) + "/scenarios/smoke/paper000_slip_short.yaml";
  std::string text = yaml_mutation::ReadText(path);
  const auto line = text.find("    track_y_m:");
  ASSERT_NE(line, std::string::npos);
  text.erase(line, text.find('\n', line) + 1 - line);
  // The random_patches mapping starts at its first key, the line after `random_patches:`.
  const auto section = text.find("  random_patches:\n");
  ASSERT_NE(section, std::string::npos);
  const int section_line =
      2 + static_cast<int>(std::count(text.begin(), text.begin() + section, '\n'));
  EXPECT_THAT([&] { (void)ParseScenario(text, path); },
              ThrowsMessage<std::invalid_argument>(
                  HasSubstr(path + ":" + std::to_string(section_line) +
                            ":5: terrain.random_patches.track_y_m: is required")));
}

TEST(ScenarioLoader, DamagedShippedScenariosGiveOnlyLocatedInputErrors) {
  for (const char* dir : {"/scenarios", "/scenarios/smoke"}) {
    for (const auto& e :
         std::filesystem::directory_iterator(std::string(WHEELHIL_SOURCE_DIR) + dir)) {
      if (e.path().extension() != ".yaml") continue;
      SCOPED_TRACE(e.path().string());
      const std::string path = e.path().string();
      yaml_mutation::ExpectOnlyLocatedInputErrors(
          yaml_mutation::ReadText(path), path,
          [&](const std::string& text) { (void)ParseScenario(text, path); });
    }
  }
}

TEST(ScenarioLoader, ShippedPaper000Loads) {
  const Scenario s =
      LoadScenarioFile(std::string(WHEELHIL_SOURCE_DIR) + "/scenarios/paper000_slip.yaml");
  EXPECT_EQ(s.name, "paper000_slip");
  EXPECT_DOUBLE_EQ(s.timing.sync_period_s, 0.25);
  EXPECT_EQ(s.terrain.random_patches.count, 2);
  EXPECT_EQ(s.terrain.random_patches.placement, RandomPatchesSpec::Placement::kStratified);
  ASSERT_TRUE(s.slip_threshold_m_s.has_value());
  EXPECT_FALSE(s.firmware.overrides_yaml.empty());
}

std::string RandomPatches(const std::string& placement, double length_max_m) {
  return "terrain:\n"
         "  random_patches: {count: 4, x_min_m: 0, x_max_m: 8, length_min_m: 0.5, length_max_m: " +
         std::to_string(length_max_m) + ", track_y_m: [0], placement: " + placement + "}\n";
}

TEST(ScenarioLoader, RandomPatchPlacementIsReadAndChecked) {
  EXPECT_EQ(ParseScenario(Minimal(), kFile).terrain.random_patches.placement,
            RandomPatchesSpec::Placement::kUniform);
  EXPECT_EQ(ParseScenario(Minimal(RandomPatches("stratified", 2.0)), kFile)
                .terrain.random_patches.placement,
            RandomPatchesSpec::Placement::kStratified);
  // Four sections of 2 m cannot hold a 2.5 m patch each.
  EXPECT_THAT([] { (void)ParseScenario(Minimal(RandomPatches("stratified", 2.5)), kFile); },
              ThrowsMessage<std::invalid_argument>(AllOf(HasSubstr("inline.yaml:11:"),
                                                         HasSubstr("random_patches.length_max_m"),
                                                         HasSubstr("section length"))));
  EXPECT_THAT(
      [] { (void)ParseScenario(Minimal(RandomPatches("evenly", 1.0)), kFile); },
      ThrowsMessage<std::invalid_argument>(HasSubstr(
          "terrain.random_patches.placement: must be uniform or stratified, not 'evenly'")));
}

TEST(ScenarioLoader, PlatformOverridesAreMergedIntoThePlatformFile) {
  const Scenario s =
      LoadScenarioFile(std::string(WHEELHIL_SOURCE_DIR) + "/scenarios/paper001_rough_floor.yaml");
  std::string text =
      "name: t\n"
      "platform:\n"
      "  file: platforms/mecanum4_omni3.yaml\n"
      "  overrides: {wheels: {follower_*: {suspension: {stiffness_n_m: 75}}}}\n"
      "motion:\n"
      "  - {type: hold, duration_s: 1}\n"
      "sensors:\n"
      "  encoders:\n"
      "    nodes: [{wheel: follower_front, node_id: 1}]\n";
  const Scenario o = ParseScenario(text, kFile);
  int followers = 0;
  for (std::size_t i = 0; i < o.platform.vehicle.wheels.size(); ++i) {
    const auto& w = o.platform.vehicle.wheels[i];
    if (w.name.rfind("follower_", 0) != 0) continue;
    ++followers;
    EXPECT_DOUBLE_EQ(w.suspension.stiffness_n_m, 75.0);
    EXPECT_DOUBLE_EQ(s.platform.vehicle.wheels[i].suspension.stiffness_n_m, 300.0);  // as file
  }
  EXPECT_EQ(followers, 3);
  text.replace(text.find("follower_*"), 10, "folower_*");
  EXPECT_THAT([&] { (void)ParseScenario(text, kFile); },
              ThrowsMessage<std::invalid_argument>(AllOf(HasSubstr("inline.yaml:4:"),
                                                         HasSubstr("platform.overrides"),
                                                         HasSubstr("matches no wheel"))));
  std::string scalar = Minimal();
  scalar.replace(scalar.find("platform: platforms/diff2.yaml"), 30,
                 "platform: {file: platforms/diff2.yaml, overrides: 3}");
  EXPECT_THAT(
      [&] { (void)ParseScenario(scalar, kFile); },
      ThrowsMessage<std::invalid_argument>(HasSubstr("platform.overrides: must be a mapping")));
}

// The commanded path of `motion`, integrated here independently of the loader (0.1 ms, midpoint
// heading): final (x, y, heading) in the start frame.
Eigen::Vector3d IntegrateCommandedPath(const std::vector<MotionSegment>& motion) {
  Eigen::Vector3d q = Eigen::Vector3d::Zero();
  const double dt = 1e-4, total = MotionDuration(motion);
  for (double t = 0; t < total; t += dt) {
    const platforms::BodyTwist v = TwistAt(motion, t + dt / 2);
    const double mid = q.z() + 0.5 * v.wz_rad_s * dt;
    q.x() += (std::cos(mid) * v.vx_m_s - std::sin(mid) * v.vy_m_s) * dt;
    q.y() += (std::sin(mid) * v.vx_m_s + std::cos(mid) * v.vy_m_s) * dt;
    q.z() += v.wz_rad_s * dt;
  }
  return q;
}

std::string WithMotion(std::string text, const std::string& motion_lines) {
  const std::string old = "  - {type: twist, duration_s: 1, vx_m_s: 0.2}\n";
  text.replace(text.find(old), old.size(), motion_lines);
  return text;
}

TEST(ScenarioLoader, WaypointsOnADiffDriveTurnInPlaceThenDriveStraight) {
  const Scenario s = ParseScenario(
      WithMotion(Minimal(),
                 "  - {type: waypoints, points_m: [[1, 0], [1, 1], [0, 1], [0, 0]], speed: 0.2,\n"
                 "     accel: 0.5, turn_speed_rad_s: 0.8, turn_accel_rad_s2: 2}\n"),
      kFile);
  // straight, then (turn +90 deg, straight) x 3
  ASSERT_EQ(s.motion.size(), 7u);
  for (std::size_t i = 0; i < 7; ++i) {
    ASSERT_EQ(s.motion[i].kind, MotionSegment::Kind::kTrapezoid) << i;
    if (i % 2 == 0) {
      EXPECT_TRUE(s.motion[i].direction.isApprox(Eigen::Vector3d::UnitX())) << i;
      EXPECT_NEAR(s.motion[i].distance, 1.0, 1e-12) << i;
      EXPECT_DOUBLE_EQ(s.motion[i].speed, 0.2);
    } else {
      EXPECT_TRUE(s.motion[i].direction.isApprox(Eigen::Vector3d::UnitZ())) << i;  // left turn
      EXPECT_NEAR(s.motion[i].distance, M_PI / 2, 1e-9) << i;
      EXPECT_DOUBLE_EQ(s.motion[i].speed, 0.8);
    }
  }
  const Eigen::Vector3d end = IntegrateCommandedPath(s.motion);
  EXPECT_NEAR(end.x(), 0.0, 1e-3);
  EXPECT_NEAR(end.y(), 0.0, 1e-3);
  EXPECT_NEAR(end.z(), 3 * M_PI / 2, 1e-3);
}

TEST(ScenarioLoader, WaypointsOnAHolonomicPlatformKeepTheHeadingAfterEarlierSegments) {
  const std::string text =
      "name: t\n"
      "platform: platforms/mecanum4_omni3.yaml\n"
      "motion:\n"
      "  - {type: twist, duration_s: 1, wz_rad_s: 1.5707963267948966}\n"  // faces +y
      "  - {type: waypoints, points_m: [[0, 1], [-1, 1]], speed: 0.2, accel: 0.5}\n"
      "sensors:\n"
      "  encoders:\n"
      "    nodes:\n"
      "      - {wheel: follower_front, node_id: 1}\n";
  const Scenario s = ParseScenario(text, kFile);
  ASSERT_EQ(s.motion.size(), 3u);
  // after the quarter turn to the left, world +y is body forward and world -x body left
  EXPECT_TRUE(s.motion[1].direction.isApprox(Eigen::Vector3d::UnitX(), 1e-6));
  EXPECT_TRUE(s.motion[2].direction.isApprox(Eigen::Vector3d::UnitY(), 1e-6));
  const Eigen::Vector3d end = IntegrateCommandedPath(s.motion);
  EXPECT_NEAR(end.x(), -1.0, 1e-3);
  EXPECT_NEAR(end.y(), 1.0, 1e-3);
  EXPECT_NEAR(end.z(), M_PI / 2, 1e-3);
}

TEST(ScenarioLoader, WaypointErrorsNameTheField) {
  EXPECT_THAT(
      [] {
        (void)ParseScenario(WithMotion(Minimal(),
                                       "  - {type: waypoints, points_m: [[1, 0], [2]],"
                                       " speed: 0.2, accel: 0.5}\n"),
                            kFile);
      },
      ThrowsMessage<std::invalid_argument>(HasSubstr("motion[0].points_m[1]: must be [x, y]")));
  EXPECT_THAT(
      [] {
        (void)ParseScenario(
            WithMotion(Minimal(),
                       "  - {type: wheels, duration_s: 1, omega_rad_s: [1, 1, 0, 0]}\n"
                       "  - {type: waypoints, points_m: [[1, 0]], speed: 0.2, accel: 0.5}\n"),
            kFile);
      },
      ThrowsMessage<std::invalid_argument>(
          AllOf(HasSubstr(":5:5: motion[1]"), HasSubstr("cannot follow a `wheels` segment"))));
}

TEST(ScenarioLoader, EveryShippedScenarioLoads) {
  // scenarios/*.yaml and scenarios/smoke/*.yaml (platforms/, firmware/ and campaigns/ hold
  // other file kinds).
  int loaded = 0;
  for (const char* dir : {"/scenarios", "/scenarios/smoke"}) {
    for (const auto& e :
         std::filesystem::directory_iterator(std::string(WHEELHIL_SOURCE_DIR) + dir)) {
      if (e.path().extension() != ".yaml") continue;
      SCOPED_TRACE(e.path().string());
      EXPECT_NO_THROW((void)LoadScenarioFile(e.path().string()));
      ++loaded;
    }
  }
  EXPECT_GE(loaded, 20);
}

TEST(MotionProfile, TrapezoidCoversTheDistance) {
  const double d = 10.0, v = 0.25, a = 0.5;
  const double total = TrapezoidDuration(d, v, a);
  EXPECT_NEAR(total, 2 * v / a + (d - v * v / a) / v, 1e-12);
  double s = 0;
  const double dt = 1e-4;
  for (double t = 0; t < total; t += dt) s += TrapezoidSpeed(d, v, a, t + dt / 2) * dt;
  EXPECT_NEAR(s, d, 1e-4);
  EXPECT_DOUBLE_EQ(TrapezoidSpeed(d, v, a, total / 2), v);
}

TEST(MotionProfile, TriangularWhenShort) {
  const double d = 0.01, v = 1.0, a = 0.5;
  const double total = TrapezoidDuration(d, v, a);
  EXPECT_NEAR(total, 2 * std::sqrt(d / a), 1e-12);
  EXPECT_NEAR(TrapezoidSpeed(d, v, a, total / 2), std::sqrt(d * a), 1e-12);
}

TEST(MotionProfile, TwistAtFollowsSegments) {
  std::vector<MotionSegment> m(2);
  m[0].kind = MotionSegment::Kind::kHold;
  m[0].duration_s = 1;
  m[1].kind = MotionSegment::Kind::kTwist;
  m[1].duration_s = 2;
  m[1].twist.wz_rad_s = 0.5;
  EXPECT_DOUBLE_EQ(TwistAt(m, 0.5).wz_rad_s, 0.0);
  EXPECT_DOUBLE_EQ(TwistAt(m, 1.5).wz_rad_s, 0.5);
  EXPECT_DOUBLE_EQ(TwistAt(m, 3.5).wz_rad_s, 0.0);
  EXPECT_DOUBLE_EQ(MotionDuration(m), 3.0);
}

std::string ClosedLoop(const std::string& devices, const std::string& extra = "") {
  return "name: t\n"
         "platform: platforms/diff2.yaml\n"
         "motion: {source: firmware, goal: {x_m: 10, y_m: 0}}\n"
         "devices:\n" +
         devices + "timing: {duration_s: 5}\n" + extra;
}

TEST(ScenarioLoader, DrivesMakeAClosedLoop) {
  const Scenario s = ParseScenario(
      ClosedLoop("  - {kind: canopen_cia402, wheel: left, node_id: 11, name: drive_left}\n"
                 "  - {kind: canopen_cia402, wheel: right, node_id: 12,\n"
                 "     objects: {\"0x6060\": 9, \"0x1400sub5\": 100}}\n",
                 "faults:\n"
                 "  - {type: drive, kind: overcurrent, drive: drive_left, start_s: 1}\n"
                 "  - {type: drive, kind: torque_limit, drive: drive12, start_s: 1, end_s: 2,\n"
                 "     torque_limit_nm: 0.5}\n"
                 "  - {type: device, kind: silent, node: drive12, start_s: 3}\n"),
      kFile);
  ASSERT_TRUE(s.firmware_motion);
  ASSERT_TRUE(s.firmware_motion->goal);
  EXPECT_DOUBLE_EQ(s.firmware_motion->goal->x(), 10);
  EXPECT_TRUE(s.motion.empty());
  ASSERT_EQ(s.devices.size(), 2u);
  const auto& d = s.devices[1].drive;
  EXPECT_EQ(d.name, "drive12");
  EXPECT_EQ(d.node.default_mode, 9);
  EXPECT_EQ(d.node.rpdo[0].event_ms, 100);
  EXPECT_DOUBLE_EQ(d.node.gear_ratio, 20);           // the platform motor's
  EXPECT_NEAR(d.motor_torque_limit_nm, 4.8, 1e-12);  // kt x gear x max current < 5 N*m
  ASSERT_EQ(s.faults.size(), 3u);
  EXPECT_EQ(s.faults[1].drive.kind, DriveFault::Kind::kTorqueLimit);
  EXPECT_DOUBLE_EQ(s.faults[1].drive.torque_limit_nm, 0.5);
}

const char* kMotorController = R"(  - kind: dbc
    name: motors
    dbc: own_hardware/dual_motor_controller.dbc
    node: MotorCtrl
    setpoint_timeout_ms: 100
    signals:
      MC_SpeedLeft: {quantity: wheel_speed_setpoint, wheel: left}
      MC_SpeedRight: {quantity: wheel_speed_setpoint, wheel: right}
      MC_Enable: {quantity: drive_enable, wheel: right}
      MC_FbSpeedLeft: {quantity: wheel_speed, wheel: left}
      MC_FbSpeedRight: {quantity: wheel_speed, wheel: right}
      MC_FbCurrentLeft: {quantity: motor_current, wheel: left}
      MC_FbCurrentRight: {quantity: motor_current, wheel: right}
      MC_PosLeft: {quantity: wheel_angle, wheel: left, counts_per_rev: 4096}
      MC_PosRight: {quantity: wheel_angle, wheel: right, counts_per_rev: 4096}
)";

TEST(ScenarioLoader, ADbcMotorControllerDrivesTheWheels) {
  const Scenario s = ParseScenario(ClosedLoop(kMotorController), kFile);
  ASSERT_EQ(s.devices.size(), 1u);
  const DbcDeviceConfig& c = s.devices[0].dbc_device;
  EXPECT_DOUBLE_EQ(c.setpoint_timeout_s, 0.1);
  ASSERT_EQ(c.signals[0].quantity, DbcQuantity::kWheelSpeedSetpoint);
  EXPECT_NEAR(c.signals[0].motor_torque_limit_nm, 4.8, 1e-12);  // the platform motor's
  // A wheel with a CiA 402 drive and the controller's set point has two drives; a set point
  // for a caster, none to drive; without the right wheel's set point it has no drive.
  EXPECT_THAT(
      [] {
        (void)ParseScenario(ClosedLoop(std::string(kMotorController) +
                                       "  - {kind: canopen_cia402, wheel: left, node_id: 11}\n"),
                            kFile);
      },
      ThrowsMessage<std::invalid_argument>(HasSubstr("wheel 'left' has two drives")));
  std::string caster = kMotorController;
  caster.replace(caster.find("wheel: left}"), 12, "wheel: caster_front}");
  EXPECT_THAT([&] { (void)ParseScenario(ClosedLoop(caster), kFile); },
              ThrowsMessage<std::invalid_argument>(HasSubstr(
                  "wheel 'caster_front' of platform diff2 has no motor (wheel_speed_setpoint")));
  std::string one = kMotorController;
  one.erase(one.find("      MC_SpeedRight"),
            one.find("      MC_Enable") - one.find("      MC_SpeedRight"));
  EXPECT_THAT([&] { (void)ParseScenario(ClosedLoop(one), kFile); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("wheel 1 has a drive_enable but no")));
}

TEST(ScenarioLoader, ClosedLoopMistakesAreNamed) {
  const std::string both =
      "  - {kind: canopen_cia402, wheel: left, node_id: 11}\n"
      "  - {kind: canopen_cia402, wheel: right, node_id: 12}\n";
  EXPECT_THAT(
      [] {
        (void)ParseScenario(ClosedLoop("  - {kind: canopen_cia402, wheel: left, node_id: 11}\n"),
                            kFile);
      },
      ThrowsMessage<std::invalid_argument>(HasSubstr("driven wheel 'right' has no drive")));
  EXPECT_THAT(
      [] {
        (void)ParseScenario(
            ClosedLoop("  - {kind: canopen_cia402, wheel: caster_front, node_id: 11}\n"), kFile);
      },
      ThrowsMessage<std::invalid_argument>(HasSubstr("has no motor")));
  EXPECT_THAT(
      [&] { (void)ParseScenario(Minimal("devices:\n" + both), kFile); },
      ThrowsMessage<std::invalid_argument>(HasSubstr("takes its motion from the firmware")));
  EXPECT_THAT(
      [&] {
        (void)ParseScenario(ClosedLoop(both,
                                       "faults:\n  - {type: drive, kind: stuck, drive: nope, "
                                       "start_s: 1}\n"),
                            kFile);
      },
      ThrowsMessage<std::invalid_argument>(HasSubstr("'nope' is not the name of a drive")));
  EXPECT_THAT(
      [&] {
        (void)ParseScenario(ClosedLoop(both,
                                       "faults:\n  - {type: device, kind: reboot, node: drive11, "
                                       "start_s: 1, end_s: 2}\n"),
                            kFile);
      },
      ThrowsMessage<std::invalid_argument>(HasSubstr("its own faults are type: drive")));
  EXPECT_THAT(
      [&] {
        (void)ParseScenario(ClosedLoop("  - {kind: canopen_cia402, wheel: left, node_id: 11,\n"
                                       "     objects: {\"0x1A00sub1\": 0x10000020}}\n"
                                       "  - {kind: canopen_cia402, wheel: right, node_id: 12}\n"),
                            kFile);
      },
      ThrowsMessage<std::invalid_argument>(HasSubstr("TPDO1 mapping")));
}

}  // namespace
}  // namespace wheelhil::emulator::scenario
