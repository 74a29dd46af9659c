// Tests for emulator/devices/cia402_drive_node.h: the CiA 402 drive walked with raw CAN frames
// (NMT, SDO, RPDO, SYNC, heartbeats) as a master sends them, every expected frame byte for byte.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <initializer_list>
#include <numbers>
#include <vector>

#include "bus/canopen_eds.h"
#include "emulator/devices/cia402_drive_node.h"
#include "emulator/devices/cia402_eds.h"

namespace wheelhil::emulator {
namespace {

using bus::CanFrame;
using State = Cia402DriveNode::State;

constexpr std::uint8_t kId = 5;
constexpr std::int64_t kMs = 1'000'000;

CanFrame Std(std::uint32_t id, std::initializer_list<std::uint8_t> bytes) {
  const std::vector<std::uint8_t> v(bytes);
  return CanFrame::Classic(id, v);
}
CanFrame Sdo(std::uint8_t cmd, std::uint16_t index, std::uint8_t sub, std::uint32_t data) {
  return Std(0x600 + kId,
             {cmd, static_cast<std::uint8_t>(index), static_cast<std::uint8_t>(index >> 8), sub,
              static_cast<std::uint8_t>(data), static_cast<std::uint8_t>(data >> 8),
              static_cast<std::uint8_t>(data >> 16), static_cast<std::uint8_t>(data >> 24)});
}
std::uint32_t Data(const CanFrame& f) {
  return f.data[4] | f.data[5] << 8 | f.data[6] << 16 | static_cast<std::uint32_t>(f.data[7]) << 24;
}
CanFrame Rpdo1(std::uint16_t cw, std::int32_t target) {
  const auto t = static_cast<std::uint32_t>(target);
  return Std(0x200 + kId, {static_cast<std::uint8_t>(cw), static_cast<std::uint8_t>(cw >> 8),
                           static_cast<std::uint8_t>(t), static_cast<std::uint8_t>(t >> 8),
                           static_cast<std::uint8_t>(t >> 16), static_cast<std::uint8_t>(t >> 24)});
}

// A drive with 10:1 gear, rpm units, booted at 100 ms.
class DriveTest : public ::testing::Test {
 protected:
  DriveTest() : drive_(Config(), 8.0) {}
  static Cia402DriveConfig Config() {
    Cia402DriveConfig c;
    c.node_id = kId;
    c.gear_ratio = 10;
    c.rated_torque_mnm = 500;  // 0.5 N*m motor side = 5 N*m at the wheel
    return c;
  }
  std::vector<NodeFrame> Poll(std::int64_t t) {
    t_ = t;
    return drive_.Poll(t);
  }
  std::vector<NodeFrame> Send(const CanFrame& f) {
    auto out = drive_.Poll(t_);
    auto more = drive_.OnFrame(f, t_);
    out.insert(out.end(), more.begin(), more.end());
    return out;
  }
  // An expedited SDO upload: the value, or the abort code (with *aborted set).
  std::uint32_t Upload(std::uint16_t index, std::uint8_t sub, bool* aborted = nullptr) {
    const auto out = Send(Sdo(0x40, index, sub, 0));
    EXPECT_EQ(out.size(), 1u);
    if (out.empty()) return 0;
    EXPECT_EQ(out[0].frame.id, 0x580u + kId);
    if (aborted != nullptr) *aborted = out[0].frame.data[0] == 0x80;
    return Data(out[0].frame);
  }
  // An expedited SDO download of `size` bytes: 0 or the abort code.
  std::uint32_t Download(std::uint16_t index, std::uint8_t sub, std::uint32_t v, int size) {
    const std::uint8_t cmd = static_cast<std::uint8_t>(0x23 | (4 - size) << 2);
    const auto out = Send(Sdo(cmd, index, sub, v));
    EXPECT_GE(out.size(), 1u);
    if (out.empty()) return 0xFFFFFFFF;
    if (out[0].frame.data[0] == 0x60) return 0;
    EXPECT_EQ(out[0].frame.data[0], 0x80);
    return Data(out[0].frame);
  }
  void BootAndStart() {
    const auto boot = Poll(100 * kMs);
    ASSERT_EQ(boot.size(), 1u);
    EXPECT_EQ(boot[0].frame.id, 0x700u + kId);
    EXPECT_EQ(boot[0].frame.data[0], 0x00);
    (void)Send(Std(0x000, {0x01, kId}));
    ASSERT_EQ(drive_.nmt_state(), Cia402DriveNode::NmtState::kOperational);
  }
  void Enable() {
    (void)Send(Rpdo1(0x06, 0));
    (void)Send(Rpdo1(0x07, 0));
    (void)Send(Rpdo1(0x0F, 0));
    ASSERT_EQ(drive_.state(), State::kOperationEnabled);
  }
  std::uint16_t Statusword() { return static_cast<std::uint16_t>(Upload(0x6041, 0)); }

