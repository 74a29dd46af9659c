#include "firmware_stub/fw_app.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <map>

#include "tests/firmware_stub/fw_test_devices.h"

namespace wheelhil::fw {
namespace {

using testing::Devices;

constexpr std::int64_t kMs = 1'000'000;

const char* kPaper000 = R"(
estimator: paper000
canopen: {boot_timeout_s: 0.5, heartbeat_period_s: 0.1, heartbeat_timeout_s: 0.35}
sync: {period_s: 0.25, deadline_s: 0.2}
imu: {yaw_frame_id: 0x174}
paper000:
  track_width_m: 0.5
  wheel_radius_m: 0.075
  counts_per_rev: 2000
  counter_bits: 32
  left: {node_id: 1}
  right: {node_id: 2}
  residual_mean_rad: 0.0
  residual_sigma_rad: 0.002
)";

const char* kPaper002 = R"(
estimator: paper002
canopen: {boot_timeout_s: 0.5, heartbeat_period_s: 0.1, heartbeat_timeout_s: 0.35}
sync: {period_s: 0.001}
accel: {frame_id: 0x170}
paper002:
  wheel_radius_m: 0.05
  wheel_mount_radius_m: 0.2
  counts_per_rev: 4096
  wheels:
    - {node_id: 1, angle_deg: 0}
    - {node_id: 2, angle_deg: 120}
    - {node_id: 3, angle_deg: 240}
  accel_mount_radius_m: 0.15
)";

/// The app on a simulated bus: encoder nodes that boot, answer SDOs, start on NMT, send TPDO1
/// on SYNC and beat; the IMU / accelerometers send what the test sets. All in virtual time.
class Bench {
 public:
  explicit Bench(const std::string& yaml, int beat_ms = 100)
      : config_(ParseFwConfig(yaml, "test.yaml")),
        protocol_(FwProtocol::LoadDir(testing::DbcDir(), NodeIds(config_),
                                      config_.imu.enabled ? config_.imu.yaw_frame_id : 0,
                                      config_.accel.enabled ? config_.accel.frame_id : 0)),
        app_(config_, protocol_),
        beat_ms_(beat_ms) {
    for (int id : NodeIds(config_)) alive_[id] = true;
  }

  static std::vector<int> NodeIds(const FwConfig& c) {
    std::vector<int> ids;
    for (const auto& n : c.encoder_nodes()) ids.push_back(n.node_id);
    return ids;
  }

  /// Boot-ups at 10 ms, then runs until the master has started every node.
  void StartUp() {
    std::vector<bus::CanFrame> out;
    app_.Start(0, out);
    Deliver(out, 0);
    t_ = 10 * kMs;
    for (const auto& [id, on] : alive_) {
      if (on) Feed(dev_.Boot(id));
    }
    ASSERT_TRUE(app_.master().started());
  }

  /// Runs until the app has sent the next SYNC: the IMU (every 10 ms) and heartbeats are fed in
  /// time order on the way, the accelerometers once just before the SYNC, and the nodes answer
  /// the SYNC with `positions` (node id -> counts). Returns the output frames the app sent
  /// meanwhile (estimates and status; those of a cycle closed by its deadline included).
  std::vector<bus::CanFrame> Cycle(const std::map<int, std::uint32_t>& positions,
                                   double yaw_rate_rad_s = 0.0,
                                   std::array<double, 4> accel = {0, 0, 0, 0}) {
    positions_ = positions;
    outputs_.clear();
    sync_seen_ = false;
    while (!sync_seen_) {
      const std::int64_t next = std::max(t_, app_.NextEventNs());
      for (;;) {  // Device events before `next`, in time order.
        const std::int64_t imu = config_.imu.enabled && imu_on_ ? next_imu_ : kNever;
        const std::int64_t beat = next_beat_;
        const std::int64_t ev = std::min(imu, beat);
        if (ev >= next) break;
        t_ = std::max(t_, ev);
        if (ev == imu) {
          Feed(dev_.Yaw(yaw_rate_rad_s));
          next_imu_ += 10 * kMs;
        } else {
          for (const auto& [id, on] : alive_) {
            if (on && started_[id]) Feed(dev_.State(id, 0x05));
          }
          next_beat_ += beat_ms_ * kMs;
        }
      }
      t_ = next;
      if (config_.accel.enabled && accel_on_ && app_.master().started() &&
          app_.NextEventNs() <= t_ && !accel_sent_) {
        Feed(dev_.Accel(accel, accel_counter_++));
        accel_sent_ = true;
      }
      std::vector<bus::CanFrame> out;
      app_.Poll(t_, out);
      Deliver(out, t_);
    }
    accel_sent_ = false;
    return outputs_;
  }

  void Feed(const bus::CanFrame& f) {
    std::vector<bus::CanFrame> out;
    app_.OnFrame(f, t_, out);
    Deliver(out, t_);
  }

