#pragma once
/// Writes candump lines through a bus::CandumpWriter on a thread of its own, so that a lockstep
/// run's thread only copies each frame into a queue and the formatting happens on another CPU
/// (the physics worker's, which a paper-002 run leaves mostly idle).
///
/// Contract: one producer thread calls Write(); lines reach the writer in the order Write() was
/// called, exactly as `writer.Write(timestamp_ns, interface, frame)` would have written them
/// (the writer's own checks and return value, which is dropped, included). Nobody else may use
/// the writer from construction until Stop() (or the destructor) returned; Stop() writes what
/// is still queued first. Write() never blocks on I/O; it waits only while the queue is full.
/// The thread sleeps between drains (0.5 to 2 ms), so it costs its CPU next to nothing.

#include <pthread.h>
#include <sched.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <string>
#include <thread>
#include <vector>

#include "bus/can_frame.h"
#include "bus/candump_log.h"

namespace wheelhil::emulator::sim {

class BackgroundCandump {
 public:
  /// `capacity` is rounded up to a power of two; `cpus` (may be null): where the thread runs.
  BackgroundCandump(bus::CandumpWriter& writer, std::string interface, const cpu_set_t* cpus,
                    std::size_t capacity = 8192)
      : writer_(writer), interface_(std::move(interface)) {
    std::size_t n = 4;
    while (n < capacity) n *= 2;
    ring_.resize(n);
    mask_ = n - 1;
    thread_ = std::thread([this] { Drain(); });
    if (cpus != nullptr) {
      (void)::pthread_setaffinity_np(thread_.native_handle(), sizeof(cpu_set_t), cpus);
    }
  }
  ~BackgroundCandump() { Stop(); }
  BackgroundCandump(const BackgroundCandump&) = delete;
  BackgroundCandump& operator=(const BackgroundCandump&) = delete;

  void Write(std::int64_t timestamp_ns, const bus::CanFrame& frame) {
    const std::uint64_t t = tail_.load(std::memory_order_relaxed);
    while (t - head_seen_ > mask_) {  // full: wait for the thread (it drains in bursts)
      head_seen_ = head_.load(std::memory_order_acquire);
      if (t - head_seen_ > mask_) std::this_thread::yield();
    }
    ring_[t & mask_] = Entry{timestamp_ns, frame};
    tail_.store(t + 1, std::memory_order_release);
  }

  /// Writes what is queued, then ends the thread. Idempotent.
  void Stop() {
    if (!thread_.joinable()) return;
    stop_.store(true, std::memory_order_release);
    thread_.join();
  }

 private:
  struct Entry {
    std::int64_t timestamp_ns = 0;
    bus::CanFrame frame;
  };

  void Drain() {
    auto sleep = std::chrono::microseconds(500);
    for (;;) {
      // stop_ is read before tail_: every push before Stop() is then seen below.
      const bool stopping = stop_.load(std::memory_order_acquire);
      const std::uint64_t t = tail_.load(std::memory_order_acquire);
      std::uint64_t h = head_.load(std::memory_order_relaxed);
      if (h == t) {
        if (stopping) return;
        std::this_thread::sleep_for(sleep);
        sleep = std::min(sleep * 2, std::chrono::microseconds(2000));
        continue;
      }
      sleep = std::chrono::microseconds(500);
      for (; h != t; ++h) {
        const Entry& e = ring_[h & mask_];
        (void)writer_.Write(e.timestamp_ns, interface_, e.frame);
        if ((h & 63) == 63) head_.store(h + 1, std::memory_order_release);  // room, in bursts
      }
      head_.store(h, std::memory_order_release);
    }
  }

  bus::CandumpWriter& writer_;
  const std::string interface_;
  std::vector<Entry> ring_;
  std::uint64_t mask_ = 0;
  alignas(64) std::atomic<std::uint64_t> head_{0};  ///< Next entry the thread writes.
  alignas(64) std::atomic<std::uint64_t> tail_{0};  ///< Next free entry (producer).
  std::uint64_t head_seen_ = 0;                     ///< Producer's last look at head_.
  alignas(64) std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace wheelhil::emulator::sim