  Cia402DriveNode drive_;
  std::int64_t t_ = 0;
};

TEST_F(DriveTest, BootsIntoSwitchOnDisabledAndServesItsDictionary) {
  EXPECT_EQ(drive_.state(), State::kNotReadyToSwitchOn);
  BootAndStart();
  EXPECT_EQ(drive_.state(), State::kSwitchOnDisabled);
  EXPECT_EQ(Statusword(), 0x0240);  // switch on disabled, remote
  EXPECT_EQ(Upload(0x1000, 0), 0x00020192u);
  EXPECT_EQ(Upload(0x6502, 0), 0x104u);  // pv and csv
  EXPECT_EQ(Upload(0x1600, 1), 0x60400010u);
  EXPECT_EQ(Upload(0x1600, 2), 0x60FF0020u);
  EXPECT_EQ(Upload(0x1A00, 1), 0x60410010u);
  EXPECT_EQ(Upload(0x1A01, 2), 0x60770010u);
  EXPECT_EQ(Upload(0x1400, 1), 0x200u + kId);
  EXPECT_EQ(Upload(0x1401, 1), 0x80000300u + kId);  // RPDO2 not valid by default
  EXPECT_EQ(Upload(0x6007, 0), 1u);
  // A 1-byte object answers with a 1-byte upload (0x4F).
  const auto out = Send(Sdo(0x40, 0x6061, 0, 0));
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].frame.data[0], 0x4F);
  bool aborted = false;
  EXPECT_EQ(Upload(0x2345, 0, &aborted), 0x06020000u);
  EXPECT_TRUE(aborted);
  EXPECT_EQ(Upload(0x6041, 3, &aborted), 0x06090011u);
  EXPECT_EQ(Download(0x6041, 0, 1, 2), 0x06010002u);  // read only
  EXPECT_EQ(Download(0x6040, 0, 6, 4), 0x06070010u);  // wrong length
  EXPECT_EQ(Download(0x6060, 0, 7, 1), 0x06090030u);  // mode 7 not supported
  EXPECT_EQ(Download(0x6060, 0, 9, 1), 0u);
  EXPECT_EQ(Upload(0x6061, 0), 9u);
  // Segmented transfers are not served.
  const auto seg = Send(Sdo(0x21, 0x6040, 0, 2));
  ASSERT_EQ(seg.size(), 1u);
  EXPECT_EQ(Data(seg[0].frame), 0x05040001u);
}