  /// Decodes the last output frame `m` among `frames` (fails the test when absent).
  OutValues Out(const std::vector<bus::CanFrame>& frames, OutMessage m) const {
    for (auto it = frames.rbegin(); it != frames.rend(); ++it) {
      OutValues v;
      if (protocol_.DecodeOutput(m, *it, v)) return v;
    }
    ADD_FAILURE() << OutMessageName(m) << " not sent";
    return {};
  }

  FwApp& app() { return app_; }
  const FwProtocol& protocol() const { return protocol_; }
  const Devices& dev() const { return dev_; }
  std::map<int, bool> alive_;            ///< Node answers and beats.
  std::map<int, bool> drop_next_tpdo_;   ///< Node skips its next TPDO.
  std::map<int, int> repeat_next_tpdo_;  ///< Node sends its next TPDO this many times more.
  bool accel_on_ = true;
  bool imu_on_ = true;
  std::int64_t t_ = 0;
  std::vector<OutValues> statuses_;  ///< Every FW_Status the app sent.

 private:
  /// Plays the devices' side for every frame the app sent.
  void Deliver(const std::vector<bus::CanFrame>& frames, std::int64_t t) {
    for (const auto& f : frames) {
      if (f.id >= 0x601 && f.id <= 0x67F) {
        const int id = static_cast<int>(f.id - 0x600);
        if (alive_[id]) Feed(dev_.SdoAnswer(f));
      } else if (f.id == 0x000 && f.len == 2 && f.data[0] == 0x01) {
        started_[f.data[1]] = true;
      } else if (f.id == 0x080) {
        sync_seen_ = true;
        for (const auto& [id, pos] : positions_) {
          if (!alive_[id] || !started_[id]) continue;
          if (drop_next_tpdo_[id]) {
            drop_next_tpdo_[id] = false;
            continue;
          }
          const int copies = 1 + repeat_next_tpdo_[id];
          repeat_next_tpdo_[id] = 0;
          for (int i = 0; i < copies; ++i) Feed(dev_.Tpdo(id, pos));
        }
      } else if (f.id >= 0x680 && f.id <= 0x686) {
        outputs_.push_back(f);
        OutValues v;
        if (protocol_.DecodeOutput(OutMessage::kStatus, f, v)) statuses_.push_back(v);
      }
    }
    (void)t;
  }

  Devices dev_;
  FwConfig config_;
  FwProtocol protocol_;
  FwApp app_;
  int beat_ms_;
  static constexpr std::int64_t kNever = std::numeric_limits<std::int64_t>::max();
  std::int64_t next_beat_ = 110 * kMs;
  std::int64_t next_imu_ = 20 * kMs;
  std::map<int, bool> started_;
  std::map<int, std::uint32_t> positions_;
  bool sync_seen_ = false;
  bool accel_sent_ = false;
  int accel_counter_ = 0;
  std::vector<bus::CanFrame> outputs_;
};

/// Counts for `metres` of wheel travel (r = 0.075 m, 2000 counts/rev).
std::uint32_t Counts000(double metres) {
  return static_cast<std::uint32_t>(std::llround(metres / (2 * M_PI * 0.075) * 2000));
}

TEST(FwApp, Paper000StraightLineOutputsOnceEveryCycleWithTheCycleCounter) {
  Bench b(kPaper000);
  b.StartUp();
  double travel = 0.0;
  std::vector<bus::CanFrame> frames;
  for (int k = 0; k < 20; ++k) {
    frames = b.Cycle({{1, Counts000(travel)}, {2, Counts000(travel)}});
    // Order: estimates, then the status frame last.
    ASSERT_EQ(frames.size(), 5u) << "cycle " << k;
    EXPECT_EQ(frames.back().id, 0x686u);
    for (OutMessage m : {OutMessage::kPose, OutMessage::kPoseRaw, OutMessage::kSlipStatus,
                         OutMessage::kVelocity, OutMessage::kStatus}) {
      EXPECT_EQ(b.Out(frames, m).Get(OutField::kCycle), k) << OutMessageName(m);
    }
    // +1: the status sent at start while waiting for the nodes.
    EXPECT_EQ(b.Out(frames, OutMessage::kStatus).Get(OutField::kHeartbeat), k + 1);
    travel += 0.0625;  // 0.25 m/s for 0.25 s.
  }
  const OutValues pose = b.Out(frames, OutMessage::kPose);
  // 19 steps of 0.0625 m (the first cycle primes the counters); 0.5 mm LSB, quantised counts.
  EXPECT_NEAR(pose.Get(OutField::kX), 19 * 0.0625, 1e-3);
  EXPECT_NEAR(pose.Get(OutField::kY), 0.0, 1e-3);
  EXPECT_NEAR(b.Out(frames, OutMessage::kVelocity).Get(OutField::kVx), 0.25, 2e-3);
  const OutValues st = b.Out(frames, OutMessage::kStatus);
  EXPECT_EQ(st.Get(OutField::kState), static_cast<double>(FwState::kRunning));
  EXPECT_EQ(st.Get(OutField::kFaultBadFrame), 0);
  EXPECT_EQ(st.Get(OutField::kNodeLostEnc1), 0);
  EXPECT_EQ(b.app().stats().steps, 19u);
  EXPECT_EQ(b.app().last_faults(), 0u);
}

