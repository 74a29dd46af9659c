// The firmware app against the emulator's own CiA 406 encoder nodes (CanopenEncoderNode over
// DbcCia406Codec) on a discrete-event bus in virtual time: the master's SDO configuration must
// be accepted by the real node model, the nodes must answer its SYNCs, and node faults and
// losses must show in FW_Status. (Only this test links the emulator; the firmware never does.)
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <memory>
#include <queue>

#include "emulator/devices/canopen_encoder_node.h"
#include "emulator/devices/dbc_cia406_codec.h"
#include "firmware_stub/fw_app.h"
#include "tests/firmware_stub/fw_test_devices.h"

namespace wheelhil::fw {
namespace {

constexpr std::int64_t kMs = 1'000'000;

const char* kConfig = R"(
estimator: paper000
canopen: {boot_timeout_s: 0.5, heartbeat_period_s: 0.1, heartbeat_timeout_s: 0.35}
sync: {period_s: 0.05, deadline_s: 0.04}
imu: {yaw_frame_id: 0x174}
paper000:
  track_width_m: 0.5
  wheel_radius_m: 0.075
  counts_per_rev: 2000
  left: {node_id: 1}
  right: {node_id: 2}
  residual_sigma_rad: 0.002
)";

/// Firmware + two encoder nodes + an IMU stub on one ideal bus (every frame reaches everyone
/// else at its due instant; ties in send order).
class Loop {
 public:
  Loop()
      : config_(ParseFwConfig(kConfig, "loop.yaml")),
        protocol_(FwProtocol::LoadDir(testing::DbcDir(), {1, 2}, 0x174, 0)),
        app_(config_, protocol_) {
    auto codec = emulator::DbcCia406Codec::FromFile(testing::DbcDir() + "/cia406_encoder.dbc");
    for (std::uint8_t id : {1, 2}) {
      emulator::Cia406NodeConfig c;
      c.node_id = id;
      c.power_on_delay_ns = 100 * kMs + id * kMs;
      c.response_delay_ns = 200'000;  // 0.2 ms SYNC/SDO -> answer.
      nodes_.push_back(std::make_unique<emulator::CanopenEncoderNode>(c, codec, 0));
    }
  }

  /// Runs the bus until `until_ns`. The wheels roll at 0.25 m/s from the start.
  void RunUntil(std::int64_t until_ns) {
    if (!started_) {
      std::vector<bus::CanFrame> out;
      app_.Start(0, out);
      Push(out, 0, kFirmware);
      started_ = true;
    }
    for (;;) {
      std::int64_t t = std::min(app_.NextEventNs(), next_imu_);
      for (const auto& n : nodes_) t = std::min(t, n->NextEventNs());
      if (!queue_.empty()) t = std::min(t, queue_.top().t);
      if (t > until_ns) break;
      now_ = t;
      for (std::size_t i = 0; i < nodes_.size(); ++i) {
        Measure(i);
        for (const auto& nf : nodes_[i]->Poll(t)) Push({nf.frame}, nf.due_ns, Src(i));
      }
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
      std::vector<bus::CanFrame> out;
      app_.Poll(t, out);
      Push(out, t, kFirmware);
    }
  }

  OutValues LastStatus() const { return statuses_.empty() ? OutValues{} : statuses_.back(); }
  OutValues LastPose() const { return poses_.empty() ? OutValues{} : poses_.back(); }
  emulator::CanopenEncoderNode& node(int i) { return *nodes_[static_cast<std::size_t>(i)]; }
  FwApp& app() { return app_; }
  std::int64_t now() const { return now_; }
  bool node2_unplugged_ = false;  ///< Node 2's frames no longer reach the bus.
  std::vector<OutValues> statuses_, poses_;

 private:
  static constexpr int kFirmware = 100, kImu = 101;
  static int Src(std::size_t i) { return static_cast<int>(i); }
  struct Ev {
    std::int64_t t;
    std::uint64_t seq;
    bus::CanFrame f;
    int src;
    bool operator<(const Ev& o) const { return t != o.t ? t > o.t : seq > o.seq; }
  };

  void Measure(std::size_t i) {
    const double x = 0.25 * static_cast<double>(now_) * 1e-9;
    const double counts = x / (2 * M_PI * 0.075) * 2000;
    nodes_[i]->SetMeasurement(static_cast<std::uint32_t>(std::llround(counts)),
                              0.25 / (2 * M_PI * 0.075) * 2000);
  }

