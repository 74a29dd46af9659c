// The `dbc` device (emulator/devices/dbc_device.h): every cyclic message of a DBC node, its
// signals bound to quantities in the DBC's units, timed by GenMsgCycleTime, GenMsgStartDelayTime
// and a phase, GenMsgSendType read as its string; counters, checksums, the DBC range; errors
// that name the field.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <initializer_list>
#include <limits>
#include <memory>
#include <numbers>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "bus/dbc.h"
#include "bus/dbc_codec.h"
#include "emulator/devices/dbc_device.h"
#include "tests/emulator/devices/recording_port.h"

namespace wheelhil::emulator {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

constexpr const char* kDbc = R"(VERSION ""
BU_: Box Other
BO_ 256 BOX_Rates: 8 Box
 SG_ Yaw : 0|16@1- (0.01,0) [-300|300] "deg/s" Other
 SG_ Ax : 16|16@1- (0.001,0) [-2|2] "g" Other
 SG_ Temp : 32|8@1+ (1,-40) [-40|215] "degC" Other
 SG_ Cnt : 40|4@1+ (1,0) [0|15] "" Other
 SG_ Spare : 44|4@1+ (1,0) [0|15] "" Other
 SG_ Crc : 56|8@1+ (1,0) [0|255] "" Other
BO_ 257 BOX_Wheel: 8 Box
 SG_ Angle : 0|32@1+ (1,0) [0|0] "counts" Other
 SG_ Speed : 32|16@1- (0.1,0) [-3000|3000] "rpm" Other
 SG_ Level : 48|8@1+ (1,0) [0|100] "%" Other
 SG_ Cnt : 56|4@1+ (1,0) [0|15] "" Other
BO_ 258 BOX_Event: 2 Box
 SG_ Flag : 0|1@1+ (1,0) [0|1] "" Other
BO_ 512 OTHER_Msg: 1 Other
 SG_ X : 0|8@1+ (1,0) [0|255] "" Box
BA_DEF_ BO_ "GenMsgCycleTime" INT 0 65535;
BA_DEF_ BO_ "GenMsgSendType" ENUM "NoMsgSendType","Cyclic","Event";
BA_DEF_ BO_ "GenMsgStartDelayTime" INT 0 65535;
BA_DEF_ SG_ "GenSigStartValue" INT 0 65535;
BA_DEF_DEF_ "GenMsgSendType" "Cyclic";
BA_ "GenMsgCycleTime" BO_ 256 10;
BA_ "GenMsgCycleTime" BO_ 257 20;
BA_ "GenMsgStartDelayTime" BO_ 257 5;
BA_ "GenMsgSendType" BO_ 258 2;
BA_ "GenSigStartValue" SG_ 256 Spare 9;
)";

std::shared_ptr<const bus::DbcDatabase> Db() {
  return std::make_shared<const bus::DbcDatabase>(bus::DbcDatabase::Parse(kDbc, "box.dbc"));
}

using testing::RecordingPort;

DbcSignalBinding Bind(const char* signal, DbcQuantity q, const char* message = "") {
  DbcSignalBinding b;
  b.message = message;
  b.signal = signal;
  b.quantity = q;
  b.field = std::string("dbc.signals.") + signal;
  return b;
}

DbcDeviceConfig Config() {
  DbcDeviceConfig c;
  c.name = "box";
  c.node = "Box";
  c.signals = {Bind("Yaw", DbcQuantity::kRateZ),        Bind("Ax", DbcQuantity::kAccelX),
               Bind("Temp", DbcQuantity::kTemperature), Bind("Cnt", DbcQuantity::kCounter),
               Bind("Crc", DbcQuantity::kChecksum),     Bind("Angle", DbcQuantity::kWheelAngle),
               Bind("Speed", DbcQuantity::kWheelSpeed), Bind("Level", DbcQuantity::kConstant)};
  c.signals[4].checksum.kind = ChecksumKind::kCrc8H2F;
  c.signals[5].counts_per_rev = 4096;
  c.signals[5].wheel_index = 1;
  c.signals[6].wheel_index = 1;
  c.signals[7].value = 250;  // beyond the DBC's [0|100]: sent clamped
  c.temperature_k = 273.15 + 35;
  return c;
}