TEST(FwApp, Paper000SlipOfTheRightWheelIsFlaggedAndCorrected) {
  Bench b(kPaper000);
  b.StartUp();
  double left = 0, right = 0;
  std::vector<bus::CanFrame> frames;
  for (int k = 0; k < 8; ++k) {
    const bool spin = k == 5;
    frames = b.Cycle({{1, Counts000(left)}, {2, Counts000(right)}});
    if (k == 6) {  // The cycle whose interval contained the spin.
      const OutValues s = b.Out(frames, OutMessage::kSlipStatus);
      EXPECT_EQ(s.Get(OutField::kSlipRight), 1);
      EXPECT_EQ(s.Get(OutField::kSlipLeft), 0);
      EXPECT_GT(s.Get(OutField::kResidual), s.Get(OutField::kBandHigh));
      EXPECT_NEAR(s.Get(OutField::kBandHigh), 1.96 * 0.002, 2e-6);
    }
    left += 0.0625;
    right += 0.0625 + (spin ? 0.02 : 0.0);  // 20 mm spin, gyro says straight.
  }
  const OutValues pose = b.Out(frames, OutMessage::kPose);
  const OutValues raw = b.Out(frames, OutMessage::kPoseRaw);
  EXPECT_NEAR(pose.Get(OutField::kTheta), 0.0, 2e-3);        // Corrected: still straight.
  EXPECT_NEAR(raw.Get(OutField::kTheta), 0.02 / 0.5, 2e-3);  // Encoders: turned 40 mrad.
}

TEST(FwApp, StatusWhileWaitingForNodesThenDegradedWithoutThem) {
  Bench b(kPaper000);
  b.alive_[1] = b.alive_[2] = false;  // Nobody boots.
  std::vector<bus::CanFrame> out;
  b.app().Start(0, out);
  std::vector<std::pair<std::int64_t, OutValues>> statuses;
  for (std::int64_t t = 0; t <= 1000 * kMs; t = b.app().NextEventNs()) {
    b.app().Poll(t, out);
    for (const auto& f : out) {
      OutValues v;
      if (b.protocol().DecodeOutput(OutMessage::kStatus, f, v)) statuses.emplace_back(t, v);
    }
    out.clear();
  }
  // Every 250 ms while waiting (t = 0, 250 ms); the boot timeout (500 ms) ends the wait; the
  // first SYNC a period later; that cycle closes at its 200 ms deadline without TPDOs.
  ASSERT_EQ(statuses.size(), 3u);
  EXPECT_EQ(statuses[0].first, 0);
  EXPECT_EQ(statuses[1].first, 250 * kMs);
  for (int i = 0; i < 2; ++i) {
    EXPECT_EQ(statuses[i].second.Get(OutField::kState),
              static_cast<double>(FwState::kWaitingForNodes));
    EXPECT_EQ(statuses[i].second.Get(OutField::kCycle), 0);
    EXPECT_EQ(statuses[i].second.Get(OutField::kHeartbeat), i);
  }
  EXPECT_EQ(statuses[2].first, 950 * kMs);
  const OutValues& st = statuses[2].second;
  EXPECT_EQ(st.Get(OutField::kState), static_cast<double>(FwState::kDegraded));
  EXPECT_EQ(st.Get(OutField::kFaultBootTimeout), 1);
  EXPECT_EQ(st.Get(OutField::kFaultCycleIncomplete), 1);
  EXPECT_EQ(st.Get(OutField::kNodeLostEnc1), 1);
  EXPECT_EQ(st.Get(OutField::kNodeLostEnc2), 1);
  EXPECT_EQ(st.Get(OutField::kNodeLostEnc3), 0);
}

TEST(FwApp, EncoderCounterWrapIsSeamless) {
  Bench b(kPaper000);
  b.StartUp();
  const std::uint32_t start = 0xFFFFFFFFu - Counts000(0.3);  // Wraps after ~5 cycles.
  std::vector<bus::CanFrame> frames;
  for (int k = 0; k < 12; ++k) {
    const std::uint32_t c = start + Counts000(k * 0.0625);  // Unsigned wrap.
    frames = b.Cycle({{1, c}, {2, c}});
  }
  EXPECT_NEAR(b.Out(frames, OutMessage::kPose).Get(OutField::kX), 11 * 0.0625, 1e-3);
  EXPECT_EQ(b.app().last_faults(), 0u);
}

TEST(FwApp, OutputCycleCounterWrapsAt256) {
  Bench b(kPaper002);
  b.StartUp();
  std::vector<bus::CanFrame> frames;
  for (int k = 0; k < 258; ++k) frames = b.Cycle({{1, 0}, {2, 0}, {3, 0}});
  EXPECT_EQ(b.Out(frames, OutMessage::kPose).Get(OutField::kCycle), 257 % 256);
  EXPECT_EQ(b.Out(frames, OutMessage::kStatus).Get(OutField::kCycle), 1);
  EXPECT_EQ(b.Out(frames, OutMessage::kStatus).Get(OutField::kHeartbeat), 2);  // 259 % 256.
  EXPECT_EQ(b.app().stats().cycles, 258u);
}