  void Push(const std::vector<bus::CanFrame>& frames, std::int64_t t, int src) {
    for (const auto& f : frames) queue_.push({t, seq_++, f, src});
  }

  void Deliver(const Ev& ev) {
    if (ev.src == Src(1) && node2_unplugged_) return;
    if (ev.src != kFirmware) {
      std::vector<bus::CanFrame> out;
      app_.OnFrame(ev.f, ev.t, out);
      Push(out, ev.t, kFirmware);
    } else {
      OutValues v;
      if (protocol_.DecodeOutput(OutMessage::kStatus, ev.f, v)) statuses_.push_back(v);
      if (protocol_.DecodeOutput(OutMessage::kPose, ev.f, v)) poses_.push_back(v);
    }
    for (std::size_t i = 0; i < nodes_.size(); ++i) {
      if (ev.src == Src(i)) continue;
      Measure(i);
      for (const auto& nf : nodes_[i]->Poll(ev.t)) Push({nf.frame}, nf.due_ns, Src(i));
      for (const auto& nf : nodes_[i]->OnFrame(ev.f, ev.t)) Push({nf.frame}, nf.due_ns, Src(i));
    }
  }

  testing::Devices dev_;
  FwConfig config_;
  FwProtocol protocol_;
  FwApp app_;
  std::vector<std::unique_ptr<emulator::CanopenEncoderNode>> nodes_;
  std::priority_queue<Ev> queue_;
  std::uint64_t seq_ = 0;
  std::int64_t now_ = 0;
  std::int64_t next_imu_ = 5 * kMs;
  bool started_ = false;
};

TEST(FwEmulatorLoop, MasterConfiguresAndRunsTheEmulatedEncoderNodes) {
  Loop loop;
  loop.RunUntil(2000 * kMs);
  using State = emulator::CanopenEncoderNode::NmtState;
  EXPECT_EQ(loop.node(0).state(), State::kOperational);
  EXPECT_EQ(loop.node(1).state(), State::kOperational);
  EXPECT_EQ(loop.node(0).rejected_frames(), 0u);
  EXPECT_EQ(loop.app().master().faults(), 0u);
  for (const auto& n : loop.app().master().nodes()) {
    EXPECT_EQ(n.sdo_failures, 0u);
    EXPECT_EQ(n.last_heartbeat_state, 0x05);  // 0x1017 = 100 ms took effect.
  }
  // One status per 50 ms cycle from the first SYNC on, all Running.
  ASSERT_GT(loop.statuses_.size(), 30u);
  EXPECT_EQ(loop.app().stats().skipped_steps, 0u);
  EXPECT_EQ(loop.LastStatus().Get(OutField::kState), static_cast<double>(FwState::kRunning));
  EXPECT_EQ(loop.app().last_faults(), 0u);
  // Straight at 0.25 m/s: the pose advances 12.5 mm per cycle.
  const double steps = static_cast<double>(loop.app().stats().steps);
  EXPECT_NEAR(loop.LastPose().Get(OutField::kX), steps * 0.0125, 1e-3);
  EXPECT_NEAR(loop.LastPose().Get(OutField::kY), 0.0, 1e-3);
}

TEST(FwEmulatorLoop, NodeFaultAndNodeLossShowInTheStatus) {
  Loop loop;
  loop.RunUntil(1000 * kMs);
  loop.node(1).RaiseFault(0x7305, 0x81, loop.now());
  loop.RunUntil(1100 * kMs);
  EXPECT_EQ(loop.LastStatus().Get(OutField::kFaultEmcy), 1);
  EXPECT_EQ(loop.LastStatus().Get(OutField::kEmcyNodeId), 2);
  loop.node(1).ClearFault(loop.now());
  loop.RunUntil(1200 * kMs);
  EXPECT_EQ(loop.LastStatus().Get(OutField::kFaultEmcy), 0);

  loop.node2_unplugged_ = true;
  loop.RunUntil(1700 * kMs);
  const OutValues st = loop.LastStatus();
  EXPECT_EQ(st.Get(OutField::kNodeLostEnc2), 1);
  EXPECT_EQ(st.Get(OutField::kNodeLostEnc1), 0);
  EXPECT_EQ(st.Get(OutField::kState), static_cast<double>(FwState::kDegraded));
  const auto statuses = loop.statuses_.size();
  loop.RunUntil(2000 * kMs);
  EXPECT_GE(loop.statuses_.size(), statuses + 5);  // Still publishing every cycle.
}

}  // namespace
}  // namespace wheelhil::fw
