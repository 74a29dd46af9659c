#pragma once
// StepPipeline: a producer thread that computes a fixed number of steps ahead of the thread
// that consumes them, through a ring of reusable slots.
//
// Why: in a lockstep run the physics of the motion phase depends on time only (motion profile,
// physical faults), not on the bus or the firmware, while the run's own thread spends its time
// on the bus model, the devices and the firmware. Stepping the world on a second CPU overlaps
// the two; the results are the same bits, since the same steps run in the same order.
//
// Contract: one consumer thread calls Next(); the step function runs on the worker thread
// only, with steps 0, 1, ..., steps-1 in order, and must not share mutable state with the
// consumer. A slot returned by Next() stays valid (not rewritten) until the following Next()
// or the destruction. Destruction stops the worker after its current step and joins it.
//
// Waiting: a hand-over between CPUs that sleeps costs tens of microseconds on a virtual
// machine, so each side spins (bounded) before it blocks on a futex (std::atomic::wait), and a
// side wakes the other only when that one announced it sleeps. Lost wakeups are excluded by a
// store-then-load on each side in one total order (seq_cst): a sleeper stores its `waiting`
// flag, then re-reads the index it waits for; the other side stores that index, then reads the
// flag. One of the two sees the other's store, so either the sleeper does not sleep or it is
// woken (its wait is on a sequence word it read before announcing itself, and the waker bumps
// it). The producer, once asleep on a full ring, is woken when half the ring is free, so a
// consumer that drains fast does not pay a wake-up per step.
//
// Falling back (the constructor's `fall_back`): a worker whose CPU is taken by another job makes
// the consumer wait longer than the steps would take it to compute. Every kJudgeSteps steps the
// consumer compares its wait with the worker's CPU time for those steps; when the wait was
// longer by half in two windows in a row (the first window, while the worker builds its lead,
// not counted), the worker is stopped between two steps and the consumer computes the rest
// itself, in the same order (the same bits).
#include <immintrin.h>
#include <pthread.h>
#include <sched.h>
#include <time.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

namespace wheelhil::emulator::sim {

template <typename Slot>
class StepPipeline {
 public:
  /// Fills `out` with the result of step `step` (0-based). May throw: Next() then rethrows the
  /// message as std::runtime_error.
  using StepFn = std::function<void(std::int64_t step, Slot& out)>;

  /// Starts the worker. `capacity` is rounded up to a power of two (>= 4). `cpus`: the worker's
  /// CPU set (nullptr: inherited). `fall_back`: the consumer may take the steps back (above).
  StepPipeline(std::size_t capacity, std::int64_t steps, StepFn fn, const cpu_set_t* cpus,
               bool fall_back = false)
      : steps_(steps), fn_(std::move(fn)), fall_back_(fall_back) {
    std::size_t cap = 4;
    while (cap < capacity) cap *= 2;
    slots_.resize(cap);
    mask_ = cap - 1;
    worker_ = std::thread([this] { Produce(); });
    if (cpus != nullptr) {
      (void)::pthread_setaffinity_np(worker_.native_handle(), sizeof(cpu_set_t), cpus);
    }
  }

  ~StepPipeline() {
    stop_.store(true);
    space_seq_.fetch_add(1);
    space_seq_.notify_one();
    if (worker_.joinable()) worker_.join();
  }

  StepPipeline(const StepPipeline&) = delete;
  StepPipeline& operator=(const StepPipeline&) = delete;

  /// The step from which the consumer computed the steps itself, or -1.
  std::int64_t inline_from_step() const { return inline_from_; }
  /// Seconds the consumer waited for the worker.
  double wait_s() const { return static_cast<double>(wait_ns_total_) * 1e-9; }

