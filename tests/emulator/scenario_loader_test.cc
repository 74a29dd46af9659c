// Scenario files (emulator/scenario/scenario.h): validation errors name file:line:column and the
// field; motion profiles; the shipped scenarios load.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <stdexcept>
#include <string>

#include "emulator/scenario/scenario.h"

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

TEST(ScenarioLoader, ShippedPaper000Loads) {
  const Scenario s =
      LoadScenarioFile(std::string(WHEELHIL_SOURCE_DIR) + "/scenarios/paper000_slip.yaml");
  EXPECT_EQ(s.name, "paper000_slip");
  EXPECT_DOUBLE_EQ(s.timing.sync_period_s, 0.25);
  EXPECT_EQ(s.terrain.random_patches.count, 16);
  ASSERT_TRUE(s.slip_threshold_m_s.has_value());
  EXPECT_FALSE(s.firmware.overrides_yaml.empty());
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

}  // namespace
}  // namespace wheelhil::emulator::scenario