// A dropped TPDO skips the step; the next complete cycle spans the gap with the absolute
// counters, so the pose ends where the run without drops ends. Duplicates change nothing.
TEST(FwApp, MissingAndDuplicatedTpdosDegradeButLoseNoTravel) {
  auto run = [](bool faults) {
    Bench b(kPaper000);
    b.StartUp();
    std::vector<bus::CanFrame> frames;
    double travel = 0.0;
    for (int k = 0; k < 16; ++k) {
      if (faults && k == 4) b.drop_next_tpdo_[2] = true;
      if (faults && k == 9) b.repeat_next_tpdo_[1] = 2;
      frames = b.Cycle({{1, Counts000(travel)}, {2, Counts000(travel * 1.01)}});
      travel += 0.05;
    }
    int degraded = 0;
    for (const auto& st : b.statuses_) {
      degraded += st.Get(OutField::kState) == static_cast<double>(FwState::kDegraded);
    }
    EXPECT_EQ(degraded, faults ? 2 : 0);  // The incomplete cycle and the one with duplicates.
    EXPECT_EQ(b.app().stats().skipped_steps, faults ? 1u : 0u);
    EXPECT_EQ(b.app().assembler().duplicates(), faults ? 2u : 0u);
    return b.Out(frames, OutMessage::kPose);
  };
  const OutValues clean = run(false);
  const OutValues degraded = run(true);
  EXPECT_NEAR(degraded.Get(OutField::kX), clean.Get(OutField::kX), 1e-3);
  EXPECT_NEAR(degraded.Get(OutField::kY), clean.Get(OutField::kY), 1e-3);
  EXPECT_NEAR(degraded.Get(OutField::kTheta), clean.Get(OutField::kTheta), 2e-4);
}

TEST(FwApp, BadTrafficIsCountedFlaggedAndSurvived) {
  Bench b(kPaper000);
  b.StartUp();
  b.Cycle({{1, 0}, {2, 0}});
  b.Feed(testing::Frame("181#0102"));                   // TPDO1 with DLC 2.
  b.Feed(testing::Frame("174#00"));                     // IMU with DLC 1.
  b.Feed(testing::Frame("321#DEADBEEF"));               // Unknown id.
  b.Feed(testing::Frame("20000004#0000000000000000"));  // Error frame.
  auto frames = b.Cycle({{1, 100}, {2, 100}});
  const OutValues st = b.Out(frames, OutMessage::kStatus);
  EXPECT_EQ(st.Get(OutField::kFaultBadFrame), 1);
  EXPECT_EQ(st.Get(OutField::kBadFrameCount), 4);
  EXPECT_EQ(b.app().stats().unknown_frames, 2u);
  // Still running: the next cycle steps and the bad-frame bit is this cycle's only.
  frames = b.Cycle({{1, 200}, {2, 200}});
  EXPECT_EQ(b.Out(frames, OutMessage::kStatus).Get(OutField::kFaultBadFrame), 0);
  EXPECT_EQ(b.Out(frames, OutMessage::kStatus).Get(OutField::kBadFrameCount), 4);
  EXPECT_EQ(b.app().stats().steps, 2u);
}

TEST(FwApp, LostNodeSetsItsBitAndTheFirmwareKeepsPublishing) {
  Bench b(kPaper000);
  b.StartUp();
  std::vector<bus::CanFrame> frames;
  for (int k = 0; k < 4; ++k) frames = b.Cycle({{1, 0}, {2, 0}});
  EXPECT_EQ(b.Out(frames, OutMessage::kStatus).Get(OutField::kNodeLostEnc2), 0);
  b.alive_[2] = false;  // Node 2 dies: no heartbeat, no TPDO.
  for (int k = 0; k < 3; ++k) frames = b.Cycle({{1, 0}, {2, 0}});
  const OutValues st = b.Out(frames, OutMessage::kStatus);
  EXPECT_EQ(st.Get(OutField::kNodeLostEnc2), 1);
  EXPECT_EQ(st.Get(OutField::kNodeLostEnc1), 0);
  EXPECT_EQ(st.Get(OutField::kState), static_cast<double>(FwState::kDegraded));
  EXPECT_EQ(b.app().last_faults() & kFaultNodeLost, kFaultNodeLost);
  EXPECT_EQ(b.app().last_faults() & kFaultCycleIncomplete, kFaultCycleIncomplete);
}

TEST(FwApp, EmcyIsReportedWithItsNode) {
  Bench b(kPaper000);
  b.StartUp();
  b.Cycle({{1, 0}, {2, 0}});
  b.Feed(b.dev().Emcy(2, 0x7305, 0x81));
  auto frames = b.Cycle({{1, 0}, {2, 0}});
  EXPECT_EQ(b.Out(frames, OutMessage::kStatus).Get(OutField::kFaultEmcy), 1);
  EXPECT_EQ(b.Out(frames, OutMessage::kStatus).Get(OutField::kEmcyNodeId), 2);
  b.Feed(b.dev().Emcy(2, 0, 0));
  frames = b.Cycle({{1, 0}, {2, 0}});
  EXPECT_EQ(b.Out(frames, OutMessage::kStatus).Get(OutField::kFaultEmcy), 0);
}

