// The reference firmware closing the loop against the emulator's own CiA 402 drive nodes and
// CiA 406 encoder nodes on an ideal discrete-event bus in virtual time, with ideal wheels (each
// turns at what its drive's power stage applies): the master's SDO configuration must be
// accepted by the drive model, the enable sequence must reach Operation enabled, the path must
// be driven, a drive fault must stop the other drive, and a firmware that stops (no heartbeat)
// must trip the drives' abort connection option. The firmware's wheel kinematics is checked
// against the emulator's inverse kinematics on the shipped Mecanum platform. (Links the
// emulator; the firmware itself never does.)
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <queue>

#include "bus/cia402.h"
#include "emulator/devices/canopen_encoder_node.h"
#include "emulator/devices/cia402_drive_node.h"
#include "emulator/devices/dbc_cia406_codec.h"
#include "emulator/platforms/platform.h"
#include "firmware_stub/drive_protocol.h"
#include "firmware_stub/fw_app.h"
#include "firmware_stub/path_follower.h"
#include "tests/firmware_stub/fw_test_devices.h"

namespace wheelhil::fw {
namespace {

constexpr std::int64_t kMs = 1'000'000;
constexpr double kR = 0.075, kGear = 20, kCounts = 2000;
using DriveState = bus::cia402::State;

const char* kConfig = R"(
estimator: paper000
canopen: {boot_timeout_s: 0.5, heartbeat_period_s: 0.1, heartbeat_timeout_s: 0.35}
sync: {period_s: 0.05, deadline_s: 0.04}
imu: {yaw_frame_id: 0x174}
paper000:
  track_width_m: 0.32
  wheel_radius_m: 0.075
  counts_per_rev: 2000
  left: {node_id: 1}
  right: {node_id: 2}
  residual_sigma_rad: 0.002
drives:
  gear_ratio: 20
  wheel_radius_m: 0.075
  master_heartbeat_s: 0.1
  nodes:
    - {node_id: 11, x_m: 0, y_m: 0.16}
    - {node_id: 12, x_m: 0, y_m: -0.16}
path: {waypoints: [[1.0, 0.0]], speed_m_s: 0.25, accel_m_s2: 0.5, tolerance_m: 0.005}
)";

/// Firmware + two encoders + two drives + an IMU stub; wheel i turns at drive i's command.
class DriveLoop {
 public:
  DriveLoop()
      : config_(ParseFwConfig(kConfig, "drive_loop.yaml")),
        protocol_(FwProtocol::LoadDir(testing::DbcDir(), {1, 2}, 0x174, 0)),
        drive_protocol_(DriveProtocol::LoadDir(testing::DbcDir(), {11, 12})),
        app_(config_, protocol_, &drive_protocol_) {
    auto codec = emulator::DbcCia406Codec::FromFile(testing::DbcDir() + "/cia406_encoder.dbc");
    for (std::uint8_t id : {1, 2}) {
      emulator::Cia406NodeConfig c;
      c.node_id = id;
      c.power_on_delay_ns = 100 * kMs + id * kMs;
      c.response_delay_ns = 200'000;
      encoders_.push_back(std::make_unique<emulator::CanopenEncoderNode>(c, codec, 0));
    }
    for (std::uint8_t id : {11, 12}) {
      emulator::Cia402DriveConfig c;
      c.node_id = id;
      c.power_on_delay_ns = 120 * kMs + id * kMs;
      c.response_delay_ns = 200'000;
      c.gear_ratio = kGear;
      drives_.push_back(std::make_unique<emulator::Cia402DriveNode>(c, 4.8, 0));
    }
  }

