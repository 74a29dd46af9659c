// BackgroundCandump (emulator/sim/background_candump.h): the lines come out exactly as the
// writer would have written them in the producer's order, also when the queue is far smaller
// than the stream (the producer waits for the thread) and when the thread sleeps between
// bursts; Stop() writes what is still queued; a frame the writer refuses is left out as before.
#include "emulator/sim/background_candump.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cstdint>
#include <random>
#include <sstream>
#include <string>
#include <thread>

namespace wheelhil::emulator::sim {
namespace {

bus::CanFrame FrameNo(int k) {
  const std::uint8_t b[3] = {static_cast<std::uint8_t>(k), static_cast<std::uint8_t>(k >> 8), 7};
  bus::CanFrame f = bus::CanFrame::Classic(static_cast<std::uint32_t>(k % 0x800), b);
  if (k % 97 == 0) f.len = 99;  // invalid: the writer refuses it, directly and through the queue
  return f;
}

TEST(BackgroundCandump, SameLinesInTheSameOrderAsTheWriterDirectly) {
  constexpr int kLines = 20'000;
  std::ostringstream direct_out;
  bus::CandumpWriter direct(direct_out);
  for (int k = 0; k < kLines; ++k) (void)direct.Write(1'000 * k, "ucan0", FrameNo(k));
  ASSERT_TRUE(direct.Flush());

  std::ostringstream queued_out;
  bus::CandumpWriter queued(queued_out);
  {
    BackgroundCandump bg(queued, "ucan0", nullptr, /*capacity=*/16);
    std::mt19937 rng(5);
    for (int k = 0; k < kLines; ++k) {
      bg.Write(1'000 * k, FrameNo(k));
      if (rng() % 2000 == 0) std::this_thread::sleep_for(std::chrono::milliseconds(3));
    }
    bg.Stop();
    bg.Stop();  // idempotent
  }
  ASSERT_TRUE(queued.Flush());
  EXPECT_EQ(queued_out.str(), direct_out.str());
  EXPECT_EQ(queued.lines_written(), direct.lines_written());
  EXPECT_LT(direct.lines_written(), static_cast<std::size_t>(kLines));  // the refused ones
}

TEST(BackgroundCandump, DestructionWritesWhatIsQueued) {
  std::ostringstream out;
  bus::CandumpWriter writer(out);
  {
    BackgroundCandump bg(writer, "can0", nullptr);
    bg.Write(5, FrameNo(1));
  }
  EXPECT_EQ(writer.lines_written(), 1u);
}

}  // namespace
}  // namespace wheelhil::emulator::sim