TEST(FwApp, SilentImuIsReportedLostAfterThreeCycles) {
  Bench b(R"(
estimator: paper000
sync: {period_s: 0.005}
imu: {}
paper000: {track_width_m: 0.5, wheel_radius_m: 0.075, counts_per_rev: 2000,
           left: {node_id: 1}, right: {node_id: 2}, residual_sigma_rad: 0.002}
)");  // 5 ms cycle: the 10 ms IMU is silent in every other cycle, never three in a row.
  b.StartUp();
  std::vector<bus::CanFrame> frames;
  for (int k = 0; k < 10; ++k) frames = b.Cycle({{1, 0}, {2, 0}});
  EXPECT_EQ(b.Out(frames, OutMessage::kStatus).Get(OutField::kNodeLostImu), 0);
  b.imu_on_ = false;
  frames = b.Cycle({{1, 0}, {2, 0}});  // Silent for 1 or 2 cycles now: not yet lost.
  EXPECT_EQ(b.Out(frames, OutMessage::kStatus).Get(OutField::kNodeLostImu), 0);
  for (int k = 0; k < 3; ++k) frames = b.Cycle({{1, 0}, {2, 0}});
  EXPECT_EQ(b.Out(frames, OutMessage::kStatus).Get(OutField::kNodeLostImu), 1);
  EXPECT_EQ(b.app().last_faults() & kFaultNodeLost, kFaultNodeLost);
}

// Encoder positions of kPaper002's three wheels after k cycles (1 ms) at vx = 0.1 m/s forward:
// wheel j at angle beta_j rolls along (-sin b, cos b), rim speed -sin(b) * vx, so it moves
// -sin(b) * 0.1 mm per cycle; 4096 counts per revolution of a 0.05 m wheel.
std::map<int, std::uint32_t> Paper002ForwardCounts(int k) {
  const double cpr = 4096, r = 0.05;
  std::map<int, std::uint32_t> pos;
  for (int j = 0; j < 3; ++j) {
    const double beta = j * 2.0 * M_PI / 3.0;
    const double rim_m = -std::sin(beta) * 0.1 * k * 1e-3;
    pos[j + 1] = static_cast<std::uint32_t>(
        static_cast<std::int64_t>(std::llround(rim_m / (2 * M_PI * r) * cpr)));
  }
  return pos;
}

TEST(FwApp, Paper002ConstantVelocityFusesToTheOdometry) {
  Bench b(kPaper002);
  b.StartUp();
  std::vector<bus::CanFrame> frames;
  for (int k = 0; k < 600; ++k) {
    frames = b.Cycle(Paper002ForwardCounts(k), 0.0, {0, 0, 0, 0});
  }
  ASSERT_EQ(frames.size(), 5u);
  const OutValues fused = b.Out(frames, OutMessage::kVelocity);
  const OutValues odom = b.Out(frames, OutMessage::kVelocityOdom);
  EXPECT_NEAR(odom.Get(OutField::kVx), 0.1, 3e-3);
  EXPECT_NEAR(fused.Get(OutField::kVx), 0.1, 3e-3);
  EXPECT_NEAR(fused.Get(OutField::kVy), 0.0, 3e-3);
  EXPECT_NEAR(b.Out(frames, OutMessage::kVelocityAccel).Get(OutField::kVx), 0.0, 1e-3);
  EXPECT_NEAR(b.Out(frames, OutMessage::kPose).Get(OutField::kX), 0.1 * 0.599, 1e-3);
  EXPECT_EQ(b.app().stats().accel_duplicates, 0u);
  EXPECT_EQ(b.app().last_faults(), 0u);
}