  void RunUntil(std::int64_t until_ns) {
    if (!started_) {
      std::vector<bus::CanFrame> out;
      app_.Start(0, out);
      Push(out, 0, kFirmware);
      started_ = true;
    }
    for (;;) {
      std::int64_t t = std::min(firmware_hung_ ? INT64_MAX : app_.NextEventNs(), next_imu_);
      for (const auto& n : encoders_) t = std::min(t, n->NextEventNs());
      for (const auto& n : drives_) t = std::min(t, n->NextEventNs());
      t = std::min(t, next_physics_);
      if (!queue_.empty()) t = std::min(t, queue_.top().t);
      if (t > until_ns) break;
      now_ = t;
      if (next_physics_ <= t) {
        Physics();
        next_physics_ += kMs;
      }
      PollNodes(t, -1);
      if (next_imu_ <= t) {
        Push({dev_.Yaw(0.0)}, t, kImu);
        next_imu_ += 10 * kMs;
      }
      if (!queue_.empty() && queue_.top().t <= t) {
        const Ev ev = queue_.top();
        queue_.pop();
        Deliver(ev);
        continue;
      }
      if (!firmware_hung_) {
        std::vector<bus::CanFrame> out;
        app_.Poll(t, out);
        Push(out, t, kFirmware);
      }
    }
  }

  emulator::Cia402DriveNode& drive(int i) { return *drives_[static_cast<std::size_t>(i)]; }
  FwApp& app() { return app_; }
  std::int64_t now() const { return now_; }
  double wheel_angle(int i) const { return angle_[static_cast<std::size_t>(i)]; }
  double wheel_speed(int i) const { return omega_[static_cast<std::size_t>(i)]; }
  bool firmware_hung_ = false;  ///< The firmware no longer runs (no frames, no Poll).
  std::vector<bus::CanFrame> emcy_;

 private:
  static constexpr int kFirmware = 100, kImu = 101;
  struct Ev {
    std::int64_t t;
    std::uint64_t seq;
    bus::CanFrame f;
    int src;
    bool operator<(const Ev& o) const { return t != o.t ? t > o.t : seq > o.seq; }
  };

  // Ideal wheels at 1 kHz: the speed the power stage applies, or stopped when it is off.
  void Physics() {
    for (std::size_t i = 0; i < 2; ++i) {
      const emulator::WheelDriveCommand c = drives_[i]->WheelCommand();
      omega_[i] = c.torque_limit_nm > 0 ? c.omega_rad_s : 0.0;
      angle_[i] += omega_[i] * 1e-3;
      drives_[i]->SetMeasurement(angle_[i], omega_[i], 0.0, 0.0);
      const double counts = angle_[i] / (2 * M_PI) * kCounts;
      encoders_[i]->SetMeasurement(static_cast<std::uint32_t>(std::llround(counts)),
                                   omega_[i] / (2 * M_PI) * kCounts);
    }
  }

  void PollNodes(std::int64_t t, int except) {
    for (std::size_t i = 0; i < 2; ++i) {
      if (static_cast<int>(i) != except) {
        for (const auto& nf : encoders_[i]->Poll(t))
          Push({nf.frame}, nf.due_ns, static_cast<int>(i));
      }
      if (static_cast<int>(i) + 10 != except) {
        for (const auto& nf : drives_[i]->Poll(t))
          Push({nf.frame}, nf.due_ns, static_cast<int>(i) + 10);
      }
    }
  }

  void Push(const std::vector<bus::CanFrame>& frames, std::int64_t t, int src) {
    for (const auto& f : frames) queue_.push({t, seq_++, f, src});
  }

  void Deliver(const Ev& ev) {
    if (ev.src >= 10 && ev.src < 20 && (ev.f.id & 0x780) == 0x080) emcy_.push_back(ev.f);
    if (ev.src != kFirmware && !firmware_hung_) {
      std::vector<bus::CanFrame> out;
      app_.OnFrame(ev.f, ev.t, out);
      Push(out, ev.t, kFirmware);
    }
    PollNodes(ev.t, ev.src);
    for (std::size_t i = 0; i < 2; ++i) {
      if (ev.src != static_cast<int>(i)) {
        for (const auto& nf : encoders_[i]->OnFrame(ev.f, ev.t)) {
          Push({nf.frame}, nf.due_ns, static_cast<int>(i));
        }
      }
      if (ev.src != static_cast<int>(i) + 10) {
        for (const auto& nf : drives_[i]->OnFrame(ev.f, ev.t)) {
          Push({nf.frame}, nf.due_ns, static_cast<int>(i) + 10);
        }
      }
    }
  }