// A body turning at 0.5 rad/s, the sensor mounted upside down (roll 180 deg): its z axis is the
// body's -z, so it reads -0.5 rad/s; wheel 1 at 3/4 turn spinning at 10 rad/s.
TEST(DbcDevice, SendsEveryCyclicMessageOfItsNodeInTheDbcUnits) {
  DbcDeviceConfig c = Config();
  c.R_BS = MountRotation({180, 0, 0});
  DbcDevice d(Db(), c);
  ASSERT_EQ(d.message_count(), 2u);  // BOX_Event is "Event" (written as index 2): not sent
  EXPECT_EQ(d.message(0).name, "BOX_Rates");
  physics::BodyTruth body;
  body.omega_WB_W = {0, 0, 0.5};  // level: the same in B
  std::vector<physics::WheelTruth> wheels(2);
  wheels[1].angle_rad = 1.5 * std::numbers::pi;
  wheels[1].omega_rad_s = 10;
  DeviceWorld world{&body, &wheels, {}};
  RecordingPort port;
  d.Poll(44'000'000, world, port);
  // BOX_Rates at 0, 10, .., 40 ms; BOX_Wheel at 5 (GenMsgStartDelayTime), 25 ms.
  std::vector<std::pair<std::uint32_t, std::int64_t>> order;
  for (const auto& f : port.sent) order.emplace_back(f.frame.id, f.due_ns / 1'000'000);
  EXPECT_THAT(order,
              ::testing::ElementsAre(std::pair{256u, 0}, std::pair{257u, 5}, std::pair{256u, 10},
                                     std::pair{256u, 20}, std::pair{257u, 25}, std::pair{256u, 30},
                                     std::pair{256u, 40}));
  const auto db = Db();
  const auto rates = bus::DecodeMessage(*db->FindMessage("BOX_Rates"), port.sent[3].frame);
  EXPECT_NEAR(rates.at("Yaw"), -0.5 * 180 / std::numbers::pi, 0.005 + 1e-9);
  // Upside down at rest the sensor's x is the body's x: no specific force along it.
  EXPECT_NEAR(rates.at("Ax"), 0.0, 0.0005 + 1e-9);
  EXPECT_DOUBLE_EQ(rates.at("Temp"), 35);
  EXPECT_DOUBLE_EQ(rates.at("Cnt"), 2);    // its third frame
  EXPECT_DOUBLE_EQ(rates.at("Spare"), 9);  // GenSigStartValue
  const std::span<const std::uint8_t> p(port.sent[3].frame.data.data(), 8);
  EXPECT_EQ(rates.at("Crc"), ComputeChecksum(ChecksumKind::kCrc8H2F,
                                             *db->FindMessage("BOX_Rates")->FindSignal("Crc"), p));
  const auto wheel = bus::DecodeMessage(*db->FindMessage("BOX_Wheel"), port.sent[4].frame);
  EXPECT_DOUBLE_EQ(wheel.at("Angle"), 3072);  // 3/4 of 4096 counts
  EXPECT_NEAR(wheel.at("Speed"), 10 * 60 / (2 * std::numbers::pi), 0.05 + 1e-9);
  EXPECT_DOUBLE_EQ(wheel.at("Level"), 100);
  EXPECT_DOUBLE_EQ(wheel.at("Cnt"), 1);
  EXPECT_EQ(d.clamped(), 2u);  // Level, in both BOX_Wheel frames
}