TEST_F(DriveTest, WalksEveryTransitionOfTheStateMachine) {
  BootAndStart();
  ASSERT_EQ(Download(0x6060, 0, 9, 1), 0u);
  // Illegal commands in Switch on disabled are ignored: switch on, enable operation.
  (void)Send(Rpdo1(0x07, 0));
  EXPECT_EQ(drive_.state(), State::kSwitchOnDisabled);
  (void)Send(Rpdo1(0x0F, 0));
  EXPECT_EQ(drive_.state(), State::kSwitchOnDisabled);
  (void)Send(Rpdo1(0x06, 0));  // 2
  EXPECT_EQ(drive_.state(), State::kReadyToSwitchOn);
  EXPECT_EQ(Statusword() & 0x6F, 0x21);
  (void)Send(Rpdo1(0x07, 0));  // 3
  EXPECT_EQ(drive_.state(), State::kSwitchedOn);
  EXPECT_EQ(Statusword() & 0x6F, 0x23);
  EXPECT_EQ(drive_.WheelCommand().torque_limit_nm, 0.0);  // no torque before enable
  (void)Send(Rpdo1(0x0F, 0));                             // 4
  EXPECT_EQ(drive_.state(), State::kOperationEnabled);
  EXPECT_EQ(Statusword() & 0x6F, 0x27);
  EXPECT_GT(drive_.WheelCommand().torque_limit_nm, 0.0);
  (void)Send(Rpdo1(0x07, 0));  // 5
  EXPECT_EQ(drive_.state(), State::kSwitchedOn);
  (void)Send(Rpdo1(0x06, 0));  // 6
  EXPECT_EQ(drive_.state(), State::kReadyToSwitchOn);
  (void)Send(Rpdo1(0x00, 0));  // 7 (disable voltage)
  EXPECT_EQ(drive_.state(), State::kSwitchOnDisabled);
  (void)Send(Rpdo1(0x06, 0));
  (void)Send(Rpdo1(0x02, 0));  // 7 (quick stop)
  EXPECT_EQ(drive_.state(), State::kSwitchOnDisabled);
  (void)Send(Rpdo1(0x06, 0));
  (void)Send(Rpdo1(0x0F, 0));  // 3 + 4 at once
  EXPECT_EQ(drive_.state(), State::kOperationEnabled);
  (void)Send(Rpdo1(0x06, 0));  // 8
  EXPECT_EQ(drive_.state(), State::kReadyToSwitchOn);
  (void)Send(Rpdo1(0x0F, 0));
  (void)Send(Rpdo1(0x00, 0));  // 9
  EXPECT_EQ(drive_.state(), State::kSwitchOnDisabled);
  (void)Send(Rpdo1(0x06, 0));
  (void)Send(Rpdo1(0x07, 0));
  (void)Send(Rpdo1(0x02, 0));  // 10
  EXPECT_EQ(drive_.state(), State::kSwitchOnDisabled);
  // 11 and 12: quick stop (option 2: quick-stop ramp, then Switch on disabled).
  Enable();
  (void)Send(Rpdo1(0x0F, 600));
  EXPECT_DOUBLE_EQ(drive_.demand_velocity(), 600);
  (void)Send(Rpdo1(0x0B, 600));  // 11
  EXPECT_EQ(drive_.state(), State::kQuickStopActive);
  EXPECT_EQ(Statusword() & 0x6F, 0x07);
  EXPECT_GT(drive_.WheelCommand().torque_limit_nm, 0.0);  // braking under torque
  (void)Poll(t_ + 6 * kMs);                               // 50000 rpm/s: 300 rpm in 6 ms
  EXPECT_NEAR(drive_.demand_velocity(), 300, 1e-6);
  EXPECT_EQ(drive_.state(), State::kQuickStopActive);
  (void)Poll(t_ + 6 * kMs);
  EXPECT_EQ(drive_.state(), State::kSwitchOnDisabled);  // 12 (quick stop complete)
  // 16: with option 6 the drive stays in Quick stop active and may be enabled again.
  ASSERT_EQ(Download(0x605A, 0, 6, 2), 0u);
  Enable();
  (void)Send(Rpdo1(0x0B, 0));
  (void)Poll(t_ + kMs);
  EXPECT_EQ(drive_.state(), State::kQuickStopActive);
  (void)Send(Rpdo1(0x0F, 0));  // 16
  EXPECT_EQ(drive_.state(), State::kOperationEnabled);
  (void)Send(Rpdo1(0x0B, 0));
  (void)Send(Rpdo1(0x00, 0));  // 12 (disable voltage)
  EXPECT_EQ(drive_.state(), State::kSwitchOnDisabled);
}

