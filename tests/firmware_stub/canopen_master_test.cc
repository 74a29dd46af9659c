#include "firmware_stub/canopen_master.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/firmware_stub/fw_test_devices.h"

namespace wheelhil::fw {
namespace {

using testing::Devices;
using ::testing::ElementsAre;
using ::testing::IsEmpty;
using testing::Strings;

constexpr std::int64_t kMs = 1'000'000;

class CanopenMasterTest : public ::testing::Test {
 protected:
  CanopenMasterTest() : protocol_(FwProtocol::LoadDir(testing::DbcDir(), {1, 2}, 0, 0)) {
    config_.node_ids = {1, 2};
    config_.boot_timeout_ns = 500 * kMs;
    config_.heartbeat_producer_ms = 100;
    config_.heartbeat_timeout_ns = 350 * kMs;
    config_.sdo_timeout_ns = 50 * kMs;
    config_.sdo_retries = 1;
    config_.tpdo_transmission_type = 1;
    config_.sync_period_ns = 10 * kMs;
  }

  /// Answers every SDO request in `frames` with success; returns the non-SDO frames.
  std::vector<bus::CanFrame> AnswerSdos(CanopenMaster& m, std::vector<bus::CanFrame> frames,
                                        std::int64_t t) {
    std::vector<bus::CanFrame> rest;
    while (!frames.empty()) {
      std::vector<bus::CanFrame> next;
      for (const auto& f : frames) {
        if (f.id >= 0x601 && f.id <= 0x67F) {
          EXPECT_TRUE(m.OnFrame(dev_.SdoAnswer(f), t));
          auto more = m.Poll(t).frames;
          next.insert(next.end(), more.begin(), more.end());
        } else {
          rest.push_back(f);
        }
      }
      frames = next;
    }
    return rest;
  }

  /// Boots both nodes at t and completes their configuration.
  void BootAll(CanopenMaster& m, std::int64_t t) {
    m.OnFrame(dev_.Boot(1), t);
    m.OnFrame(dev_.Boot(2), t);
    AnswerSdos(m, m.Poll(t).frames, t);
    ASSERT_TRUE(m.started());
  }

