#include "firmware_stub/cycle_assembler.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <random>

namespace wheelhil::fw {
namespace {

constexpr std::int64_t kMs = 1'000'000;

CycleAssembler Make(std::vector<std::uint8_t> nodes = {1, 2, 3}) {
  return CycleAssembler({std::move(nodes), 8 * kMs});
}

TEST(CycleAssembler, ClosesWhenTheLastTpdoArrivesInAnyOrder) {
  auto a = Make();
  EXPECT_FALSE(a.OnSync(0));
  EXPECT_FALSE(a.OnTpdo(3, 300, 0, 1 * kMs));
  EXPECT_FALSE(a.OnTpdo(1, 100, -5, 1 * kMs));
  const auto c = a.OnTpdo(2, 200, 0, 2 * kMs);
  ASSERT_TRUE(c);
  EXPECT_EQ(c->close, AssembledCycle::Close::kComplete);
  EXPECT_TRUE(c->complete());
  EXPECT_EQ(c->index, 0u);
  EXPECT_EQ(c->encoders[0].position, 100u);  // In configured node order, not arrival order.
  EXPECT_EQ(c->encoders[0].speed, -5);
  EXPECT_EQ(c->encoders[1].position, 200u);
  EXPECT_EQ(c->encoders[2].position, 300u);
  EXPECT_FALSE(a.cycle_open());
  EXPECT_EQ(a.NextDeadlineNs(), std::numeric_limits<std::int64_t>::max());
}

TEST(CycleAssembler, DuplicateInTheCycleIsCountedAndTheFirstKept) {
  auto a = Make({1, 2});
  a.OnSync(0);
  EXPECT_FALSE(a.OnTpdo(1, 100, 0, 1));
  EXPECT_FALSE(a.OnTpdo(1, 999, 0, 2));
  const auto c = a.OnTpdo(2, 200, 0, 3);
  ASSERT_TRUE(c);
  EXPECT_EQ(c->encoders[0].position, 100u);
  EXPECT_EQ(a.duplicates(), 1u);
  // A repeat after the cycle closed is a duplicate too; a node not yet seen would be late.
  EXPECT_FALSE(a.OnTpdo(2, 200, 0, 4));
  EXPECT_EQ(a.duplicates(), 2u);
  EXPECT_EQ(a.late_frames(), 0u);
}

TEST(CycleAssembler, MissingTpdoClosesAtTheNextSyncWithTheMissingMask) {
  auto a = Make();
  a.OnSync(0);
  a.OnTpdo(1, 100, 0, 1);
  a.OnTpdo(3, 300, 0, 1);
  const auto c = a.OnSync(10 * kMs);
  ASSERT_TRUE(c);
  EXPECT_EQ(c->close, AssembledCycle::Close::kNextSync);
  EXPECT_EQ(c->missing_mask, 0b010u);
  EXPECT_FALSE(c->complete());
  EXPECT_EQ(a.incomplete_cycles(), 1u);
  // The next cycle is open and gets its own frames.
  EXPECT_TRUE(a.cycle_open());
  a.OnTpdo(1, 110, 0, 11 * kMs);
  a.OnTpdo(2, 210, 0, 11 * kMs);
  const auto d = a.OnTpdo(3, 310, 0, 11 * kMs);
  ASSERT_TRUE(d);
  EXPECT_EQ(d->index, 1u);
  EXPECT_EQ(d->interval_ns, 10 * kMs);
}

TEST(CycleAssembler, DeadlineClosesAnIncompleteCycleAndLateFramesAreCounted) {
  auto a = Make({1, 2});
  a.OnSync(100 * kMs);
  a.OnTpdo(1, 1, 0, 101 * kMs);
  EXPECT_EQ(a.NextDeadlineNs(), 108 * kMs);
  EXPECT_FALSE(a.Poll(108 * kMs - 1));
  const auto c = a.Poll(108 * kMs);
  ASSERT_TRUE(c);
  EXPECT_EQ(c->close, AssembledCycle::Close::kDeadline);
  EXPECT_EQ(c->missing_mask, 0b10u);
  EXPECT_FALSE(a.Poll(109 * kMs));             // Closed exactly once.
  EXPECT_FALSE(a.OnTpdo(2, 2, 0, 109 * kMs));  // The straggler.
  EXPECT_EQ(a.late_frames(), 1u);
  EXPECT_FALSE(a.OnSync(110 * kMs));  // Nothing was open any more.
}

TEST(CycleAssembler, WithoutDeadlineOnlyTheNextSyncClosesAnIncompleteCycle) {
  CycleAssembler a({{1, 2}, 0});
  a.OnSync(0);
  a.OnTpdo(1, 1, 0, 1);
  EXPECT_EQ(a.NextDeadlineNs(), std::numeric_limits<std::int64_t>::max());
  EXPECT_FALSE(a.Poll(1'000'000 * kMs));
  const auto c = a.OnSync(1'000'000 * kMs);
  ASSERT_TRUE(c);
  EXPECT_EQ(c->close, AssembledCycle::Close::kNextSync);
  EXPECT_EQ(c->missing_mask, 0b10u);
}

TEST(CycleAssembler, UnknownNodeIsCountedAndIgnored) {
  auto a = Make({1});
  a.OnSync(0);
  EXPECT_FALSE(a.OnTpdo(9, 1, 0, 1));
  EXPECT_EQ(a.unexpected_nodes(), 1u);
  EXPECT_TRUE(a.OnTpdo(1, 1, 0, 1));
}

TEST(CycleAssembler, AsyncSamplesBelongToTheIntervalTheSyncEnds) {
  auto a = Make({1});
  a.OnYawRate(1.0, 1);  // Before the first SYNC: interval ending at SYNC 0.
  a.OnSync(10 * kMs);
  a.OnYawRate(2.0, 11 * kMs);  // After SYNC 0: belongs to cycle 1.
  a.OnAccel({1, 2, 3, 4}, 11 * kMs);
  auto c0 = a.OnTpdo(1, 0, 0, 12 * kMs);
  ASSERT_TRUE(c0);
  EXPECT_EQ(c0->yaw_samples, 1u);
  EXPECT_DOUBLE_EQ(c0->yaw_rate_sum_rad_s, 1.0);
  EXPECT_EQ(c0->accel_samples, 0u);
  a.OnYawRate(4.0, 15 * kMs);
  a.OnSync(20 * kMs);
  auto c1 = a.OnTpdo(1, 0, 0, 21 * kMs);
  ASSERT_TRUE(c1);
  EXPECT_EQ(c1->yaw_samples, 2u);
  EXPECT_DOUBLE_EQ(c1->yaw_rate_sum_rad_s, 6.0);
  EXPECT_EQ(c1->accel_samples, 1u);
  EXPECT_DOUBLE_EQ(c1->accel_sum_m_s2[3], 4.0);
}

TEST(CycleAssembler, NoSynchronousInputsMeansTheSyncCompletesTheCycle) {
  auto a = Make({});
  a.OnAccel({1, 1, 1, 1}, 1);
  const auto c = a.OnSync(10);
  ASSERT_TRUE(c);
  EXPECT_EQ(c->accel_samples, 1u);
  EXPECT_EQ(c->close, AssembledCycle::Close::kComplete);
  EXPECT_TRUE(a.OnSync(20));
}

// Shuffled, duplicated and dropped TPDOs over many cycles: every cycle is closed exactly once,
// in order, and every reading that arrived before the next SYNC is in its own cycle.
TEST(CycleAssembler, RandomisedTrafficClosesEveryCycleOnceInOrder) {
  std::mt19937_64 rng(406);
  auto a = Make({1, 2, 3, 4});
  std::vector<AssembledCycle> closed;
  auto take = [&](std::optional<AssembledCycle> c) {
    if (c) closed.push_back(*c);
  };
  std::uint64_t dropped = 0, dups = 0;
  const int kCycles = 500;
  for (int k = 0; k < kCycles; ++k) {
    const std::int64_t t = k * 10 * kMs;
    take(a.OnSync(t));
    std::vector<std::uint8_t> order = {1, 2, 3, 4};
    std::shuffle(order.begin(), order.end(), rng);
    for (std::uint8_t n : order) {
      if (rng() % 20 == 0) {
        ++dropped;
        continue;
      }
      // Position encodes (cycle, node) so the test can check attribution.
      take(a.OnTpdo(n, static_cast<std::uint32_t>(k * 10 + n), 0, t + 1));
      if (rng() % 10 == 0) {
        ++dups;
        take(a.OnTpdo(n, 0xFFFFFFFF, 0, t + 2));
      }
    }
    take(a.Poll(t + 9 * kMs));
  }
  ASSERT_EQ(closed.size(), static_cast<std::size_t>(kCycles));
  std::uint64_t missing = 0;
  for (int k = 0; k < kCycles; ++k) {
    const auto& c = closed[static_cast<std::size_t>(k)];
    EXPECT_EQ(c.index, static_cast<std::uint64_t>(k));
    for (int i = 0; i < 4; ++i) {
      if (c.missing_mask & (1u << i)) {
        ++missing;
        EXPECT_FALSE(c.encoders[static_cast<std::size_t>(i)].present);
      } else {
        EXPECT_EQ(c.encoders[static_cast<std::size_t>(i)].position,
                  static_cast<std::uint32_t>(k * 10 + i + 1));
      }
    }
  }
  EXPECT_EQ(missing, dropped);
  EXPECT_GT(dropped, 0u);
  EXPECT_EQ(a.duplicates(), dups);
  EXPECT_EQ(a.late_frames(), 0u);
}

TEST(CycleAssembler, RejectsBadConfig) {
  EXPECT_THROW(CycleAssembler({{1, 1}, kMs}), std::invalid_argument);
  EXPECT_THROW(CycleAssembler({{1}, -1}), std::invalid_argument);
  EXPECT_THROW(CycleAssembler({{1, 2, 3, 4, 5, 6, 7, 8, 9}, kMs}), std::invalid_argument);
}

}  // namespace
}  // namespace wheelhil::fw