// Encoder 1 silent for 200 cycles (0.2 s) at vx = 0.1 m/s, noise-free accelerometers. The
// fused velocity must stay as close to the truth through and after the gap as before it (3 mm/s
// covers the 77 um count quantisation, as in the test above; the catch-up read as one cycle's
// motion gave ~0.4 m/s), the odometry velocity too once it is back, the pose must end where the
// counts say (no travel lost) and every gap cycle must be flagged.
TEST(FwApp, Paper002EncoderDropoutNeitherSpikesTheVelocityNorLosesTravel) {
  auto run = [](bool dropout) {
    Bench b(kPaper002);
    b.StartUp();
    std::vector<bus::CanFrame> frames;
    double max_fused_err = 0.0, max_odom_err = 0.0;
    int incomplete = 0, degraded = 0;
    constexpr int kGapStart = 300, kGapEnd = 500, kCycles = 900;
    for (int k = 0; k < kCycles; ++k) {
      const std::map<int, std::uint32_t> pos = Paper002ForwardCounts(k);
      const bool silent = dropout && k >= kGapStart && k < kGapEnd;
      if (silent) b.drop_next_tpdo_[1] = true;
      frames = b.Cycle(pos, 0.0, {0, 0, 0, 0});
      if (k < 200) continue;  // Start-up transient (the observer starts at rest).
      // Every estimate frame (an incomplete cycle's come out when the next SYNC closes it);
      // the odometry velocity is held while it is not observed.
      for (const auto& f : frames) {
        OutValues v;
        if (b.protocol().DecodeOutput(OutMessage::kVelocity, f, v)) {
          max_fused_err = std::max(max_fused_err, std::abs(v.Get(OutField::kVx) - 0.1));
        } else if (b.protocol().DecodeOutput(OutMessage::kVelocityOdom, f, v)) {
          max_odom_err = std::max(max_odom_err, std::abs(v.Get(OutField::kVx) - 0.1));
        }
      }
    }
    for (const auto& st : b.statuses_) {
      incomplete += st.Get(OutField::kFaultCycleIncomplete) == 1;
      degraded += st.Get(OutField::kState) == static_cast<double>(FwState::kDegraded);
    }
    std::printf(
        "paper002 %s dropout: max |vx - 0.1| after 0.2 s: fused %.2f mm/s, odometry %.2f mm/s\n",
        dropout ? "with" : "without", 1e3 * max_fused_err, 1e3 * max_odom_err);
    EXPECT_EQ(incomplete, dropout ? kGapEnd - kGapStart : 0);
    EXPECT_EQ(degraded, dropout ? kGapEnd - kGapStart : 0);
    EXPECT_EQ(b.app().stats().skipped_steps, dropout ? 200u : 0u);
    EXPECT_EQ(b.app().last_faults(), 0u);  // Healthy again after the gap.
    EXPECT_LT(max_fused_err, 3e-3) << (dropout ? "with" : "without") << " dropout";
    EXPECT_LT(max_odom_err, 3e-3) << (dropout ? "with" : "without") << " dropout";
    EXPECT_NEAR(b.Out(frames, OutMessage::kVelocity).Get(OutField::kVy), 0.0, 3e-3);
    // Pose after the last cycle: 0.1 m/s * 0.899 s (the first cycle primes the counters).
    const OutValues pose = b.Out(frames, OutMessage::kPose);
    EXPECT_NEAR(pose.Get(OutField::kX), 0.1 * (kCycles - 1) * 1e-3, 1e-3);
    return pose.Get(OutField::kX);
  };
  const double x_clean = run(false);
  const double x_dropout = run(true);
  EXPECT_NEAR(x_dropout, x_clean, 5e-4);  // One pose LSB: no counts lost in the gap.
}

TEST(FwApp, AccelDuplicateAndBadChecksumAreRejected) {
  Bench b(kPaper002);
  b.StartUp();
  b.Cycle({{1, 0}, {2, 0}, {3, 0}});
  b.Feed(b.dev().Accel({1, 0, 0, -1}, 0));  // Repeats the counter the bench just sent.
  EXPECT_EQ(b.app().stats().accel_duplicates, 1u);
  bus::CanFrame corrupt = b.dev().Accel({1, 0, 0, -1}, 3);
  corrupt.data[2] ^= 0x10;
  b.Feed(corrupt);
  EXPECT_EQ(b.app().stats().bad_frames, 1u);
}

TEST(FwApp, SameInputsGiveTheSameOutputs) {
  auto run = [] {
    Bench b(kPaper000);
    b.StartUp();
    std::vector<std::string> all;
    for (int k = 0; k < 30; ++k) {
      const double t = 0.0625 * k;
      const auto frames =
          b.Cycle({{1, Counts000(t)}, {2, Counts000(t * 1.02 + 0.001 * k)}}, 0.01 * std::sin(k));
      for (const auto& s : testing::Strings(frames)) all.push_back(s);
    }
    return all;
  };
  const auto first = run();
  EXPECT_EQ(first.size(), 150u);
  EXPECT_EQ(first, run());
}

// SYNC followed from the bus, 200 ms deadline: the second TPDO1 reaches the interface at
// `arrival` and the program reads it only at 250 ms (it was busy). Judged by its arrival, a frame
// that came after the deadline is late (the cycle closed without it) and one that came before
// it completes the cycle, however late it is read.
TEST(FwApp, TpdoIsJudgedByItsArrivalNotByWhenItIsRead) {
  const std::string yaml = std::string(kPaper000).replace(std::string(kPaper000).find("sync: {"), 7,
                                                          "sync: {produce: false, ");
  const FwConfig config = ParseFwConfig(yaml, "test.yaml");
  const FwProtocol protocol = FwProtocol::LoadDir(testing::DbcDir(), {1, 2}, 0x174, 0);
  const Devices dev;
  const bus::CanFrame sync = testing::Frame("080#");
  for (const std::int64_t arrival : {190 * kMs, 210 * kMs}) {
    FwApp app(config, protocol);
    std::vector<bus::CanFrame> out;
    app.Start(0, out);
    app.OnFrameArrived(sync, 0, out);
    app.OnFrameArrived(dev.Tpdo(1, 100), 100 * kMs, out);
    ASSERT_TRUE(app.assembler().cycle_open());
    app.OnFrameArrived(dev.Tpdo(2, 100), arrival, out);
    const bool late = arrival > 200 * kMs;
    EXPECT_EQ(app.assembler().cycles_closed(), 1u) << arrival;
    EXPECT_EQ(app.assembler().incomplete_cycles(), late ? 1u : 0u) << arrival;
    EXPECT_EQ(app.assembler().late_frames(), late ? 1u : 0u) << arrival;
  }
}