TEST(DbcDevice, ASharedCounterCountsSendInstantsAndAPhaseShiftsAMessage) {
  DbcDeviceConfig c = Config();
  c.signals[3].counter_shared = true;  // "Cnt" in both messages
  c.signals[3].counter_modulo = 15;
  DbcMessageTiming t;
  t.message = "BOX_Wheel";
  t.phase_ms = 5;  // 5 + 5 = 10 ms: with BOX_Rates
  t.field = "dbc.messages.BOX_Wheel";
  c.timing = {t};
  DbcDevice d(Db(), c);
  physics::BodyTruth body;
  std::vector<physics::WheelTruth> wheels(2);
  DeviceWorld world{&body, &wheels, {}};
  RecordingPort port;
  d.Poll(300'000'000, world, port);
  const auto db = Db();
  std::vector<std::pair<std::int64_t, double>> cnt;
  for (const auto& f : port.sent) {
    const auto v = bus::DecodeMessage(*db->FindMessage(f.frame.id, false), f.frame);
    cnt.emplace_back(f.due_ns / 1'000'000, v.at("Cnt"));
  }
  EXPECT_EQ(cnt[0], (std::pair<std::int64_t, double>{0, 0}));
  EXPECT_EQ(cnt[1], (std::pair<std::int64_t, double>{10, 1}));  // BOX_Rates
  EXPECT_EQ(cnt[2], (std::pair<std::int64_t, double>{10, 1}));  // BOX_Wheel: same instant
  // Modulo 15 wraps after 14: the instant at 150 ms has counter 0.
  for (const auto& [ms, v] : cnt) {
    if (ms == 150) {
      EXPECT_EQ(v, 0);
    }
    if (ms == 140) {
      EXPECT_EQ(v, 14);
    }
  }
}

TEST(DbcDevice, ConfigurationsTheDbcCannotCarryAreRefusedNamingTheField) {
  auto throws = [](DbcDeviceConfig c, const std::string& what) {
    EXPECT_THAT([&] { (void)DbcDevice(Db(), c); },
                ThrowsMessage<std::invalid_argument>(HasSubstr(what)));
  };
  DbcDeviceConfig c = Config();
  c.node = "Nobody";
  throws(c, "dbc.node: 'Nobody' is not a node of the DBC (BU_: Box, Other)");
  c = Config();
  c.signals.push_back(Bind("Nope", DbcQuantity::kRateX));
  throws(c, "dbc.signals.Nope: no message node Box sends cyclically has a signal 'Nope'");
  c = Config();
  c.signals.push_back(Bind("Flag", DbcQuantity::kConstant, "BOX_Event"));
  throws(c, "'BOX_Event' is not a cyclic message of node Box");
  c = Config();
  c.signals[0].quantity = DbcQuantity::kAccelZ;  // Yaw is in deg/s
  throws(c, "dbc.signals.Yaw: Yaw's unit 'deg/s' is not a unit of acceleration");
  c = Config();
  c.signals[5].counts_per_rev = 0;  // "counts" is no angle
  throws(c, "for encoder counts give counts_per_rev");
  c = Config();
  c.signals[4].checksum.kind = ChecksumKind::kCrc16Ccitt;
  throws(c, "Crc (8 bits) cannot carry a crc16_ccitt checksum");
  c = Config();
  c.signals[3].counter_modulo = 17;
  throws(c, "modulo 17 does not fit the 4 bits of Cnt");
  c = Config();
  c.signals.push_back(Bind("Yaw", DbcQuantity::kRateX, "BOX_Rates"));
  throws(c, "BOX_Rates.Yaw is bound twice");
  c = Config();
  DbcMessageTiming t;
  t.message = "OTHER_Msg";
  t.field = "dbc.messages.OTHER_Msg";
  c.timing = {t};
  throws(c, "dbc.messages.OTHER_Msg: 'OTHER_Msg' is not a message node Box sends");
}

// A two-channel motor controller described by its DBC: the firmware's MC_Command (received)
// sets each wheel's speed and the enable; MC_Feedback (sent every 10 ms) reports speed, current,
// torque and position of the left wheel.
constexpr const char* kMotorDbc = R"(VERSION ""
BU_: Fw Mc
BO_ 512 MC_Command: 5 Fw
 SG_ SpeedLeft : 0|16@1- (0.1,0) [-3000|3000] "rpm" Mc
 SG_ SpeedRight : 16|16@1- (0.1,0) [-3000|3000] "rpm" Mc
 SG_ Enable : 32|1@1+ (1,0) [0|1] "" Mc
BO_ 513 MC_Feedback: 8 Mc
 SG_ FbSpeedLeft : 0|16@1- (0.1,0) [-3000|3000] "rpm" Fw
 SG_ FbCurrentLeft : 16|16@1- (0.01,0) [-100|100] "A" Fw
 SG_ FbTorqueLeft : 32|16@1- (0.001,0) [-30|30] "Nm" Fw
 SG_ FbPosLeft : 48|16@1+ (1,0) [0|65535] "counts" Fw