  Devices dev_;
  FwProtocol protocol_;
  CanopenMasterConfig config_;
};

TEST_F(CanopenMasterTest, BootUpThenSdoThenNmtStartThenSync) {
  CanopenMaster m(config_, protocol_);
  m.Start(0);
  EXPECT_THAT(m.Poll(0).frames, IsEmpty());  // Waits for boot-ups; no SYNC yet.
  EXPECT_FALSE(m.started());

  EXPECT_TRUE(m.OnFrame(dev_.Boot(1), 10 * kMs));
  auto p = m.Poll(10 * kMs);
  // TPDO1 transmission type 1 (0x1800:2, u8 -> command 0x2F).
  EXPECT_THAT(Strings(p.frames), ElementsAre("601#2F00180201000000"));
  EXPECT_TRUE(m.OnFrame(dev_.SdoAnswer(p.frames[0]), 11 * kMs));
  p = m.Poll(11 * kMs);
  // Producer heartbeat 100 ms (0x1017, u16 -> command 0x2B).
  EXPECT_THAT(Strings(p.frames), ElementsAre("601#2B17100064000000"));
  EXPECT_TRUE(m.OnFrame(dev_.SdoAnswer(p.frames[0]), 12 * kMs));
  p = m.Poll(12 * kMs);
  EXPECT_THAT(Strings(p.frames), ElementsAre("000#0101"));  // NMT start node 1.
  EXPECT_FALSE(p.sync_sent);
  EXPECT_FALSE(m.started());  // Node 2 still booting.

  m.OnFrame(dev_.Boot(2), 20 * kMs);
  p = m.Poll(20 * kMs);
  EXPECT_THAT(Strings(p.frames), ElementsAre("602#2F00180201000000"));
  m.OnFrame(dev_.SdoAnswer(p.frames[0]), 21 * kMs);
  p = m.Poll(21 * kMs);
  EXPECT_THAT(Strings(p.frames), ElementsAre("602#2B17100064000000"));
  m.OnFrame(dev_.SdoAnswer(p.frames[0]), 22 * kMs);
  p = m.Poll(22 * kMs);
  EXPECT_THAT(Strings(p.frames), ElementsAre("000#0102"));
  EXPECT_FALSE(p.sync_sent);
  EXPECT_TRUE(m.started());
  EXPECT_EQ(m.faults(), 0u);

  // The first SYNC one period after the last start, then on the 10 ms grid.
  EXPECT_EQ(m.NextEventNs(), 32 * kMs);
  EXPECT_THAT(m.Poll(31 * kMs).frames, IsEmpty());
  p = m.Poll(32 * kMs);
  EXPECT_THAT(Strings(p.frames), ElementsAre("080#"));
  EXPECT_TRUE(p.sync_sent);
  EXPECT_THAT(m.Poll(41 * kMs).frames, IsEmpty());
  EXPECT_THAT(Strings(m.Poll(42 * kMs).frames), ElementsAre("080#"));
  EXPECT_EQ(m.syncs_sent(), 2u);
}

TEST_F(CanopenMasterTest, ResetCommunicationAtStartWhenConfigured) {
  config_.reset_communication_at_start = true;
  CanopenMaster m(config_, protocol_);
  m.Start(0);
  EXPECT_THAT(Strings(m.Poll(0).frames), ElementsAre("000#8200"));
}

TEST_F(CanopenMasterTest, BootTimeoutSetsFaultAndTheOtherNodeRuns) {
  config_.heartbeat_timeout_ns = 0;  // No heartbeats in this test.
  CanopenMaster m(config_, protocol_);
  m.Start(0);
  m.OnFrame(dev_.Boot(1), 10 * kMs);
  const auto rest = AnswerSdos(m, m.Poll(10 * kMs).frames, 10 * kMs);
  EXPECT_THAT(Strings(rest), ElementsAre("000#0101"));
  EXPECT_FALSE(m.started());
  EXPECT_EQ(m.NextEventNs(), 500 * kMs);  // The boot timeout.
  EXPECT_FALSE(m.Poll(500 * kMs).sync_sent);
  EXPECT_TRUE(m.started());
  EXPECT_TRUE(m.Poll(510 * kMs).sync_sent);  // Keeps going without node 2.
  EXPECT_EQ(m.faults() & kFaultBootTimeout, kFaultBootTimeout);
  EXPECT_EQ(m.nodes_lost_mask(), 0b10u);
  EXPECT_EQ(m.nodes()[1].state, CanopenMaster::NodeState::kMissing);

  // Node 2 boots late: configured and started then; the fault clears.
  m.OnFrame(dev_.Boot(2), 600 * kMs);
  const auto late = AnswerSdos(m, m.Poll(600 * kMs).frames, 600 * kMs);
  EXPECT_THAT(Strings(late), ::testing::Contains("000#0102"));
  EXPECT_EQ(m.faults() & kFaultBootTimeout, 0u);
  EXPECT_EQ(m.nodes_lost_mask(), 0u);
}

TEST_F(CanopenMasterTest, HeartbeatLossSetsNodeLostAndRecoveryClearsIt) {
  CanopenMaster m(config_, protocol_);
  m.Start(0);
  BootAll(m, 10 * kMs);
  std::int64_t t = 10 * kMs;
  for (int i = 1; i <= 5; ++i) {  // Both nodes beat every 100 ms.
    t = (10 + 100 * i) * kMs;
    m.OnFrame(dev_.State(1, 0x05), t);
    m.OnFrame(dev_.State(2, 0x05), t);
    m.Poll(t);
  }
  EXPECT_EQ(m.faults(), 0u);
  // Node 2 goes silent after t = 510 ms; node 1 keeps beating.
  for (int i = 6; i <= 9; ++i) {
    t = (10 + 100 * i) * kMs;
    m.OnFrame(dev_.State(1, 0x05), t);
    m.Poll(t);
  }
  // 350 ms after 510 ms is 860 ms: at 910 ms node 2 is lost, node 1 is not.
  EXPECT_EQ(m.faults() & kFaultNodeLost, kFaultNodeLost);
  EXPECT_EQ(m.nodes_lost_mask(), 0b10u);
  EXPECT_TRUE(m.nodes()[1].lost);
  EXPECT_FALSE(m.nodes()[0].lost);
  EXPECT_TRUE(m.Poll(920 * kMs).sync_sent);  // SYNC keeps coming (degrade, not die).
  // It comes back.
  m.OnFrame(dev_.State(2, 0x05), 950 * kMs);
  m.Poll(950 * kMs);
  EXPECT_EQ(m.faults() & kFaultNodeLost, 0u);
  EXPECT_EQ(m.nodes_lost_mask(), 0u);
}

TEST_F(CanopenMasterTest, HeartbeatLossExactlyAtTheTimeout) {
  CanopenMaster m(config_, protocol_);
  m.Start(0);
  BootAll(m, 0);
  m.Poll(350 * kMs);  // Exactly 350 ms after the boot-up: not yet (">" timeout).
  EXPECT_EQ(m.faults() & kFaultNodeLost, 0u);
  m.Poll(350 * kMs + 1);
  EXPECT_EQ(m.faults() & kFaultNodeLost, kFaultNodeLost);
  EXPECT_EQ(m.nodes_lost_mask(), 0b11u);
}

TEST_F(CanopenMasterTest, SdoAbortSetsFaultAndStillStartsTheNode) {
  config_.node_ids = {1};
  CanopenMaster m(config_, protocol_);
  m.Start(0);
  m.OnFrame(dev_.Boot(1), 0);
  auto p = m.Poll(0);
  ASSERT_EQ(p.frames.size(), 1u);
  m.OnFrame(dev_.SdoAnswer(p.frames[0], 0x06090030), 1 * kMs);  // Value out of range.
  p = m.Poll(1 * kMs);
  EXPECT_THAT(Strings(p.frames), ElementsAre("601#2B17100064000000"));
  m.OnFrame(dev_.SdoAnswer(p.frames[0]), 2 * kMs);
  p = m.Poll(2 * kMs);
  EXPECT_THAT(Strings(p.frames), ElementsAre("000#0101"));
  EXPECT_EQ(m.faults(), static_cast<std::uint32_t>(kFaultSdo));
  EXPECT_EQ(m.nodes()[0].sdo_failures, 1u);
}

TEST_F(CanopenMasterTest, UnansweredSdoIsRetriedThenGivenUp) {
  config_.node_ids = {1};
  config_.heartbeat_producer_ms = 0;  // Only the TPDO type step.
  CanopenMaster m(config_, protocol_);
  m.Start(0);
  m.OnFrame(dev_.Boot(1), 0);
  EXPECT_THAT(Strings(m.Poll(0).frames), ElementsAre("601#2F00180201000000"));
  EXPECT_THAT(m.Poll(49 * kMs).frames, IsEmpty());
  EXPECT_THAT(Strings(m.Poll(50 * kMs).frames), ElementsAre("601#2F00180201000000"));  // Retry.
  EXPECT_THAT(Strings(m.Poll(100 * kMs).frames), ElementsAre("000#0101"));
  EXPECT_EQ(m.faults(), static_cast<std::uint32_t>(kFaultSdo));
}

TEST_F(CanopenMasterTest, EmcySetsFaultUntilErrorReset) {
  CanopenMaster m(config_, protocol_);
  m.Start(0);
  BootAll(m, 0);
  EXPECT_TRUE(m.OnFrame(dev_.Emcy(2, 0x7305, 0x81), 5 * kMs));
  EXPECT_EQ(m.faults() & kFaultEmcy, kFaultEmcy);
  EXPECT_EQ(m.nodes()[1].last_emcy_code, 0x7305);
  EXPECT_TRUE(m.OnFrame(dev_.Emcy(2, 0x0000, 0x00), 6 * kMs));
  EXPECT_EQ(m.faults() & kFaultEmcy, 0u);
}

TEST_F(CanopenMasterTest, NodeBackInPreOperationalIsStartedAgain) {
  CanopenMaster m(config_, protocol_);
  m.Start(0);
  BootAll(m, 0);
  m.OnFrame(dev_.State(1, 0x7F), 100 * kMs);
  EXPECT_THAT(Strings(m.Poll(100 * kMs).frames), ::testing::Contains("000#0101"));
}

TEST_F(CanopenMasterTest, NodeResetIsReconfigured) {
  CanopenMaster m(config_, protocol_);
  m.Start(0);
  BootAll(m, 0);
  m.OnFrame(dev_.Boot(1), 200 * kMs);  // The node reset itself.
  EXPECT_FALSE(m.started());
  EXPECT_THAT(Strings(m.Poll(200 * kMs).frames), ::testing::Contains("601#2F00180201000000"));
  EXPECT_EQ(m.nodes()[0].boot_count, 2u);
}

TEST_F(CanopenMasterTest, HeartbeatBeforeBootUpMeansAlreadyBooted) {
  CanopenMaster m(config_, protocol_);
  m.Start(0);
  m.OnFrame(dev_.State(1, 0x05), 10 * kMs);  // The firmware started after the node.
  EXPECT_THAT(Strings(m.Poll(10 * kMs).frames), ElementsAre("601#2F00180201000000"));
}

TEST_F(CanopenMasterTest, MalformedFramesAreCountedNotFatal) {
  CanopenMaster m(config_, protocol_);
  m.Start(0);
  EXPECT_TRUE(m.OnFrame(testing::Frame("701#0000"), 0));       // Heartbeat, DLC 2.
  EXPECT_TRUE(m.OnFrame(testing::Frame("081#0573"), 0));       // EMCY, DLC 2.
  EXPECT_TRUE(m.OnFrame(testing::Frame("581#60001802"), 0));   // SDO, DLC 4.
  EXPECT_FALSE(m.OnFrame(testing::Frame("709#00"), 0));        // Not our node.
  EXPECT_FALSE(m.OnFrame(testing::Frame("123#DEADBEEF"), 0));  // Not CANopen NMT/SDO.
  EXPECT_EQ(m.bad_frames(), 3u);
  EXPECT_EQ(m.faults() & kFaultBadFrame, kFaultBadFrame);
  EXPECT_EQ(m.nodes()[0].state, CanopenMaster::NodeState::kWaitBoot);
}

TEST_F(CanopenMasterTest, LatePollSkipsMissedSyncsInsteadOfBursting) {
  config_.node_ids = {};
  CanopenMaster m(config_, protocol_);
  m.Start(0);
  EXPECT_FALSE(m.Poll(0).sync_sent);
  EXPECT_TRUE(m.Poll(10 * kMs).sync_sent);
  EXPECT_EQ(m.Poll(65 * kMs).frames.size(), 1u);  // One SYNC, not five.
  EXPECT_EQ(m.NextEventNs(), 70 * kMs);
}

TEST_F(CanopenMasterTest, RejectsBadConfig) {
  config_.node_ids = {1, 1};
  EXPECT_THROW(CanopenMaster(config_, protocol_), std::invalid_argument);
  config_.node_ids = {0};
  EXPECT_THROW(CanopenMaster(config_, protocol_), std::invalid_argument);
}

}  // namespace
}  // namespace wheelhil::fw