  /// The next step's slot. Throws std::runtime_error when the step function threw or every
  /// step was already consumed.
  const Slot& Next() {
    if (next_ > 0) Release(next_);
    if (fall_back_ && inline_from_ < 0 && next_ > 0 && next_ % kJudgeSteps == 0) Judge();
    if (inline_from_ >= 0 && head_.load() <= next_) return ComputeInline();
    if (head_.load(std::memory_order_acquire) > next_) return slots_[next_++ & mask_];
    const auto wait_start = std::chrono::steady_clock::now();
    if (!WaitForSlot(next_)) {
      throw std::runtime_error(error_.empty() ? "physics: no step left to consume"
                                              : "physics worker: " + error_);
    }
    const std::int64_t waited = std::chrono::duration_cast<std::chrono::nanoseconds>(
                                    std::chrono::steady_clock::now() - wait_start)
                                    .count();
    wait_ns_window_ += waited;
    wait_ns_total_ += waited;
    return slots_[next_++ & mask_];
  }

  /// The slot `ahead` steps after the one the last Next() returned (ahead >= 1; the first
  /// step's for ahead 1 before any Next()), without consuming it: it stays valid until the
  /// Next() that passes it. Waits for the worker (or computes it on the consumer's thread once
  /// it fell back). nullptr when it lies beyond the last step, beyond half the ring, or the
  /// step function failed (Next() reports that).
  const Slot* Peek(std::int64_t ahead) {
    if (ahead < 1 || static_cast<std::size_t>(ahead) >= slots_.size() / 2) return nullptr;
    const std::uint64_t index = next_ + static_cast<std::uint64_t>(ahead) - 1;
    if (index >= static_cast<std::uint64_t>(steps_)) return nullptr;
    if (inline_from_ >= 0) {
      try {
        ProduceInline(index);
      } catch (const std::exception&) {
        return nullptr;
      }
      return &slots_[index & mask_];
    }
    return WaitForSlot(index) ? &slots_[index & mask_] : nullptr;
  }

 private:
  static constexpr std::int64_t kJudgeSteps = 1024;

  // The consumer waits (spins, then sleeps) until the worker filled slot `index`; false when
  // the worker is done without it.
  bool WaitForSlot(std::uint64_t index) {
    for (int spin = 0; head_.load(std::memory_order_acquire) <= index; ++spin) {
      if (done_.load(std::memory_order_acquire) && head_.load() <= index) return false;
      if (spin < kConsumerSpins) {
        _mm_pause();
        continue;
      }
      const std::uint32_t seq = data_seq_.load();
      consumer_waiting_.store(true);
      if (head_.load() > index || done_.load()) {
        consumer_waiting_.store(false);
        continue;
      }
      data_seq_.wait(seq);
      consumer_waiting_.store(false);
    }
    return true;
  }

  static std::int64_t ThreadCpuNs() {
    timespec ts{};
    ::clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return std::int64_t{ts.tv_sec} * 1000000000 + ts.tv_nsec;
  }

  // Every kJudgeSteps consumed steps: the wait against what the worker's CPU spent on them.
  void Judge() {
    const std::int64_t cpu_ns = worker_cpu_ns_.load();
    const std::int64_t cpu_steps = worker_cpu_steps_.load();
    const std::int64_t waited = std::exchange(wait_ns_window_, 0);
    if (cpu_steps <= 0 || next_ <= static_cast<std::uint64_t>(kJudgeSteps)) return;
    const double cpu_per_step = static_cast<double>(cpu_ns) / static_cast<double>(cpu_steps);
    losing_windows_ =
        static_cast<double>(waited) > 1.5 * cpu_per_step * kJudgeSteps ? losing_windows_ + 1 : 0;
    if (losing_windows_ >= 2) StopWorker();
  }

  // Stops the worker between two steps; the consumer computes from the first it did not make.
  void StopWorker() {
    stop_.store(true);
    space_seq_.fetch_add(1);
    space_seq_.notify_one();
    if (worker_.joinable()) worker_.join();
    if (!error_.empty()) return;  // Next() reports it
    inline_from_ = static_cast<std::int64_t>(head_.load());
    done_.store(false);
  }

  const Slot& ComputeInline() {
    if (next_ >= static_cast<std::uint64_t>(steps_)) {
      throw std::runtime_error("physics: no step left to consume");
    }
    ProduceInline(next_);
    return slots_[next_++ & mask_];
  }

