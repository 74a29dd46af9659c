// The reference firmware's closed-loop parts without a bus: the drives' PDO binding over
// bus/dbc/cia402_drive.dbc, the CiA 402 master side (enable sequence, set points, safe stop),
// the path follower on ideal kinematics and the wheel-speed kinematics, and the config keys.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

#include "bus/cia402.h"
#include "firmware_stub/cia402_drives.h"
#include "firmware_stub/drive_protocol.h"
#include "firmware_stub/fw_config.h"
#include "firmware_stub/path_follower.h"
#include "tests/firmware_stub/fw_test_devices.h"

namespace wheelhil::fw {
namespace {

using ::testing::ElementsAre;
using testing::Frame;
using ::testing::HasSubstr;
using testing::Strings;
using ::testing::ThrowsMessage;

constexpr double kPi = 3.14159265358979323846;
namespace c402 = bus::cia402;

DriveSettings TwoDrives() {
  DriveSettings d;
  d.enabled = true;
  d.gear_ratio = 20;
  d.wheel_radius_m = 0.075;
  d.nodes = {DriveNodeSettings{11, 0.0, 0.16, false, 0.0, 1},
             DriveNodeSettings{12, 0.0, -0.16, false, 0.0, 1}};
  return d;
}

/// A TPDO1 of `node` reporting `state` (and bit 9 remote, as a drive does).
bus::CanFrame Tpdo1(std::uint8_t node, c402::State state, std::int32_t velocity = 0) {
  bus::CanFrame f;
  f.id = 0x180u + node;
  f.len = 6;
  const std::uint16_t sw = c402::StatuswordPattern(state) | c402::statusword::kRemote;
  f.data[0] = static_cast<std::uint8_t>(sw);
  f.data[1] = static_cast<std::uint8_t>(sw >> 8);
  const auto v = static_cast<std::uint32_t>(velocity);
  for (int i = 0; i < 4; ++i) f.data[2 + i] = static_cast<std::uint8_t>(v >> (8 * i));
  return f;
}

TEST(DriveProtocol, BindsTheDriveDbcByCiA402Position) {
  const DriveProtocol p = DriveProtocol::LoadDir(testing::DbcDir(), {11, 12});
  bus::CanFrame f;
  ASSERT_TRUE(p.EncodeRpdo1(11, 0x000F, -637, f));
  EXPECT_EQ(bus::ToCanUtilsString(f), "20B#0F0083FDFFFF");
  // A node the DBC does not list uses another node's layout.
  ASSERT_TRUE(p.EncodeRpdo1(40, 0x0006, 1, f));
  EXPECT_EQ(bus::ToCanUtilsString(f), "228#060001000000");

  std::uint8_t node = 0;
  const bus::CanFrame t1 = Frame("18C#3716C8FCFFFF");
  EXPECT_EQ(p.TpdoOf(t1, node), 1);
  EXPECT_EQ(node, 12);
  std::uint16_t sw = 0;
  std::int32_t v = 0;
  ASSERT_TRUE(p.DecodeTpdo1(t1, sw, v));
  EXPECT_EQ(sw, 0x1637);
  EXPECT_EQ(v, -824);
  const bus::CanFrame t2 = Frame("28B#00F0FFFF9CFF");
  EXPECT_EQ(p.TpdoOf(t2, node), 2);
  std::int32_t pos = 0;
  std::int16_t torque = 0;
  ASSERT_TRUE(p.DecodeTpdo2(t2, pos, torque));
  EXPECT_EQ(pos, -4096);
  EXPECT_EQ(torque, -100);
  EXPECT_FALSE(p.DecodeTpdo1(Frame("18C#3716"), sw, v));  // Wrong length.
  EXPECT_EQ(p.TpdoOf(Frame("20B#0F0000000000"), node), 0);
}

TEST(DriveProtocol, MissingFileAndMissingFieldAreNamed) {
  EXPECT_THAT([] { (void)DriveProtocol::LoadDir("/nonexistent", {11}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("/nonexistent/cia402_drive.dbc")));
  const std::string dbc = R"(VERSION ""
BU_: Fw Drive
BO_ 523 Drive_RPDO1: 6 Fw
 SG_ Controlword : 0|16@1+ (1,0) [0|65535] "" Drive
BO_ 395 Drive_TPDO1: 6 Drive
 SG_ Statusword : 0|16@1+ (1,0) [0|65535] "" Fw
 SG_ VelocityActual : 16|32@1- (1,0) [0|0] "" Fw
)";
  auto db = std::make_shared<const bus::DbcDatabase>(bus::DbcDatabase::Parse(dbc, "mine.dbc"));
  EXPECT_THAT([&] { DriveProtocol p(db, "mine.dbc", {11}); },
              ThrowsMessage<std::invalid_argument>(
                  HasSubstr("mine.dbc: message Drive_RPDO1 (0x20B) has no target velocity 0x60FF "
                            "signal at bit 16 (32 bits")));
}

TEST(Cia402Drives, WalksEachDriveToOperationEnabledFromItsStatusword) {
  const DriveProtocol p = DriveProtocol::LoadDir(testing::DbcDir(), {11, 12});
  Cia402Drives drives(TwoDrives(), p, 0.01);
  std::vector<bus::CanFrame> out;
  const std::vector<double> speed = {2.0, 2.0};  // rad/s at the wheel
  drives.Cycle(speed, {true, true}, out);
  EXPECT_TRUE(out.empty());  // No statusword yet: nothing sent.
  auto step = [&](c402::State s11, c402::State s12) {
    bool bad = true;
    EXPECT_TRUE(drives.OnFrame(Tpdo1(11, s11), bad));
    EXPECT_FALSE(bad);
    EXPECT_TRUE(drives.OnFrame(Tpdo1(12, s12), bad));
    out.clear();
    drives.Cycle(speed, {true, true}, out);
    return Strings(out);
  };
  // 2 rad/s x 20 = 40 rad/s of the motor = 382 rpm; only sent in Operation enabled.
  EXPECT_THAT(step(c402::State::kSwitchOnDisabled, c402::State::kNotReadyToSwitchOn),
              ElementsAre("20B#060000000000", "20C#060000000000"));
  EXPECT_THAT(step(c402::State::kReadyToSwitchOn, c402::State::kSwitchOnDisabled),
              ElementsAre("20B#070000000000", "20C#060000000000"));
  EXPECT_THAT(step(c402::State::kSwitchedOn, c402::State::kReadyToSwitchOn),
              ElementsAre("20B#0F0000000000", "20C#070000000000"));
  EXPECT_FALSE(drives.all_enabled());
  EXPECT_THAT(step(c402::State::kOperationEnabled, c402::State::kOperationEnabled),
              ElementsAre("20B#0F007E010000", "20C#0F007E010000"));
  EXPECT_TRUE(drives.all_enabled());
  // A node the master has not started gets no PDO.
  out.clear();
  drives.Cycle(speed, {true, false}, out);
  EXPECT_THAT(Strings(out), ElementsAre("20B#0F007E010000"));
  EXPECT_EQ(drives.ToDriveUnits(-2.0), -382);
}

TEST(Cia402Drives, AFaultStopsEveryDriveAndTheStopIsLatched) {
  const DriveProtocol p = DriveProtocol::LoadDir(testing::DbcDir(), {11, 12});
  Cia402Drives drives(TwoDrives(), p, 0.01);
  bool bad = false;
  for (std::uint8_t n : {11, 12}) drives.OnFrame(Tpdo1(n, c402::State::kOperationEnabled), bad);
  drives.OnFrame(Tpdo1(11, c402::State::kFault), bad);
  EXPECT_TRUE(drives.stopped());
  EXPECT_EQ(drives.stop_reason(), DriveStopReason::kDriveFault);
  EXPECT_EQ(drives.stop_node(), 11);
  std::vector<bus::CanFrame> out;
  drives.Cycle({3.0, 3.0}, {true, true}, out);
  EXPECT_THAT(Strings(out), ElementsAre("20B#020000000000", "20C#020000000000"));
  // The faulted drive recovers by itself: the robot still does not move again.
  drives.OnFrame(Tpdo1(11, c402::State::kOperationEnabled), bad);
  out.clear();
  drives.Cycle({3.0, 3.0}, {true, true}, out);
  EXPECT_THAT(Strings(out), ElementsAre("20B#020000000000", "20C#020000000000"));
  EXPECT_FALSE(drives.all_enabled());
}

TEST(Cia402Drives, ADriveLeavingOperationEnabledUnaskedStopsTheRobot) {
  const DriveProtocol p = DriveProtocol::LoadDir(testing::DbcDir(), {11, 12});
  Cia402Drives drives(TwoDrives(), p, 0.01);
  bool bad = false;
  for (std::uint8_t n : {11, 12}) drives.OnFrame(Tpdo1(n, c402::State::kOperationEnabled), bad);
  ASSERT_FALSE(drives.stopped());
  drives.OnFrame(Tpdo1(12, c402::State::kSwitchOnDisabled), bad);  // e.g. abort connection 2
  EXPECT_EQ(drives.stop_reason(), DriveStopReason::kLeftEnabled);
  EXPECT_EQ(drives.stop_node(), 12);
  // An undecodable TPDO of a drive is consumed and reported bad; other nodes' are not consumed.
  EXPECT_TRUE(drives.OnFrame(Frame("18B#37"), bad));
  EXPECT_TRUE(bad);
  EXPECT_FALSE(drives.OnFrame(Tpdo1(1, c402::State::kOperationEnabled), bad));
}

TEST(Cia402Drives, ADriveThatDoesNotFollowItsSetPointStopsTheRobot) {
  const DriveProtocol p = DriveProtocol::LoadDir(testing::DbcDir(), {11, 12});
  DriveSettings s = TwoDrives();
  s.tracking_error_rad_s = 1.0;  // 1 rad/s at the wheel = 191 rpm of the motor
  s.tracking_error_time_s = 0.03;
  Cia402Drives drives(s, p, 0.01);  // 3 cycles
  bool bad = false;
  std::vector<bus::CanFrame> out;
  auto cycle = [&](std::int32_t v11, std::int32_t v12, double set_rad_s) {
    drives.OnFrame(Tpdo1(11, c402::State::kOperationEnabled, v11), bad);
    drives.OnFrame(Tpdo1(12, c402::State::kOperationEnabled, v12), bad);
    out.clear();
    drives.Cycle({set_rad_s, set_rad_s}, {true, true}, out);
  };
  // Ramping 0 -> 2 -> 4 rad/s (0, 382, 764 rpm): a velocity between the last two set points,
  // or within the window of them, is following.
  cycle(0, 0, 2.0);
  cycle(200, 150, 4.0);
  cycle(764, 600, 4.0);
  cycle(764, 764, 4.0);
  EXPECT_FALSE(drives.stopped());
  // Drive 12 freezes at 382 rpm: 2 rad/s short, three cycles in a row.
  cycle(764, 382, 4.0);
  cycle(764, 382, 4.0);
  EXPECT_FALSE(drives.stopped());
  cycle(764, 382, 4.0);
  EXPECT_TRUE(drives.stopped());
  EXPECT_EQ(drives.stop_reason(), DriveStopReason::kTrackingError);
  EXPECT_EQ(drives.stop_node(), 12);
}

TEST(Cia402Drives, CountsPerSecondUnitUsesTheMotorEncoder) {
  DriveSettings s = TwoDrives();
  s.velocity_rpm = false;
  s.counts_per_rev = 4096;
  const DriveProtocol p = DriveProtocol::LoadDir(testing::DbcDir(), {11, 12});
  const Cia402Drives drives(s, p, 0.01);
  // 1 rad/s at the wheel = 20/(2 pi) motor rev/s = 13038 increments/s.
  EXPECT_EQ(drives.ToDriveUnits(1.0), std::lround(20.0 / (2 * kPi) * 4096));
}

TEST(WheelSpeeds, DifferentialAndMecanumKinematics) {
  DriveSettings diff = TwoDrives();
  double w[4] = {};
  WheelSpeedsFor(diff, BodyVelocity{0.3, 0.0, 0.5}, w);
  EXPECT_NEAR(w[0], (0.3 - 0.5 * 0.16) / 0.075, 1e-12);
  EXPECT_NEAR(w[1], (0.3 + 0.5 * 0.16) / 0.075, 1e-12);
  diff.max_wheel_speed_rad_s = 2.0;  // Scaled together: the ratio (the turn) is kept.
  WheelSpeedsFor(diff, BodyVelocity{0.3, 0.0, 0.5}, w);
  EXPECT_NEAR(w[1], 2.0, 1e-12);
  EXPECT_NEAR(w[0] / w[1], 0.22 / 0.38, 1e-12);

  DriveSettings m;
  m.wheel_radius_m = 0.076;
  const double a = 45 * kPi / 180;
  m.nodes = {DriveNodeSettings{11, 0.25, 0.2, true, -a, 1},
             DriveNodeSettings{12, 0.25, -0.2, true, a, 1},
             DriveNodeSettings{13, -0.25, 0.2, true, a, 1},
             DriveNodeSettings{14, -0.25, -0.2, true, -a, 1}};
  // Textbook Mecanum inverse kinematics (FL, FR, RL, RR; l = lx + ly).
  const double vx = 0.2, vy = -0.1, wz = 0.3, l = 0.45, R = 0.076;
  WheelSpeedsFor(m, BodyVelocity{vx, vy, wz}, w);
  EXPECT_NEAR(w[0], (vx - vy - l * wz) / R, 1e-12);
  EXPECT_NEAR(w[1], (vx + vy + l * wz) / R, 1e-12);
  EXPECT_NEAR(w[2], (vx + vy - l * wz) / R, 1e-12);
  EXPECT_NEAR(w[3], (vx - vy + l * wz) / R, 1e-12);
}

/// Drives the follower on ideal kinematics: the body does exactly what it is told.
struct IdealRun {
  Pose2 X;
  double peak_speed = 0, peak_accel = 0;
  int cycles = 0;
};
IdealRun Follow(PathFollower& f, Pose2 X, double dt, int max_cycles) {
  IdealRun r;
  double last_v = 0;
  for (; r.cycles < max_cycles && !f.done(); ++r.cycles) {
    const BodyVelocity v = f.Step(X, dt);
    const double c = std::cos(X.theta_rad), s = std::sin(X.theta_rad);
    X.x_m += (c * v.vx_m_s - s * v.vy_m_s) * dt;
    X.y_m += (s * v.vx_m_s + c * v.vy_m_s) * dt;
    X.theta_rad += v.omega_rad_s * dt;
    const double speed = std::hypot(v.vx_m_s, v.vy_m_s);
    r.peak_speed = std::max(r.peak_speed, speed);
    r.peak_accel = std::max(r.peak_accel, (speed - last_v) / dt);
    last_v = speed;
  }
  r.X = X;
  return r;
}

TEST(PathFollower, DifferentialDriveStraightEndsAtTheGoalWithinItsLimits) {
  PathSettings p;
  p.waypoints = {Waypoint{10.0, 0.0}};
  p.speed_m_s = 0.25;
  p.accel_m_s2 = 0.5;
  p.lookahead_m = 0.5;
  p.tolerance_m = 0.01;
  PathFollower f(p, false);
  // Starts 5 cm left of the line and 3 deg off: pure pursuit brings it back.
  const IdealRun r = Follow(f, Pose2{0.0, 0.05, 3 * kPi / 180}, 0.01, 10000);
  EXPECT_TRUE(f.done());
  EXPECT_NEAR(r.X.x_m, 10.0, 0.011);
  EXPECT_NEAR(r.X.y_m, 0.0, 0.005);
  EXPECT_LE(r.peak_speed, 0.25 + 1e-12);
  EXPECT_LE(r.peak_accel, 0.5 + 1e-9);
  // 10 m at 0.25 m/s with 0.5 s ramps at each end: ~40.5 s.
  EXPECT_NEAR(r.cycles * 0.01, 40.5, 0.6);
  EXPECT_EQ(f.Step(r.X, 0.01).vx_m_s, 0.0);  // Done: standstill.
}

TEST(PathFollower, HolonomicSquareKeepsTheHeadingAndStopsAtEachCorner) {
  PathSettings p;
  p.waypoints = {Waypoint{1, 0}, Waypoint{1, 1}, Waypoint{0, 1}, Waypoint{0, 0},
                 Waypoint{0.5, 0.5}};
  p.speed_m_s = 0.3;
  p.accel_m_s2 = 0.3;
  PathFollower f(p, true);
  Pose2 X;
  double worst_heading = 0;
  std::size_t leg = 0;
  for (int i = 0; i < 20000 && !f.done(); ++i) {
    const BodyVelocity v = f.Step(X, 0.01);
    if (f.leg() != leg) {  // A new leg starts from standstill at the previous corner.
      EXPECT_NEAR(X.x_m, p.waypoints[leg].x_m, 0.011);
      EXPECT_NEAR(X.y_m, p.waypoints[leg].y_m, 0.011);
      leg = f.leg();
    }
    X.x_m += v.vx_m_s * 0.01;  // Heading stays 0: body = world.
    X.y_m += v.vy_m_s * 0.01;
    X.theta_rad += v.omega_rad_s * 0.01;
    worst_heading = std::max(worst_heading, std::abs(X.theta_rad));
  }
  ASSERT_TRUE(f.done());
  EXPECT_NEAR(X.x_m, 0.5, 0.011);
  EXPECT_NEAR(X.y_m, 0.5, 0.011);
  EXPECT_EQ(worst_heading, 0.0);
}

TEST(PathFollower, SpinInPlaceToAnAbsoluteHeading) {
  PathSettings p;
  p.waypoints = {Waypoint{0, 0, true, -2 * kPi}};  // A full turn clockwise.
  p.yaw_rate_rad_s = 0.5;
  p.heading_tolerance_rad = 0.005;
  for (bool holonomic : {true, false}) {
    PathFollower f(p, holonomic);
    const IdealRun r = Follow(f, Pose2{}, 0.01, 5000);
    EXPECT_TRUE(f.done()) << holonomic;
    EXPECT_NEAR(r.X.theta_rad, -2 * kPi, 0.006);
    EXPECT_NEAR(r.X.x_m, 0.0, 1e-12);
  }
}

TEST(PathFollower, DifferentialDriveTurnsInPlaceToALegBehindIt) {
  PathSettings p;
  p.waypoints = {Waypoint{-1, 0}};
  PathFollower f(p, false);
  const BodyVelocity v = f.Step(Pose2{}, 0.01);
  EXPECT_EQ(v.vx_m_s, 0.0);
  EXPECT_NE(v.omega_rad_s, 0.0);
  const IdealRun r = Follow(f, Pose2{}, 0.01, 20000);
  EXPECT_TRUE(f.done());
  EXPECT_NEAR(r.X.x_m, -1.0, 0.011);
}

const char* kBase = R"(estimator: paper000
sync: {period_s: 0.25}
imu: {yaw_frame_id: 0x174}
paper000:
  track_width_m: 0.32
  wheel_radius_m: 0.075
  counts_per_rev: 4096
  left: {node_id: 1}
  right: {node_id: 2}
  residual_sigma_rad: 0.002
)";

TEST(FwConfigClosedLoop, ReadsDrivesAndPath) {
  const FwConfig c = ParseFwConfig(std::string(kBase) + R"(drives:
  velocity_unit: counts_per_s
  counts_per_rev: 4096
  gear_ratio: 20
  wheel_radius_m: 0.075
  nodes:
    - {node_id: 11, x_m: 0, y_m: 0.16}
    - {node_id: 12, x_m: 0, y_m: -0.16, sign: -1, roller_angle_deg: 45}
path: {waypoints: [[10, 0], [10, 1, 90]], steer_from: raw, heading_tolerance_deg: 2}
)",
                                   "cl.yaml");
  ASSERT_TRUE(c.drives.enabled);
  EXPECT_FALSE(c.drives.velocity_rpm);
  ASSERT_EQ(c.drives.nodes.size(), 2u);
  EXPECT_EQ(c.drives.nodes[1].sign, -1);
  EXPECT_TRUE(c.drives.nodes[1].has_rollers);
  EXPECT_EQ(c.drives.quick_stop_option, 6);
  ASSERT_EQ(c.path.waypoints.size(), 2u);
  EXPECT_TRUE(c.path.waypoints[1].has_theta);
  EXPECT_NEAR(c.path.waypoints[1].theta_rad, kPi / 2, 1e-12);
  EXPECT_EQ(c.path.steer_from, SteerFrom::kRaw);
  EXPECT_NEAR(c.path.heading_tolerance_rad, 2 * kPi / 180, 1e-12);
}