BA_DEF_ BO_ "GenMsgCycleTime" INT 0 65535;
BA_ "GenMsgCycleTime" BO_ 513 10;
)";

DbcDeviceConfig MotorConfig() {
  DbcDeviceConfig c;
  c.name = "mc";
  c.node = "Mc";
  c.setpoint_timeout_s = 0.1;
  c.signals = {Bind("SpeedLeft", DbcQuantity::kWheelSpeedSetpoint),
               Bind("SpeedRight", DbcQuantity::kWheelSpeedSetpoint),
               Bind("Enable", DbcQuantity::kDriveEnable),
               Bind("FbSpeedLeft", DbcQuantity::kWheelSpeed),
               Bind("FbCurrentLeft", DbcQuantity::kMotorCurrent),
               Bind("FbTorqueLeft", DbcQuantity::kMotorTorque),
               Bind("FbPosLeft", DbcQuantity::kWheelAngle)};
  c.signals[0].wheel_index = 0;
  c.signals[0].motor_torque_limit_nm = 4.8;
  c.signals[1].wheel_index = 1;
  c.signals[1].motor_torque_limit_nm = 4.8;
  c.signals[1].gain = -1;  // the right motor is mounted mirrored
  c.signals[2].wheel_index = 1;
  c.signals[6].counts_per_rev = 1000;
  return c;
}

bus::CanFrame Command(double left_rpm, double right_rpm, int enable) {
  const auto db = bus::DbcDatabase::Parse(kMotorDbc, "mc.dbc");
  return bus::EncodeMessage(
      *db.FindMessage("MC_Command"),
      {{"SpeedLeft", left_rpm}, {"SpeedRight", right_rpm}, {"Enable", enable}});
}

TEST(DbcMotorController, SetPointsDriveTheWheelsAndFeedbackReportsThem) {
  const auto db =
      std::make_shared<const bus::DbcDatabase>(bus::DbcDatabase::Parse(kMotorDbc, "mc.dbc"));
  DbcDevice d(db, MotorConfig());
  RecordingPort port;
  auto drives = [&] { return d.wheel_drives(); };
  ASSERT_EQ(drives().size(), 2u);
  EXPECT_EQ(drives()[0].command.torque_limit_nm, 0.0);  // Before any set point: coasting.
  d.OnFrame(Command(30, 60, 1), 1'000'000, port);
  const double rpm = 2 * std::numbers::pi / 60;
  EXPECT_EQ(drives()[0].wheel, 0u);
  EXPECT_NEAR(drives()[0].command.omega_rad_s, 30 * rpm, 1e-12);
  EXPECT_EQ(drives()[0].command.torque_limit_nm, 4.8);  // No enable bound for the left wheel.
  EXPECT_NEAR(drives()[1].command.omega_rad_s, -60 * rpm, 1e-12);
  EXPECT_EQ(drives()[1].command.torque_limit_nm, 4.8);
  d.OnFrame(Command(30, 60, 0), 2'000'000, port);  // Right disabled: it coasts.
  EXPECT_EQ(drives()[1].command.torque_limit_nm, 0.0);
  EXPECT_EQ(drives()[0].command.torque_limit_nm, 4.8);
  // No set point for more than 0.1 s: every power stage off.
  d.EndStep(102'000'000);
  EXPECT_EQ(drives()[0].command.torque_limit_nm, 4.8);
  d.EndStep(102'000'001);
  EXPECT_EQ(drives()[0].command.torque_limit_nm, 0.0);
  d.OnFrame(Command(30, 60, 1), 103'000'000, port);
  EXPECT_EQ(drives()[0].command.torque_limit_nm, 4.8);
  // A short frame is refused and named; the set points stay.
  bus::CanFrame bad = Command(90, 90, 1);
  bad.len = 3;
  d.OnFrame(bad, 104'000'000, port);
  EXPECT_EQ(d.rejected_frames(), 1u);
  EXPECT_EQ(d.setpoint_frames(), 3u);
  ASSERT_EQ(port.events.size(), 1u);
  EXPECT_EQ(port.events[0]["message"], "MC_Command");
  EXPECT_THAT(port.events[0]["why"].get<std::string>(), HasSubstr("3 bytes"));
  EXPECT_NEAR(drives()[0].command.omega_rad_s, 30 * rpm, 1e-12);

  physics::BodyTruth body;
  std::vector<physics::WheelTruth> wheels(2);
  wheels[0].omega_rad_s = 3.0;
  wheels[0].motor_current_a = 2.5;
  wheels[0].motor_torque_nm = 1.25;
  wheels[0].angle_rad = std::numbers::pi;
  DeviceWorld world{&body, &wheels, {}};
  d.Poll(0, world, port);
  ASSERT_EQ(port.sent.size(), 1u);
  const auto fb = bus::DecodeMessage(*db->FindMessage("MC_Feedback"), port.sent[0].frame);
  EXPECT_NEAR(fb.at("FbSpeedLeft"), 3.0 / rpm, 0.05 + 1e-9);
  EXPECT_NEAR(fb.at("FbCurrentLeft"), 2.5, 0.005 + 1e-9);
  EXPECT_NEAR(fb.at("FbTorqueLeft"), 1.25, 0.0005 + 1e-9);
  EXPECT_DOUBLE_EQ(fb.at("FbPosLeft"), 500);
}

