#include "firmware_stub/encoder_counter.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstdint>
#include <numbers>
#include <stdexcept>

namespace wheelhil::fw {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

TEST(CounterDelta, PlainSteps) {
  EXPECT_EQ(CounterDelta(100, 105, 32), 5);
  EXPECT_EQ(CounterDelta(105, 100, 32), -5);
  EXPECT_EQ(CounterDelta(7, 7, 16), 0);
}

TEST(CounterDelta, WrapsForwardAndBackward32Bit) {
  EXPECT_EQ(CounterDelta(0xFFFFFFFFu, 0x00000002u, 32), 3);
  EXPECT_EQ(CounterDelta(0x00000002u, 0xFFFFFFFFu, 32), -3);
  EXPECT_EQ(CounterDelta(0x7FFFFFFFu, 0x80000000u, 32), 1);  // Signed-overflow edge.
}

TEST(CounterDelta, WrapsNarrowCountersAndIgnoresHighBits) {
  EXPECT_EQ(CounterDelta(0xFFFE, 0x0001, 16), 3);
  EXPECT_EQ(CounterDelta(0x0001, 0xFFFE, 16), -3);
  EXPECT_EQ(CounterDelta(0xABCD0005, 0x12340009, 16), 4);  // Upper bits are not the counter's.
  EXPECT_EQ(CounterDelta(0x7F, 0x80, 8), 1);
  EXPECT_EQ(CounterDelta(0x00, 0x80, 8), -128);  // Half range: ambiguous, reported negative.
  EXPECT_EQ(CounterDelta(0x00, 0x7F, 8), 127);
}

TEST(CounterDelta, SixtyFourBitAndBadWidth) {
  EXPECT_EQ(CounterDelta(UINT64_MAX, 1, 64), 2);
  EXPECT_EQ(CounterDelta(1, UINT64_MAX, 64), -2);
  EXPECT_EQ(CounterDelta(0, 5, 0), 0);
  EXPECT_EQ(CounterDelta(0, 5, 65), 0);
}

TEST(CountsToMeters, OneRevolutionIsTheCircumference) {
  EXPECT_DOUBLE_EQ(CountsToMeters(4096, 4096.0, 0.05), 2.0 * std::numbers::pi * 0.05);
  EXPECT_DOUBLE_EQ(CountsToMeters(-1024, 4096.0, 0.05), -0.5 * std::numbers::pi * 0.05);
  EXPECT_NEAR(MetersToCounts(CountsToMeters(12345, 2000.0, 0.03), 2000.0, 0.03), 12345.0, 1e-9);
}

TEST(EncoderIncrement, PrimesThenUnwrapsA16BitCounterOverManyTurns) {
  EncoderIncrement enc(2000.0, 0.05, 16);
  std::uint64_t raw = 65000;  // Near the top, so it wraps almost at once.
  EXPECT_EQ(enc.Update(raw), 0.0);
  double total_m = 0.0;
  std::int64_t total_counts = 0;
  for (int i = 0; i < 1000; ++i) {
    raw = (raw + 300) & 0xFFFF;
    total_m += enc.Update(raw);
    total_counts += 300;
  }
  EXPECT_NEAR(total_m, CountsToMeters(total_counts, 2000.0, 0.05), 1e-9);
  EXPECT_GT(total_counts, 4 * 65536);  // It really wrapped several times.
  enc.Reset();
  EXPECT_EQ(enc.UpdateCounts(12), 0);
  EXPECT_EQ(enc.UpdateCounts(10), -2);
}

TEST(EncoderIncrement, RejectsBadConfig) {
  EXPECT_THAT([] { EncoderIncrement(0.0, 0.05, 32); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("counts_per_rev (0)")));
  EXPECT_THAT([] { EncoderIncrement(100.0, -1.0, 32); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("radius_m")));
  EXPECT_THAT([] { EncoderIncrement(100.0, 0.05, 0); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("counter_bits (0)")));
}

}  // namespace
}  // namespace wheelhil::fw