TEST_F(DriveTest, FollowsItsTargetThroughTheGearInBothVelocityModes) {
  BootAndStart();
  ASSERT_EQ(Download(0x6060, 0, 9, 1), 0u);
  Enable();
  (void)Send(Rpdo1(0x0F, 1200));  // csv: at once
  const double wheel = 1200 * 2 * std::numbers::pi / 60 / 10;
  EXPECT_NEAR(drive_.WheelCommand().omega_rad_s, wheel, 1e-12);
  EXPECT_NEAR(drive_.WheelCommand().torque_limit_nm, 5.0, 1e-12);  // min(8, 0.5 N*m x 10)
  // Polarity bit 6 inverts the commanded and reported velocity.
  ASSERT_EQ(Download(0x607E, 0, 0x40, 1), 0u);
  EXPECT_NEAR(drive_.WheelCommand().omega_rad_s, -wheel, 1e-12);
  drive_.SetMeasurement(0, -wheel, -1.0, -2.0);
  EXPECT_EQ(static_cast<std::int32_t>(Upload(0x606C, 0)), 1200);
  EXPECT_EQ(static_cast<std::int16_t>(Upload(0x6077, 0)), 200);  // 0.1 N*m of 0.5 = 200 per mille
  ASSERT_EQ(Download(0x607E, 0, 0, 1), 0u);
  // 0x6072 max torque limits the power stage.
  ASSERT_EQ(Download(0x6072, 0, 500, 2), 0u);
  EXPECT_NEAR(drive_.WheelCommand().torque_limit_nm, 2.5, 1e-12);
  // pv: along the profile acceleration (1000 rpm/s), deceleration (4000 rpm/s).
  ASSERT_EQ(Download(0x6083, 0, 1000, 4), 0u);
  ASSERT_EQ(Download(0x6084, 0, 4000, 4), 0u);
  (void)Send(Rpdo1(0x0F, 0));
  (void)Poll(t_ + kMs);
  ASSERT_EQ(Download(0x6060, 0, 3, 1), 0u);
  EXPECT_EQ(drive_.demand_velocity(), 0);
  (void)Send(Rpdo1(0x0F, 500));
  (void)Poll(t_ + 100 * kMs);
  EXPECT_NEAR(drive_.demand_velocity(), 100, 1e-9);
  (void)Poll(t_ + 400 * kMs);
  EXPECT_NEAR(drive_.demand_velocity(), 500, 1e-9);
  (void)Send(Rpdo1(0x0F, 0));
  (void)Poll(t_ + 50 * kMs);
  EXPECT_NEAR(drive_.demand_velocity(), 300, 1e-9);
  // Target reached (bit 10) once the measured speed is within the window.
  drive_.SetMeasurement(0, 0, 0, 0);
  (void)Poll(t_ + 100 * kMs);
  EXPECT_EQ(Statusword() & 0x0400, 0x0400);
  drive_.SetMeasurement(0, 100 * 2 * std::numbers::pi / 600, 0, 0);  // 100 rpm actual
  EXPECT_EQ(Statusword() & 0x0400, 0);
}