// A motor controller whose set points are 32-bit floats (they can say 1e30, NaN, inf).
std::shared_ptr<const bus::DbcDatabase> FloatSetpointDbc() {
  constexpr const char* kFloatDbc = R"(VERSION ""
BU_: Fw Mc
BO_ 512 MC_Command: 8 Fw
 SG_ SpeedLeft : 0|32@1- (1,0) [0|0] "rad/s" Mc
 SG_ SpeedRight : 32|32@1- (1,0) [0|0] "rad/s" Mc
BO_ 513 MC_Status: 1 Mc
 SG_ Alive : 0|8@1+ (1,0) [0|255] "" Fw
BA_DEF_ BO_ "GenMsgCycleTime" INT 0 65535;
BA_ "GenMsgCycleTime" BO_ 513 10;
SIG_VALTYPE_ 512 SpeedLeft : 1;
SIG_VALTYPE_ 512 SpeedRight : 1;
)";
  return std::make_shared<const bus::DbcDatabase>(bus::DbcDatabase::Parse(kFloatDbc, "mc.dbc"));
}

// A controller of two wheels' speed set points (signals of `message`, "" for the DBC's own).
DbcDeviceConfig SetPointConfig(const char* message = "") {
  DbcDeviceConfig c;
  c.name = "mc";
  c.node = "Mc";
  c.signals = {Bind("SpeedLeft", DbcQuantity::kWheelSpeedSetpoint, message),
               Bind("SpeedRight", DbcQuantity::kWheelSpeedSetpoint, message)};
  c.signals[0].motor_torque_limit_nm = 4.8;
  c.signals[1].wheel_index = 1;
  c.signals[1].motor_torque_limit_nm = 4.8;
  return c;
}

TEST(DbcMotorController, AbsurdSetPointsAreClampedAndNamed) {
  // A float signal can command 1e30 rad/s (NaN and inf are refused: see below).
  const auto db = FloatSetpointDbc();
  DbcDeviceConfig c = SetPointConfig();
  c.signals.push_back(Bind("Alive", DbcQuantity::kCounter));
  DbcDevice d(db, c);
  RecordingPort port;
  d.OnFrame(bus::EncodeMessage(*db->FindMessage("MC_Command"),
                               {{"SpeedLeft", 1e30}, {"SpeedRight", -12.5}}),
            1'000'000, port);
  EXPECT_EQ(d.wheel_drives()[0].command.omega_rad_s, 1000.0);
  EXPECT_EQ(d.wheel_drives()[1].command.omega_rad_s, -12.5);
  EXPECT_EQ(d.clamped_setpoints(), 1u);
  ASSERT_EQ(port.events.size(), 1u);
  EXPECT_EQ(port.events[0]["event"], "setpoint_clamped");
  EXPECT_EQ(port.events[0]["signal"], "SpeedLeft");
  EXPECT_EQ(port.events[0]["wheel"], 0);
  EXPECT_NEAR(port.events[0]["commanded_rad_s"].get<double>(), 1e30, 1e24);
  EXPECT_EQ(port.events[0]["limit_rad_s"], 1000.0);
  d.OnFrame(bus::EncodeMessage(*db->FindMessage("MC_Command"),
                               {{"SpeedLeft", -3e38}, {"SpeedRight", 0}}),
            2'000'000, port);
  EXPECT_EQ(d.wheel_drives()[0].command.omega_rad_s, -1000.0);
  EXPECT_EQ(d.clamped_setpoints(), 2u);
}

