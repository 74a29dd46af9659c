// StepPipeline (emulator/sim/step_pipeline.h): every step reaches the consumer once, in
// order, with the producer's data, whatever the timing of the two sides (random pauses on
// both, a ring far smaller than the run, sleeps long enough that both sides block); a
// throwing step function ends the stream with its message; destruction in the middle of a
// run stops the worker even while it sleeps on a full ring; with fall-back on, a worker that
// makes the consumer wait longer than its steps cost (its CPU elsewhere: it sleeps) is stopped
// and the consumer computes the rest, still every step once in order, and a worker that keeps
// ahead is not.
#include "emulator/sim/step_pipeline.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <random>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace wheelhil::emulator::sim {
namespace {

struct Slot {
  std::int64_t step = -1;
  std::vector<std::int64_t> payload;  // resized per step: the slot is reused
};

void Fill(std::int64_t step, Slot& out) {
  out.step = step;
  out.payload.assign(static_cast<std::size_t>(step % 7 + 1), step * 3 + 1);
}

void Pause(std::mt19937& rng) {
  const int r = static_cast<int>(rng() % 1000);
  if (r < 5) {
    std::this_thread::sleep_for(std::chrono::microseconds(200 + rng() % 800));  // both block
  } else if (r < 100) {
    for (int i = 0; i < static_cast<int>(rng() % 2000); ++i) _mm_pause();
  }
}

TEST(StepPipeline, EveryStepOnceInOrderUnderRandomTiming) {
  for (const std::size_t capacity : {4u, 16u, 256u}) {
    constexpr std::int64_t kSteps = 20000;
    std::mt19937 producer_rng(7), consumer_rng(11);
    StepPipeline<Slot> p(
        capacity, kSteps,
        [&](std::int64_t step, Slot& out) {
          Pause(producer_rng);
          Fill(step, out);
        },
        nullptr);
    for (std::int64_t k = 0; k < kSteps; ++k) {
      const Slot& s = p.Next();
      ASSERT_EQ(s.step, k) << "capacity " << capacity;
      ASSERT_EQ(s.payload.size(), static_cast<std::size_t>(k % 7 + 1));
      ASSERT_EQ(s.payload.back(), k * 3 + 1);
      Pause(consumer_rng);
      // The slot handed out is not rewritten before the next call, however far ahead the
      // producer is.
      ASSERT_EQ(s.step, k);
    }
    EXPECT_THROW(p.Next(), std::runtime_error);  // no step left
  }
}

TEST(StepPipeline, AWorkerThatMakesTheConsumerWaitIsTakenOverInOrder) {
  constexpr std::int64_t kSteps = 5000;
  std::atomic<std::int64_t> on_worker{0};
  const std::thread::id consumer = std::this_thread::get_id();
  StepPipeline<Slot> p(
      64, kSteps,
      [&](std::int64_t step, Slot& out) {
        if (std::this_thread::get_id() != consumer) {
          ++on_worker;
          // Its CPU taken by another job: the step costs little CPU but much wall time.
          std::this_thread::sleep_for(std::chrono::microseconds(50));
        }
        Fill(step, out);
      },
      nullptr, true);
  for (std::int64_t k = 0; k < kSteps; ++k) {
    const Slot& s = p.Next();
    ASSERT_EQ(s.step, k);
    ASSERT_EQ(s.payload.back(), k * 3 + 1);
  }
  ASSERT_GE(p.inline_from_step(), 3 * 1024) << "two windows lost after the first";
  EXPECT_LT(p.inline_from_step(), kSteps);
  EXPECT_EQ(on_worker.load(), p.inline_from_step());
  EXPECT_GT(p.wait_s(), 0.0);
}

TEST(StepPipeline, AWorkerThatKeepsAheadIsKept) {
  constexpr std::int64_t kSteps = 5000;
  std::atomic<std::int64_t> made{0};
  StepPipeline<Slot> p(
      8192, kSteps,
      [&](std::int64_t step, Slot& out) {
        for (int i = 0; i < 200; ++i) _mm_pause();  // CPU work, no sleep
        Fill(step, out);
        ++made;
      },
      nullptr, true);
  // Every step is made before the consumer asks for one: it never waits.
  while (made.load() < kSteps) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  for (std::int64_t k = 0; k < kSteps; ++k) ASSERT_EQ(p.Next().step, k);
  EXPECT_EQ(p.wait_s(), 0.0);
  EXPECT_EQ(p.inline_from_step(), -1);
}

TEST(StepPipeline, AThrowingStepEndsTheStreamWithItsMessage) {
  StepPipeline<Slot> p(
      8, 100,
      [](std::int64_t step, Slot& out) {
        if (step == 40) throw std::runtime_error("wheel 2 left the world");
        Fill(step, out);
      },
      nullptr);
  for (std::int64_t k = 0; k < 40; ++k) ASSERT_EQ(p.Next().step, k);
  try {
    p.Next();
    ADD_FAILURE() << "step 40 threw, but Next() returned";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("wheel 2 left the world"), std::string::npos) << e.what();
  }
}

TEST(StepPipeline, DestructionStopsAWorkerAsleepOnAFullRing) {
  std::atomic<std::int64_t> produced{0};
  {
    StepPipeline<Slot> p(
        4, 1'000'000,
        [&](std::int64_t step, Slot& out) {
          Fill(step, out);
          produced.store(step + 1);
        },
        nullptr);
    EXPECT_EQ(p.Next().step, 0);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));  // the worker fills and sleeps
  }
  // Ring of 4 with slot 0 held: at most 4 steps were computed, not the million.
  EXPECT_LE(produced.load(), 5);
}

}  // namespace
}  // namespace wheelhil::emulator::sim