TEST_F(DriveTest, SyncSendsTpdosAndSynchronousRpdosWaitForIt) {
  BootAndStart();
  ASSERT_EQ(Download(0x6060, 0, 9, 1), 0u);
  drive_.SetMeasurement(2 * std::numbers::pi / 10, 100 * 2 * std::numbers::pi / 600, 0.5, 1.0);
  const auto out = Send(Std(0x080, {}));
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(out[0].frame.id, 0x180u + kId);
  EXPECT_EQ(out[0].frame.len, 6);
  EXPECT_EQ(out[0].frame.data[0] | out[0].frame.data[1] << 8, 0x0240);  // statusword
  EXPECT_EQ(out[0].frame.data[2] | out[0].frame.data[3] << 8, 100);     // 100 rpm
  EXPECT_EQ(out[1].frame.id, 0x280u + kId);
  EXPECT_EQ(out[1].frame.data[0] | out[1].frame.data[1] << 8, 4096);  // one motor turn
  EXPECT_EQ(out[1].frame.data[4] | out[1].frame.data[5] << 8, 100);   // 0.05 N*m: 100 per mille
  // RPDO1 synchronous (type 1): the controlword acts at the next SYNC only.
  ASSERT_EQ(Download(0x1400, 2, 1, 1), 0u);
  (void)Send(Rpdo1(0x06, 0));
  EXPECT_EQ(drive_.state(), State::kSwitchOnDisabled);
  (void)Send(Std(0x080, {}));
  EXPECT_EQ(drive_.state(), State::kReadyToSwitchOn);
  // Not in pre-operational: PDOs are not served there.
  (void)Send(Std(0x000, {0x80, kId}));
  EXPECT_TRUE(Send(Std(0x080, {})).empty());
}

TEST_F(DriveTest, PdoMappingIsChangedTheCia301Way) {
  BootAndStart();
  EXPECT_EQ(Download(0x1A00, 1, 0x60640020, 4), 0x06010000u);  // sub 0 is not 0
  ASSERT_EQ(Download(0x1A00, 0, 0, 1), 0u);
  ASSERT_EQ(Download(0x1A00, 1, 0x60640020, 4), 0u);
  ASSERT_EQ(Download(0x1A00, 2, 0x60410010, 4), 0u);
  ASSERT_EQ(Download(0x1A00, 3, 0x10000020, 4), 0u);
  EXPECT_EQ(Download(0x1A00, 0, 3, 1), 0x06040041u);  // 0x1000 is not mappable
  ASSERT_EQ(Download(0x1A00, 3, 0x606C0020, 4), 0u);
  ASSERT_EQ(Download(0x1A00, 4, 0x60770010, 4), 0u);
  EXPECT_EQ(Download(0x1A00, 0, 4, 1), 0x06040042u);  // 96 bits
  ASSERT_EQ(Download(0x1A00, 0, 2, 1), 0u);
  EXPECT_EQ(Download(0x1600, 0, 0, 1), 0u);
  ASSERT_EQ(Download(0x1600, 1, 0x60410010, 4), 0u);
  EXPECT_EQ(Download(0x1600, 0, 1, 1), 0x06040041u);  // a receive PDO maps writable objects
  // A valid PDO's COB-ID changes only through invalid.
  EXPECT_EQ(Download(0x1800, 1, 0x1A0, 4), 0x06090030u);
  ASSERT_EQ(Download(0x1800, 1, 0x800001A0u, 4), 0u);
  ASSERT_EQ(Download(0x1800, 1, 0x1A0, 4), 0u);
  ASSERT_EQ(Download(0x1801, 1, 0x80000000u | (0x280 + kId), 4), 0u);
  drive_.SetMeasurement(2 * std::numbers::pi, 0, 0, 0);
  const auto out = Send(Std(0x080, {}));
  ASSERT_EQ(out.size(), 1u);  // TPDO2 switched off
  EXPECT_EQ(out[0].frame.id, 0x1A0u);
  EXPECT_EQ(out[0].frame.len, 6);
  EXPECT_EQ(out[0].frame.data[0] | out[0].frame.data[1] << 8 | out[0].frame.data[2] << 16, 40960);
  EXPECT_EQ(out[0].frame.data[4] | out[0].frame.data[5] << 8, 0x0240);
}