TEST(DbcMotorController, BindingsTheDbcCannotCarryAreRefusedNamingTheField) {
  const auto db =
      std::make_shared<const bus::DbcDatabase>(bus::DbcDatabase::Parse(kMotorDbc, "mc.dbc"));
  DbcDeviceConfig sent = MotorConfig();
  sent.signals[0] = Bind("FbSpeedLeft", DbcQuantity::kWheelSpeedSetpoint);  // Mc sends it
  EXPECT_THAT([&] { DbcDevice d(db, sent); },
              ThrowsMessage<std::invalid_argument>(
                  HasSubstr("dbc.signals.FbSpeedLeft: no message node Mc receives")));
  DbcDeviceConfig unit = MotorConfig();
  unit.signals[0] = Bind("Enable", DbcQuantity::kWheelSpeedSetpoint);
  unit.signals[2] = Bind("SpeedLeft", DbcQuantity::kDriveEnable);
  EXPECT_THAT([&] { DbcDevice d(db, unit); },
              ThrowsMessage<std::invalid_argument>(
                  HasSubstr("Enable's unit '' is not a unit of angular rate")));
  DbcDeviceConfig current = MotorConfig();
  current.signals[4] = Bind("FbSpeedLeft", DbcQuantity::kMotorCurrent);
  current.signals.erase(current.signals.begin() + 3);  // FbSpeedLeft's own binding
  EXPECT_THAT([&] { DbcDevice d(db, current); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("'rpm' is not a unit of current")));
}

// --- multiplexed messages and set points that are not numbers ------------------------------

// MC_Feedback's page 0 reports the left motor, page 1 the right one, page 2 the controller;
// MC_Command's channel 0 commands the left wheel, channel 1 the right one (float set points).
const std::string kMuxDbc =
    std::string(WHEELHIL_SOURCE_DIR) + "/tests/data/dbc/mux_motor_controller.dbc";

std::shared_ptr<const bus::DbcDatabase> MuxDb() {
  return std::make_shared<const bus::DbcDatabase>(bus::DbcDatabase::LoadFile(kMuxDbc));
}

DbcDeviceConfig MuxFeedbackConfig() {
  DbcDeviceConfig c;
  c.name = "mc";
  c.node = "Mc";
  c.signals = {Bind("SpeedLeft", DbcQuantity::kWheelSpeed),
               Bind("SpeedRight", DbcQuantity::kWheelSpeed),
               Bind("CurrentLeft", DbcQuantity::kMotorCurrent),
               Bind("Counter", DbcQuantity::kCounter), Bind("Crc", DbcQuantity::kChecksum)};
  c.signals[1].wheel_index = 1;
  c.signals[4].checksum.kind = ChecksumKind::kCrc8H2F;
  return c;
}