  testing::Devices dev_;
  FwConfig config_;
  FwProtocol protocol_;
  DriveProtocol drive_protocol_;
  FwApp app_;
  std::vector<std::unique_ptr<emulator::CanopenEncoderNode>> encoders_;
  std::vector<std::unique_ptr<emulator::Cia402DriveNode>> drives_;
  std::array<double, 2> angle_{}, omega_{};
  std::priority_queue<Ev> queue_;
  std::uint64_t seq_ = 0;
  std::int64_t now_ = 0;
  std::int64_t next_imu_ = 5 * kMs;
  std::int64_t next_physics_ = 0;
  bool started_ = false;
};

TEST(FwDriveLoop, TheFirmwareEnablesTheDrivesAndDrivesThePath) {
  DriveLoop loop;
  loop.RunUntil(1000 * kMs);
  for (int i = 0; i < 2; ++i) {
    EXPECT_EQ(loop.drive(i).state(), DriveState::kOperationEnabled) << i;
    EXPECT_EQ(loop.drive(i).mode_display(), bus::cia402::mode::kCyclicSyncVelocity);
    EXPECT_EQ(loop.drive(i).rejected_frames(), 0u);
  }
  for (const auto& n : loop.app().master().nodes()) {
    EXPECT_EQ(n.sdo_failures, 0u) << int(n.node_id);  // 0x6060, 0x6007, 0x605A, 0x1016 taken.
  }
  loop.RunUntil(8000 * kMs);
  ASSERT_NE(loop.app().path(), nullptr);
  EXPECT_TRUE(loop.app().path()->done());
  // Ideal wheels: both turned 1 m of rim, within the follower's tolerance and a count.
  for (int i = 0; i < 2; ++i) EXPECT_NEAR(loop.wheel_angle(i) * kR, 1.0, 0.006) << i;
  EXPECT_NEAR(loop.wheel_angle(0), loop.wheel_angle(1), 1e-3);
  EXPECT_EQ(loop.wheel_speed(0), 0.0);  // At the goal: holding zero, still enabled.
  EXPECT_EQ(loop.drive(0).state(), DriveState::kOperationEnabled);
  EXPECT_EQ(loop.app().state(), FwState::kRunning);
}

TEST(FwDriveLoop, ADriveFaultStopsTheOtherDrive) {
  DriveLoop loop;
  loop.RunUntil(2000 * kMs);  // Cruising.
  ASSERT_GT(loop.wheel_speed(1), 3.0);
  loop.drive(0).RaiseFault(0x5441, loop.now());
  loop.RunUntil(2200 * kMs);
  EXPECT_EQ(loop.drive(0).state(), DriveState::kFault);
  ASSERT_NE(loop.app().drives(), nullptr);
  EXPECT_TRUE(loop.app().drives()->stopped());
  EXPECT_EQ(loop.app().drives()->stop_node(), 11);
  // Quick stop option 6 (the firmware's default): ramped to zero and held there, torque on.
  EXPECT_EQ(loop.drive(1).state(), DriveState::kQuickStopActive);
  EXPECT_EQ(loop.wheel_speed(1), 0.0);
  EXPECT_EQ(loop.app().state(), FwState::kFault);
  const double angle = loop.wheel_angle(1);
  loop.RunUntil(3000 * kMs);
  EXPECT_EQ(loop.wheel_angle(1), angle);  // Latched: it does not resume.
}

TEST(FwDriveLoop, AFirmwareThatStopsTripsTheDrivesAbortConnection) {
  DriveLoop loop;
  loop.RunUntil(2000 * kMs);
  ASSERT_EQ(loop.drive(0).state(), DriveState::kOperationEnabled);
  loop.firmware_hung_ = true;  // No more heartbeats, no more set points.
  const std::int64_t hung = loop.now();
  loop.RunUntil(hung + 250 * kMs);
  EXPECT_EQ(loop.drive(0).state(), DriveState::kOperationEnabled);  // Consumer time 0.3 s.
  loop.RunUntil(hung + 500 * kMs);
  for (int i = 0; i < 2; ++i) {
    EXPECT_NE(loop.drive(i).state(), DriveState::kOperationEnabled) << i;
    EXPECT_EQ(loop.drive(i).error_code(), bus::cia402::emcy::kHeartbeat) << i;
  }
  ASSERT_GE(loop.emcy_.size(), 2u);
  EXPECT_EQ(bus::ToCanUtilsString(loop.emcy_[0]).substr(4, 4), "3081");  // 0x8130, LE
}

TEST(FwDriveKinematics, MatchesTheEmulatorsInverseKinematicsOnTheMecanumPlatform) {
  const emulator::platforms::Platform p = emulator::platforms::LoadPlatformFile(
      std::string(WHEELHIL_SOURCE_DIR) + "/scenarios/platforms/mecanum4_omni3.yaml");
  const FwConfig c = LoadFwConfig(std::string(WHEELHIL_SOURCE_DIR) +
                                  "/scenarios/firmware/paper001_closed_loop.yaml");
  ASSERT_EQ(c.drives.nodes.size(), p.drive_wheels.size());
  for (const BodyVelocity v : {BodyVelocity{0.3, 0, 0}, BodyVelocity{0, -0.2, 0},
                               BodyVelocity{0, 0, 0.7}, BodyVelocity{0.1, 0.25, -0.4}}) {
    double w[4] = {};
    WheelSpeedsFor(c.drives, v, w);
    const auto expected = emulator::platforms::InverseKinematics(
        p, emulator::platforms::BodyTwist{v.vx_m_s, v.vy_m_s, v.omega_rad_s});
    for (std::size_t i = 0; i < 4; ++i) {
      EXPECT_NEAR(w[i], expected[p.drive_wheels[i]], 1e-9)
          << p.vehicle.wheels[p.drive_wheels[i]].name;
    }
  }
}

// Every shipped platform, its drive wheels described to the firmware as a customer would
// (contact point, heading, roller angle): the same wheel speeds as the emulator's kinematics.
TEST(FwDriveKinematics, MatchesTheEmulatorOnEveryShippedPlatform) {
  for (const char* name : {"diff2", "mecanum4_omni3", "ortho3"}) {
    SCOPED_TRACE(name);
    const emulator::platforms::Platform p = emulator::platforms::LoadPlatformFile(
        std::string(WHEELHIL_SOURCE_DIR) + "/scenarios/platforms/" + name + ".yaml");
    ASSERT_FALSE(p.drive_wheels.empty());
    DriveSettings d;
    d.wheel_radius_m = p.vehicle.wheels[p.drive_wheels[0]].radius_m;
    for (std::size_t i : p.drive_wheels) {
      const auto& w = p.vehicle.wheels[i];
      ASSERT_EQ(w.radius_m, d.wheel_radius_m);
      DriveNodeSettings n;
      n.x_m = w.mount_B.x();
      n.y_m = w.mount_B.y();
      n.heading_rad = w.heading_rad;
      n.has_rollers = w.kind != emulator::physics::WheelKind::kConventional;
      n.roller_angle_rad = w.roller_angle_rad;
      d.nodes.push_back(n);
    }
    for (const BodyVelocity v : {BodyVelocity{0.3, 0, 0}, BodyVelocity{0.1, 0.25, -0.4}}) {
      std::vector<double> w(d.nodes.size());
      BodyVelocity cmd = v;
      if (std::string(name) == "diff2") cmd.vy_m_s = 0;  // not holonomic
      WheelSpeedsFor(d, cmd, w.data());
      const auto expected = emulator::platforms::InverseKinematics(
          p, emulator::platforms::BodyTwist{cmd.vx_m_s, cmd.vy_m_s, cmd.omega_rad_s});
      for (std::size_t i = 0; i < w.size(); ++i) {
        EXPECT_NEAR(w[i], expected[p.drive_wheels[i]], 1e-9) << i;
      }
    }
  }
}

}  // namespace
}  // namespace wheelhil::fw