TEST_F(DriveTest, FaultStopsTheWheelSendsEmcyAndResetsOnlyWhenTheCauseIsGone) {
  BootAndStart();
  ASSERT_EQ(Download(0x6060, 0, 9, 1), 0u);
  Enable();
  (void)Send(Rpdo1(0x0F, 1000));
  drive_.TripOverCurrent(t_, true);
  EXPECT_EQ(drive_.state(), State::kFault);
  EXPECT_EQ(drive_.WheelCommand().torque_limit_nm, 0.0);  // power stage off at once
  const auto emcy = Poll(t_ + kMs);
  ASSERT_EQ(emcy.size(), 1u);
  EXPECT_EQ(emcy[0].frame.id, 0x080u + kId);
  EXPECT_THAT(std::vector<int>(emcy[0].frame.data.begin(), emcy[0].frame.data.begin() + 8),
              ::testing::ElementsAre(0x10, 0x23, 0x03, 0, 0, 0, 0, 0));
  EXPECT_EQ(Statusword() & 0x4F, 0x08);
  EXPECT_EQ(Upload(0x603F, 0), 0x2310u);
  EXPECT_EQ(Upload(0x1001, 0), 0x03u);
  // Enabling does nothing in Fault; a reset while the cause persists is refused.
  (void)Send(Rpdo1(0x0F, 1000));
  (void)Send(Rpdo1(0x8F, 1000));
  EXPECT_EQ(drive_.state(), State::kFault);
  drive_.ClearOverCurrentCause();
  (void)Send(Rpdo1(0x8F, 1000));  // no rising edge: bit 7 was already set
  EXPECT_EQ(drive_.state(), State::kFault);
  (void)Send(Rpdo1(0x00, 0));
  const auto reset = Send(Rpdo1(0x80, 0));  // 15
  EXPECT_EQ(drive_.state(), State::kSwitchOnDisabled);
  const auto after = Poll(t_ + kMs);
  std::vector<NodeFrame> all = reset;
  all.insert(all.end(), after.begin(), after.end());
  ASSERT_EQ(all.size(), 1u);
  EXPECT_EQ(all[0].frame.data[0] | all[0].frame.data[1] << 8, 0x0000);  // error reset
  EXPECT_EQ(Upload(0x603F, 0), 0u);
}

TEST_F(DriveTest, OverCurrentTripsAfterTheTripTime) {
  Cia402DriveConfig c = Config();
  c.trip_current_a = 5;
  c.trip_time_s = 0.01;
  Cia402DriveNode d(c, 8.0);
  (void)d.Poll(100 * kMs);
  (void)d.OnFrame(Std(0x000, {0x01, kId}), 100 * kMs);
  (void)d.OnFrame(Sdo(0x2F, 0x6060, 0, 9), 100 * kMs);
  for (std::uint16_t cw : {0x06, 0x07, 0x0F}) (void)d.OnFrame(Rpdo1(cw, 100), 100 * kMs);
  ASSERT_EQ(d.state(), State::kOperationEnabled);
  d.SetMeasurement(0, 0, 4, 6.0);
  (void)d.Poll(105 * kMs);
  EXPECT_EQ(d.state(), State::kOperationEnabled);
  d.SetMeasurement(0, 0, 4, 4.0);  // below again: the timer restarts
  (void)d.Poll(106 * kMs);
  d.SetMeasurement(0, 0, 4, 6.0);
  (void)d.Poll(112 * kMs);
  EXPECT_EQ(d.state(), State::kOperationEnabled);
  (void)d.Poll(117 * kMs);
  EXPECT_EQ(d.state(), State::kFault);
  EXPECT_EQ(d.error_code(), 0x2310);
}