// The firmware following SYNC (as under `wheelhil run`): a script in bus time (SYNC every 250 ms,
// heartbeats every 100 ms, node 2's heartbeats lost from 1.0 s to 2.5 s, its TPDO1s still
// coming) played with the host clock `host_per_bus` times bus time. Returns every frame the app
// sent, as text, and the cycle counters of the FW_Status frames with Status_NodeLostEnc2 set.
struct FollowerRun {
  std::vector<std::string> frames;
  std::vector<int> lost_cycles;
  FwAppStats stats;
};

FollowerRun RunFollower(double host_per_bus) {
  const std::string yaml = std::string(kPaper000).replace(
      std::string(kPaper000).find("sync: {period_s: 0.25, deadline_s: 0.2}"), 39,
      "sync: {produce: false, period_s: 0.25, deadline_s: 0}");
  const FwConfig config = ParseFwConfig(yaml, "test.yaml");
  const FwProtocol protocol = FwProtocol::LoadDir(testing::DbcDir(), {1, 2}, 0x174, 0);
  const Devices dev;
  FwApp app(config, protocol);
  FollowerRun run;
  std::vector<bus::CanFrame> out;
  auto host = [&](std::int64_t bus_ns) {
    return static_cast<std::int64_t>(std::llround(static_cast<double>(bus_ns) * host_per_bus));
  };
  std::vector<bus::CanFrame> pending;  // Frames the app sent, answered by the nodes.
  auto flush = [&](std::int64_t bus_ns) {
    while (!out.empty()) {
      std::vector<bus::CanFrame> sent;
      sent.swap(out);
      for (const auto& f : sent) {
        run.frames.push_back(testing::Strings({f})[0]);
        OutValues v;
        if (protocol.DecodeOutput(OutMessage::kStatus, f, v) &&
            v.Get(OutField::kNodeLostEnc2) == 1) {
          run.lost_cycles.push_back(static_cast<int>(v.Get(OutField::kCycle)));
        }
        if (f.id >= 0x601 && f.id <= 0x602) app.OnFrameArrived(dev.SdoAnswer(f), host(bus_ns), out);
      }
    }
  };
  auto feed = [&](const bus::CanFrame& f, std::int64_t bus_ns) {
    app.OnFrameArrived(f, host(bus_ns), out);
    flush(bus_ns);
  };
  app.Start(0, out);
  flush(0);
  feed(dev.Boot(1), 10 * kMs);
  feed(dev.Boot(2), 10 * kMs);
  EXPECT_TRUE(app.master().started());
  for (std::int64_t t = 10 * kMs; t <= 4000 * kMs; t += 10 * kMs) {
    const bool beat = t % (100 * kMs) == 10 * kMs && t > 10 * kMs;
    if (beat) feed(dev.State(1, 0x05), t);
    if (beat && (t < 1000 * kMs || t > 2500 * kMs)) feed(dev.State(2, 0x05), t);
    if (t % (250 * kMs) == 0) {
      feed(dev.Yaw(0.0), t);
      feed(testing::Frame("080#"), t);
      feed(dev.Tpdo(1, 0), t);
      feed(dev.Tpdo(2, 0), t);
    }
    app.Poll(host(t + 5 * kMs), out);  // The program polls between frames too.
    flush(t + 5 * kMs);
  }
  run.stats = app.stats();
  return run;
}

// The heartbeat consumer runs on bus time while the firmware follows SYNC: node 2 silent for
// 1.5 s of bus time is flagged at the same cycle whether the frames come 200x faster than real
// time (a lockstep emulator) or 4x slower (a loaded host): the same frames out, byte for byte.
// Its last heartbeat (0.91 s) came in the interval of the SYNC at 0.75 s; the consumer waits
// heartbeat_timeout_s (0.35 s) + one period (0.6 s) of bus time, so the first SYNC beyond is
// 1.5 s (the 6th: cycle 5, as cycles count from 0 at the SYNC at 0.25 s); the heartbeat at
// 2.51 s clears it, after the status of the cycle opened at 2.5 s (cycle 9).
TEST(FwApp, FollowingSyncHeartbeatTimeoutIsJudgedOnBusTime) {
  const FollowerRun fast = RunFollower(1.0 / 200.0);
  const FollowerRun real = RunFollower(1.0);
  const FollowerRun slow = RunFollower(4.0);
  EXPECT_EQ(fast.lost_cycles, (std::vector<int>{5, 6, 7, 8, 9}));
  EXPECT_EQ(fast.frames, real.frames);
  EXPECT_EQ(fast.frames, slow.frames);
  EXPECT_EQ(fast.stats.cycles, 16u);        // SYNCs at 0.25 ... 4.0 s.
  EXPECT_EQ(slow.stats.sync_silences, 0u);  // 1 s of host time between SYNCs: not silent.
}