// Signals of pages 0 and 1 bound: each cycle sends page 0 with the left motor's signals, then
// page 1 with the right one's (one frame used to carry both speeds in the same bits under
// whatever the switch said).
TEST(DbcDevice, BoundSignalsOfTwoMultiplexerValuesGoOutAsOneFrameEach) {
  const auto db = MuxDb();
  DbcDevice d(db, MuxFeedbackConfig());
  physics::BodyTruth body;
  std::vector<physics::WheelTruth> wheels(2);
  wheels[0].omega_rad_s = 3.0;
  wheels[0].motor_current_a = 1.5;
  wheels[1].omega_rad_s = -2.0;
  DeviceWorld world{&body, &wheels, {}};
  RecordingPort port;
  d.Poll(15'000'000, world, port);  // cycles at 0 and 10 ms
  ASSERT_EQ(port.sent.size(), 4u);
  EXPECT_EQ(d.frames_sent(), 4u);
  const bus::DbcMessage& msg = *db->FindMessage("MC_Feedback");
  const double rpm = 2 * std::numbers::pi / 60;
  for (std::size_t i = 0; i < port.sent.size(); ++i) {
    const bus::CanFrame& f = port.sent[i].frame;
    EXPECT_EQ(port.sent[i].due_ns, i < 2 ? 0 : 10'000'000) << i;
    const auto v = bus::DecodeMessage(msg, f);
    EXPECT_EQ(v.at("Page"), static_cast<double>(i % 2)) << i;
    EXPECT_EQ(v.at("Counter"), static_cast<double>(i)) << i;  // frames of its message
    EXPECT_EQ(v.at("Crc"),
              ComputeChecksum(ChecksumKind::kCrc8H2F, *msg.FindSignal("Crc"), f.payload()));
    if (i % 2 == 0) {
      EXPECT_NEAR(v.at("SpeedLeft"), 3.0 / rpm, 0.05 + 1e-9) << i;
      EXPECT_NEAR(v.at("CurrentLeft"), 1.5, 0.005 + 1e-9) << i;
      EXPECT_FALSE(v.contains("SpeedRight"));
    } else {
      EXPECT_NEAR(v.at("SpeedRight"), -2.0 / rpm, 0.05 + 1e-9) << i;
      EXPECT_EQ(v.at("CurrentRight"), 0.0) << i;  // not bound, no start value
      EXPECT_FALSE(v.contains("SpeedLeft"));
    }
  }
}

TEST(DbcDevice, AMultiplexerSwitchTheDeviceMustSetIsNotBindable) {
  DbcDeviceConfig c = MuxFeedbackConfig();
  c.signals.push_back(Bind("Page", DbcQuantity::kConstant));
  EXPECT_THAT([&] { DbcDevice d(MuxDb(), c); },
              ThrowsMessage<std::invalid_argument>(HasSubstr(
                  "dbc.signals.Page: Page is the multiplexer switch of MC_Feedback, whose m0, m1 "
                  "signals are bound: the device sends one frame per bound multiplexer value")));
  // A multiplexer value its switch cannot say.
  const auto narrow = std::make_shared<const bus::DbcDatabase>(bus::DbcDatabase::Parse(
      "BU_: Mc Fw\nBO_ 513 Fb: 2 Mc\n SG_ Page M : 0|2@1+ (1,0) [0|0] \"\" Fw\n"
      " SG_ T m5 : 8|8@1+ (1,0) [0|0] \"\" Fw\nBA_DEF_ BO_ \"GenMsgCycleTime\" INT 0 65535;\n"
      "BA_ \"GenMsgCycleTime\" BO_ 513 10;\n",
      "narrow.dbc"));
  DbcDeviceConfig n;
  n.node = "Mc";
  n.signals = {Bind("T", DbcQuantity::kConstant)};
  EXPECT_THAT([&] { DbcDevice d(narrow, n); },
              ThrowsMessage<std::invalid_argument>(
                  HasSubstr("Fb: multiplexer value m5 does not fit the 2-bit switch Page")));
}

bus::CanFrame FloatCommand(const bus::DbcMessage& msg,
                           std::initializer_list<std::pair<const char*, float>> values,
                           std::optional<int> channel = std::nullopt) {
  bus::CanFrame f;
  f.id = msg.id;
  f.len = static_cast<std::uint8_t>(msg.length);
  const std::span<std::uint8_t> payload(f.data.data(), f.len);
  if (channel) bus::InsertRaw(*msg.multiplexer(), static_cast<std::uint64_t>(*channel), payload);
  for (const auto& [name, v] : values) {
    bus::InsertRaw(*msg.FindSignal(name), std::bit_cast<std::uint32_t>(v), payload);
  }
  return f;
}