TEST_F(DriveTest, AbortConnectionActsWhenTheMastersHeartbeatStops) {
  for (int option : {1, 2, 3}) {
    SCOPED_TRACE(option);
    Cia402DriveNode d(Config(), 8.0);
    std::int64_t t = 100 * kMs;
    (void)d.Poll(t);
    (void)d.OnFrame(Std(0x000, {0x01, kId}), t);
    (void)d.OnFrame(Sdo(0x23, 0x1016, 1, 0x7F << 16 | 100), t);  // consume node 127, 100 ms
    (void)d.OnFrame(Sdo(0x2B, 0x6007, 0, static_cast<std::uint32_t>(option)), t);
    (void)d.OnFrame(Sdo(0x2F, 0x6060, 0, 9), t);
    for (std::uint16_t cw : {0x06, 0x07, 0x0F}) (void)d.OnFrame(Rpdo1(cw, 600), t);
    // No heartbeat yet: supervision has not started.
    (void)d.Poll(t += 500 * kMs);
    ASSERT_EQ(d.state(), State::kOperationEnabled);
    for (int i = 0; i < 5; ++i) {
      (void)d.Poll(t += 50 * kMs);
      (void)d.OnFrame(Std(0x77F, {0x05}), t);
    }
    (void)d.Poll(t += 99 * kMs);
    ASSERT_EQ(d.state(), State::kOperationEnabled);
    const auto out = d.Poll(t += 2 * kMs);
    if (option == 1) {
      EXPECT_EQ(d.state(), State::kFaultReactionActive);  // quick-stop ramp first (0x605E = 2)
      ASSERT_EQ(out.size(), 1u);
      EXPECT_EQ(out[0].frame.id, 0x080u + kId);
      EXPECT_EQ(out[0].frame.data[0] | out[0].frame.data[1] << 8, 0x8130);
      EXPECT_EQ(out[0].frame.data[2], 0x11);  // generic + communication
      (void)d.Poll(t += 20 * kMs);
      EXPECT_EQ(d.state(), State::kFault);  // 14
    } else if (option == 2) {
      EXPECT_EQ(d.state(), State::kSwitchOnDisabled);
      EXPECT_EQ(d.WheelCommand().torque_limit_nm, 0.0);
    } else {
      EXPECT_EQ(d.state(), State::kQuickStopActive);
      (void)d.Poll(t += 20 * kMs);
      EXPECT_EQ(d.state(), State::kSwitchOnDisabled);
    }
  }
}

TEST_F(DriveTest, RpdoDeadlineAndNmtStopAbortTheConnection) {
  BootAndStart();
  ASSERT_EQ(Download(0x6060, 0, 9, 1), 0u);
  ASSERT_EQ(Download(0x6007, 0, 2, 2), 0u);
  ASSERT_EQ(Download(0x1400, 5, 50, 2), 0u);
  Enable();
  (void)Poll(t_ + 49 * kMs);
  (void)Send(Rpdo1(0x0F, 100));
  (void)Poll(t_ + 49 * kMs);
  EXPECT_EQ(drive_.state(), State::kOperationEnabled);
  (void)Poll(t_ + 2 * kMs);
  EXPECT_EQ(drive_.state(), State::kSwitchOnDisabled);
  ASSERT_EQ(Download(0x1400, 5, 0, 2), 0u);
  Enable();
  (void)Send(Std(0x000, {0x02, 0}));  // NMT stop, all nodes
  EXPECT_EQ(drive_.state(), State::kSwitchOnDisabled);
  EXPECT_EQ(drive_.nmt_state(), Cia402DriveNode::NmtState::kStopped);
  EXPECT_TRUE(Send(Sdo(0x40, 0x6041, 0, 0)).empty());  // no SDO in stopped
}