// No SYNC at all (dead bus or producer) for SyncSilenceNs() of host time: the master's timers
// fall back to the host clock, so a silent node is still flagged; the first SYNC after that
// puts them back on bus time (which never runs backwards).
TEST(FwApp, WithoutSyncTheMasterFallsBackToTheHostClock) {
  const std::string yaml = std::string(kPaper000).replace(
      std::string(kPaper000).find("sync: {period_s: 0.25, deadline_s: 0.2}"), 39,
      "sync: {produce: false, period_s: 0.01, deadline_s: 0}");
  const FwConfig config = ParseFwConfig(yaml, "test.yaml");
  const FwProtocol protocol = FwProtocol::LoadDir(testing::DbcDir(), {1, 2}, 0x174, 0);
  const Devices dev;
  FwApp app(config, protocol);
  ASSERT_EQ(app.SyncSilenceNs(), FwApp::kSyncSilenceMinNs);  // 10 periods are less.
  std::vector<bus::CanFrame> out;
  app.Start(0, out);
  auto answer = [&](std::int64_t t) {
    for (std::size_t i = 0; i < out.size(); ++i) {
      const bus::CanFrame f = out[i];
      if (f.id >= 0x601 && f.id <= 0x602) app.OnFrameArrived(dev.SdoAnswer(f), t, out);
    }
    out.clear();
  };
  app.OnFrameArrived(dev.Boot(1), 1 * kMs, out);
  app.OnFrameArrived(dev.Boot(2), 1 * kMs, out);
  answer(1 * kMs);
  ASSERT_TRUE(app.master().started());
  // Only node 1 beats; no SYNC. Within the grace bus time stands still: nobody is lost.
  std::int64_t t = 1 * kMs;
  for (; t < app.SyncSilenceNs(); t += 100 * kMs) {
    app.OnFrameArrived(dev.State(1, 0x05), t, out);
    app.Poll(t, out);
  }
  EXPECT_FALSE(app.master().nodes()[1].lost);
  EXPECT_FALSE(app.sync_silent());
  // Past the grace the host clock drives the timers: node 2 lost 0.36 s later, node 1 not.
  const std::int64_t due = app.SyncSilenceNs() + 360 * kMs + 10 * kMs;  // + one period.
  EXPECT_LE(app.NextEventNs(), due);
  for (; t <= due + 50 * kMs; t += 50 * kMs) {
    if (t % (100 * kMs) == 1 * kMs) app.OnFrameArrived(dev.State(1, 0x05), t, out);
    app.Poll(t, out);
  }
  EXPECT_TRUE(app.sync_silent());
  EXPECT_EQ(app.stats().sync_silences, 1u);
  EXPECT_TRUE(app.master().nodes()[1].lost);
  EXPECT_FALSE(app.master().nodes()[0].lost);
  // SYNC returns: bus time again, continuing from where the host clock took it.
  const std::int64_t before = app.MasterClockNs(t);
  app.OnFrameArrived(testing::Frame("080#"), t, out);
  EXPECT_FALSE(app.sync_silent());
  EXPECT_GE(app.MasterClockNs(t + 500 * kMs), before);
  EXPECT_EQ(app.MasterClockNs(t + 500 * kMs), app.MasterClockNs(t));  // Stands still again.
  EXPECT_TRUE(app.master().nodes()[1].lost);                          // Still silent.
  app.OnFrameArrived(dev.State(2, 0x05), t + kMs, out);
  EXPECT_FALSE(app.master().nodes()[1].lost);
}

TEST(FwApp, KernelStampIsMappedOntoTheMonotonicClock) {
  // 3 ms old at real time 1000.000 s, monotonic now 50 ms.
  EXPECT_EQ(ArrivalOnMonotonicNs(999'997 * kMs, 1'000'000 * kMs, 50 * kMs), 47 * kMs);
  // A stamp from the future or older than a second (clock stepped): now.
  EXPECT_EQ(ArrivalOnMonotonicNs(1'000'001 * kMs, 1'000'000 * kMs, 50 * kMs), 50 * kMs);
  EXPECT_EQ(ArrivalOnMonotonicNs(990'000 * kMs, 1'000'000 * kMs, 50 * kMs), 50 * kMs);
}

TEST(FwApp, BadEstimatorParametersNameTheFile) {
  FwConfig c = ParseFwConfig(kPaper002, "p2.yaml");
  c.paper002.angles_rad = {0.0, 0.0, 0.0};  // Singular wheel geometry.
  const FwProtocol p = FwProtocol::LoadDir(testing::DbcDir(), {1, 2, 3}, 0, 0x170);
  EXPECT_THAT([&] { FwApp(c, p); }, ::testing::ThrowsMessage<std::invalid_argument>(
                                        ::testing::HasSubstr("p2.yaml: paper002: wheels")));
}

}  // namespace
}  // namespace wheelhil::fw