  // The consumer's thread computes every step up to `index` not yet made.
  void ProduceInline(std::uint64_t index) {
    for (std::uint64_t h = head_.load(); h <= index; ++h) {
      try {
        fn_(static_cast<std::int64_t>(h), slots_[h & mask_]);
      } catch (const std::exception& e) {
        throw std::runtime_error(std::string("physics: ") + e.what());
      }
      head_.store(h + 1);
    }
  }

  // Spin rounds (pause instruction, ~10-50 ns each here) before a side blocks.
  static constexpr int kConsumerSpins = 4000;
  static constexpr int kProducerSpins = 400;

  // The consumer is done with every slot before `upto`.
  void Release(std::uint64_t upto) {
    tail_.store(upto);
    const std::uint64_t free_slots = slots_.size() - (head_.load() - upto);
    if (free_slots >= slots_.size() / 2 && producer_waiting_.load() &&
        producer_waiting_.exchange(false)) {
      space_seq_.fetch_add(1);
      space_seq_.notify_one();
    }
  }

  void Produce() {
    const std::int64_t cpu_at_start = fall_back_ ? ThreadCpuNs() : 0;
    try {
      for (std::int64_t step = 0; step < steps_; ++step) {
        const std::uint64_t head = head_.load(std::memory_order_relaxed);
        // The consumer holds slot next_-1 until its next call: tail_ counts released slots.
        for (int spin = 0; head - tail_.load(std::memory_order_acquire) >= slots_.size(); ++spin) {
          if (stop_.load()) return Finish();
          if (spin < kProducerSpins) {
            _mm_pause();
            continue;
          }
          const std::uint32_t seq = space_seq_.load();
          producer_waiting_.store(true);
          if (slots_.size() - (head - tail_.load()) >= slots_.size() / 2 || stop_.load()) {
            producer_waiting_.store(false);
            continue;
          }
          space_seq_.wait(seq);
          producer_waiting_.store(false);
        }
        if (stop_.load()) return Finish();
        fn_(step, slots_[head & mask_]);
        head_.store(head + 1);
        if ((step + 1) % 64 == 0 && fall_back_) {
          worker_cpu_ns_.store(ThreadCpuNs() - cpu_at_start);
          worker_cpu_steps_.store(step + 1);
        }
        WakeConsumer();
      }
    } catch (const std::exception& e) {
      error_ = e.what();
    } catch (...) {
      error_ = "unknown exception";
    }
    Finish();
  }

  void Finish() {
    done_.store(true);
    data_seq_.fetch_add(1);
    data_seq_.notify_one();
  }

  void WakeConsumer() {
    if (consumer_waiting_.load() && consumer_waiting_.exchange(false)) {
      data_seq_.fetch_add(1);
      data_seq_.notify_one();
    }
  }

  const std::int64_t steps_;
  StepFn fn_;
  const bool fall_back_;
  std::vector<Slot> slots_;
  std::size_t mask_ = 0;
  // Each side's hot words on their own cache line: the spinning side reads the other's line
  // only, and a write does not invalidate what the writer's peer keeps reading.
  alignas(64) std::atomic<std::uint64_t> head_{0};  // slots filled (producer)
  std::atomic<std::uint32_t> data_seq_{0};
  std::atomic<bool> done_{false};
  alignas(64) std::atomic<std::uint64_t> tail_{0};  // slots released (consumer)
  std::uint64_t next_ = 0;                          // consumer: next slot to hand out
  std::atomic<std::uint32_t> space_seq_{0};
  alignas(64) std::atomic<bool> consumer_waiting_{false};
  alignas(64) std::atomic<bool> producer_waiting_{false};
  std::atomic<bool> stop_{false};
  std::string error_;  // written before done_ (release), read after it (acquire)
  // Falling back: the consumer's side, then the worker's CPU time for its first steps.
  std::int64_t inline_from_ = -1;
  int losing_windows_ = 0;
  std::int64_t wait_ns_window_ = 0;
  std::int64_t wait_ns_total_ = 0;
  alignas(64) std::atomic<std::int64_t> worker_cpu_ns_{0};
  std::atomic<std::int64_t> worker_cpu_steps_{0};
  std::thread worker_;
};

}  // namespace wheelhil::emulator::sim