TEST_F(DriveTest, ResetNodeRestoresDefaultsAndBootsAgain) {
  BootAndStart();
  ASSERT_EQ(Download(0x6060, 0, 9, 1), 0u);
  Enable();
  ASSERT_EQ(Download(0x1017, 0, 50, 2), 0u);
  const auto hb = Poll(t_ + 50 * kMs);
  ASSERT_EQ(hb.size(), 1u);
  EXPECT_EQ(hb[0].frame.data[0], 0x05);
  (void)Send(Std(0x000, {0x81, kId}));
  EXPECT_EQ(drive_.nmt_state(), Cia402DriveNode::NmtState::kOff);
  const auto boot = Poll(t_ + 10 * kMs);
  ASSERT_EQ(boot.size(), 1u);
  EXPECT_EQ(boot[0].frame.data[0], 0x00);
  EXPECT_EQ(drive_.state(), State::kSwitchOnDisabled);
  EXPECT_EQ(Upload(0x6060, 0), 0u);
  EXPECT_EQ(Upload(0x1017, 0), 0u);
}

TEST(Cia402DriveNode, RejectsABadConfiguration) {
  Cia402DriveConfig c;
  c.node_id = 0;
  EXPECT_THROW(Cia402DriveNode(c, 1.0), std::invalid_argument);
  c.node_id = 3;
  c.tpdo[0].map = {0x10000020};
  EXPECT_THROW(Cia402DriveNode(c, 1.0), std::invalid_argument);
  c.tpdo[0].map = {0x60410010};
  EXPECT_NO_THROW(Cia402DriveNode(c, 1.0));
  EXPECT_THROW(Cia402DriveNode(c, 0.0), std::invalid_argument);
}

TEST(Cia402Eds, ADcfSetsTheDriveDefaultsAndItsMapping) {
  const bus::EdsFile dcf = bus::EdsFile::Parse(
      "[DeviceComissioning]\nNodeID=7\n"
      "[6060]\nDataType=0x0002\nAccessType=rw\nDefaultValue=9\n"
      "[6007]\nDataType=0x0003\nAccessType=rw\nDefaultValue=3\n"
      "[1800sub1]\nDataType=0x0007\nAccessType=rw\nDefaultValue=$NODEID+0x180\n"
      "[1A00sub0]\nDataType=0x0005\nAccessType=rw\nDefaultValue=1\n"
      "[1A00sub1]\nDataType=0x0007\nAccessType=rw\nDefaultValue=0x60640020\n"
      "[2100]\nDataType=0x0006\nAccessType=rw\nDefaultValue=42\n",
      "servo.dcf");
  Cia402DriveConfig c;
  c.node_id = 0;
  ApplyCia402Eds(dcf, c);
  EXPECT_EQ(c.node_id, 7);
  EXPECT_EQ(c.default_mode, 9);
  EXPECT_EQ(c.abort_connection_option, 3);
  EXPECT_EQ(c.tpdo[0].cob_id, 0x187u);
  EXPECT_EQ(c.tpdo[0].map, std::vector<std::uint32_t>{0x60640020});
  ASSERT_EQ(c.extra_objects.size(), 1u);
  EXPECT_EQ(c.extra_objects[0].index, 0x2100);
  Cia402DriveNode d(c, 1.0);
  (void)d.Poll(100 * kMs);
  const auto up = d.OnFrame(Std(0x607, {0x40, 0x00, 0x21, 0, 0, 0, 0, 0}), 100 * kMs);
  ASSERT_EQ(up.size(), 1u);
  EXPECT_EQ(up[0].frame.data[0], 0x4B);  // 2-byte upload
  EXPECT_EQ(Data(up[0].frame), 42u);
  Cia402DriveConfig other;
  other.node_id = 8;
  EXPECT_THAT([&] { ApplyCia402Eds(dcf, other); },
              ::testing::ThrowsMessage<std::invalid_argument>(
                  ::testing::HasSubstr("servo.dcf: the DCF is for node 7, the drive is node 8")));
  EXPECT_THAT([&] { SetCia402Object(other, 0x6502, 0, 1); },
              ::testing::ThrowsMessage<std::invalid_argument>(
                  ::testing::HasSubstr("0x6502 sub 0 is not a setting of the drive")));
}

}  // namespace
}  // namespace wheelhil::emulator