TEST(FwConfigClosedLoop, MistakesNameFileLineAndField) {
  auto parse = [](const std::string& extra) {
    return [extra] { (void)ParseFwConfig(std::string(kBase) + extra, "cl.yaml"); };
  };
  EXPECT_THAT(parse("path: {waypoints: [[1, 0]]}\n"),
              ThrowsMessage<std::invalid_argument>(HasSubstr("path: needs a drives section")));
  EXPECT_THAT(parse("drives: {wheel_radius_m: 0.075, nodes: [{node_id: 2, x_m: 0, y_m: 0}]}\n"),
              ThrowsMessage<std::invalid_argument>(HasSubstr("node_id 2 is used twice")));
  EXPECT_THAT(parse("drives: {wheel_radius_m: 0.075, velocity_unit: rps, nodes: []}\n"),
              ThrowsMessage<std::invalid_argument>(
                  HasSubstr("cl.yaml:11:48: drives.velocity_unit: 'rps' is not one of rpm")));
  EXPECT_THAT(parse("drives:\n  wheel_radius_m: 0.075\n  nodes:\n    - {node_id: 11, x_m: 0}\n"),
              ThrowsMessage<std::invalid_argument>(HasSubstr("drives.nodes[0].y_m: is required")));
  EXPECT_THAT(parse("drives: {wheel_radius_m: 0.075, nodes: [{node_id: 11, x_m: 0, y_m: 0}]}\n"
                    "path: {waypoints: [[1, 0, 0, 0]]}\n"),
              ThrowsMessage<std::invalid_argument>(
                  HasSubstr("cl.yaml:12:20: path.waypoints[0]: must be [x_m, y_m]")));
}

}  // namespace
}  // namespace wheelhil::fw