// Channel 0's frame commands the left wheel only: the right wheel's set point shares its bits
// but belongs to channel 1's frames.
TEST(DbcMotorController, MultiplexedSetPointsAreReadFromTheirOwnFrames) {
  const auto db = MuxDb();
  const DbcDeviceConfig c = SetPointConfig("MC_Command");
  DbcDevice d(db, c);
  RecordingPort port;
  const bus::DbcMessage& cmd = *db->FindMessage("MC_Command");
  d.OnFrame(FloatCommand(cmd, {{"SpeedLeft", 5.0f}}, 0), 1'000'000, port);
  EXPECT_EQ(d.wheel_drives()[0].command.omega_rad_s, 5.0);
  EXPECT_EQ(d.wheel_drives()[0].command.torque_limit_nm, 4.8);
  EXPECT_EQ(d.wheel_drives()[1].command.torque_limit_nm, 0.0);  // no set point yet: coasting
  d.OnFrame(FloatCommand(cmd, {{"SpeedRight", -7.0f}}, 1), 2'000'000, port);
  EXPECT_EQ(d.wheel_drives()[0].command.omega_rad_s, 5.0);
  EXPECT_EQ(d.wheel_drives()[1].command.omega_rad_s, -7.0);
  EXPECT_EQ(d.setpoint_frames(), 2u);
  d.OnFrame(FloatCommand(cmd, {{"SpeedLeft", 9.0f}}, 3), 3'000'000, port);  // no such channel
  EXPECT_EQ(d.setpoint_frames(), 2u);
  EXPECT_EQ(d.wheel_drives()[0].command.omega_rad_s, 5.0);
}

// A float set point can be NaN or infinite. Such a frame is no command: counted, named, and it
// does not hold the power stages on past the set-point timeout (it used to be skipped silently
// while refreshing the timeout, so the wheels kept turning at the last set point).
TEST(DbcMotorController, NonFiniteSetPointsAreCountedNamedAndDoNotHoldTheTimeout) {
  const auto db = FloatSetpointDbc();
  DbcDeviceConfig c = SetPointConfig();
  c.setpoint_timeout_s = 0.1;
  DbcDevice d(db, c);
  RecordingPort port;
  const bus::DbcMessage& cmd = *db->FindMessage("MC_Command");
  constexpr float kNan = std::numeric_limits<float>::quiet_NaN();
  constexpr float kInf = std::numeric_limits<float>::infinity();
  d.OnFrame(FloatCommand(cmd, {{"SpeedLeft", 5.0f}, {"SpeedRight", 6.0f}}), 1'000'000, port);
  d.OnFrame(FloatCommand(cmd, {{"SpeedLeft", kNan}, {"SpeedRight", 8.0f}}), 50'000'000, port);
  EXPECT_EQ(d.nonfinite_setpoints(), 1u);
  EXPECT_EQ(d.wheel_drives()[1].command.omega_rad_s, 6.0);  // the frame is refused whole
  d.OnFrame(FloatCommand(cmd, {{"SpeedLeft", 4.0f}, {"SpeedRight", -kInf}}), 100'000'000, port);
  EXPECT_EQ(d.nonfinite_setpoints(), 2u);
  EXPECT_EQ(d.setpoint_frames(), 1u);
  ASSERT_EQ(port.events.size(), 2u);
  EXPECT_EQ(port.events[0]["event"], "setpoint_not_finite");
  EXPECT_EQ(port.events[0]["device"], "mc");
  EXPECT_EQ(port.events[0]["message"], "MC_Command");
  EXPECT_EQ(port.events[0]["signal"], "SpeedLeft");
  EXPECT_EQ(port.events[0]["wheel"], 0);
  EXPECT_EQ(port.events[0]["commanded"], "nan");
  EXPECT_EQ(port.events[1]["signal"], "SpeedRight");
  EXPECT_EQ(port.events[1]["wheel"], 1);
  EXPECT_EQ(port.events[1]["commanded"], "-inf");
  // 0.1 s after the last finite set point (1 ms) every power stage is off.
  d.EndStep(101'000'001);
  EXPECT_EQ(d.wheel_drives()[0].command.torque_limit_nm, 0.0);
  EXPECT_EQ(d.wheel_drives()[1].command.torque_limit_nm, 0.0);
  // A finite command brings them back.
  d.OnFrame(FloatCommand(cmd, {{"SpeedLeft", 2.0f}, {"SpeedRight", 3.0f}}), 120'000'000, port);
  EXPECT_EQ(d.wheel_drives()[0].command.omega_rad_s, 2.0);
  EXPECT_EQ(d.wheel_drives()[1].command.torque_limit_nm, 4.8);
}

}  // namespace
}  // namespace wheelhil::emulator
