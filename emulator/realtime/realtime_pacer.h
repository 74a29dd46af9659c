#pragma once
/// The real-time mode: frames with nominal instants (ns relative to a stream start) are sent at
/// those instants on CLOCK_MONOTONIC. The pacer sleeps with clock_nanosleep(CLOCK_MONOTONIC,
/// TIMER_ABSTIME) to each frame's absolute deadline (start + nominal, never an accumulated
/// relative sleep, so rounding never drifts), sends the frame, and hands a SendRecord to a
/// writer thread through a lock-free SPSC ring: no allocation, no locks and no logging I/O on
/// the send path. Frames come in through another SPSC ring from a producer thread (the device
/// models), which may run ahead by the ring's capacity.
///
/// With a spin margin the pacer waits in two steps (WaitUntilNs): clock_nanosleep to the
/// deadline minus the margin, then a spin on clock_gettime up to the deadline. On hosts whose
/// timer wakes late (a virtual machine's timer: tens to hundreds of µs) this takes the timer's
/// wake-up error out of the send instant as long as the error stays under the margin; it costs
/// the margin in CPU time per frame.
///
/// ApplyRealtimeSettings() asks for SCHED_FIFO, mlockall(MCL_CURRENT | MCL_FUTURE), a 1 ns
/// timer slack and CPU pinning for the calling thread; what the system refuses is reported in
/// notes (with the reason and how to allow it), never fatal.

#include <time.h>

#include <atomic>
#include <cstdint>
#include <string>
#include <system_error>
#include <vector>

#include "bus/can_frame.h"
#include "emulator/realtime/spsc_ring.h"

namespace wheelhil::emulator::realtime {

inline constexpr std::int64_t kNsPerS = 1'000'000'000;

/// ns -> timespec for non-negative instants (tv_nsec always in [0, 1e9)).
constexpr timespec NsToTimespec(std::int64_t t_ns) noexcept {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(t_ns / kNsPerS);
  ts.tv_nsec = static_cast<long>(t_ns % kNsPerS);
  if (ts.tv_nsec < 0) {
    ts.tv_nsec += kNsPerS;
    ts.tv_sec -= 1;
  }
  return ts;
}
constexpr std::int64_t TimespecToNs(const timespec& ts) noexcept {
  return static_cast<std::int64_t>(ts.tv_sec) * kNsPerS + static_cast<std::int64_t>(ts.tv_nsec);
}
/// k-th deadline of a periodic stream: start + k * period, computed from k (no accumulation).
constexpr std::int64_t PeriodicDeadlineNs(std::int64_t start_ns, std::int64_t period_ns,
                                          std::int64_t k) noexcept {
  return start_ns + k * period_ns;
}
/// Smallest k with PeriodicDeadlineNs(start, period, k) > now_ns (0 when now is before start):
/// where a periodic loop resumes after it overran, skipping the deadlines it missed.
/// period_ns must be > 0.
constexpr std::int64_t NextPeriodIndex(std::int64_t start_ns, std::int64_t period_ns,
                                       std::int64_t now_ns) noexcept {
  if (now_ns < start_ns) return 0;
  return (now_ns - start_ns) / period_ns + 1;
}

/// CLOCK_MONOTONIC now, ns.
std::int64_t MonotonicNowNs() noexcept;
/// Sleeps until the absolute CLOCK_MONOTONIC instant t_ns (returns at once when it has passed);
/// resumes after signals. Returns 0 or an errno value (EINVAL for a negative instant).
int SleepUntilNs(std::int64_t t_ns) noexcept;
/// Hybrid wait for the absolute CLOCK_MONOTONIC instant t_ns: SleepUntilNs(t_ns - spin_ns) when
/// that instant is still ahead, then spins on clock_gettime until t_ns. spin_ns <= 0 is a plain
/// SleepUntilNs(t_ns). Never returns before t_ns (also when t_ns is negative or the sleep
/// failed). Returns the CLOCK_MONOTONIC instant, ns, read when it returned (>= t_ns).
std::int64_t WaitUntilNs(std::int64_t t_ns, std::int64_t spin_ns) noexcept;

/// Wake-up error of the bare timer: `count` periodic absolute waits (WaitUntilNs with spin_ns)
/// of period_ns on the calling thread, each (return instant - deadline) in ns, >= 0. A
/// measurement for the bench (it allocates the result up front), not for the send path.
std::vector<std::int64_t> MeasureWakeErrorsNs(std::int64_t period_ns, int count,
                                              std::int64_t spin_ns);
struct RealtimeOptions {
  bool sched_fifo = true;   ///< Ask for SCHED_FIFO at fifo_priority.
  int fifo_priority = 80;   ///< 1..99.
  bool lock_memory = true;  ///< mlockall(MCL_CURRENT | MCL_FUTURE) for the whole process.
  int cpu = -1;             ///< Pin the calling thread to this CPU; -1 = no pinning.
  /// prctl(PR_SET_TIMERSLACK) for the calling thread, ns (a SCHED_OTHER thread's default is
  /// 50 µs, added to every sleep; SCHED_FIFO threads get none). 0 = leave it (the kernel would
  /// read 0 as "back to the default"), so the smallest request is 1.
  long timer_slack_ns = 1;
};

/// What was granted; notes say what was refused, why, and how to allow it.
struct RealtimeStatus {
  bool sched_fifo = false;
  bool memory_locked = false;
  int pinned_cpu = -1;
  long timer_slack_ns = -1;  ///< The calling thread's slack afterwards (PR_GET_TIMERSLACK).
  std::vector<std::string> notes;
};

/// Applies `options` to the calling thread (and mlockall to the process). Call once before the
/// paced loop, not on the send path. Never throws for refusals (they end up in notes).
RealtimeStatus ApplyRealtimeSettings(const RealtimeOptions& options);

/// A frame and its nominal send instant, ns after the stream start.
struct PacedFrame {
  bus::CanFrame frame;
  std::int64_t nominal_ns = 0;
};

/// What happened to one frame: nominal and actual send instants (ns after the stream start;
/// sent_ns is read right after the send returned) and the send's errno (0 = sent).
struct SendRecord {
  std::int64_t nominal_ns = 0;
  std::int64_t woke_ns = 0;  ///< When the pacer woke for this frame (before the send).
  std::int64_t sent_ns = 0;
  std::uint32_t id = 0;
  std::int32_t error = 0;
};

/// Where the pacer puts frames (a SocketCAN transport, a test double). Send must not allocate
/// or block for long; it is called on the real-time thread.
class FrameSink {
 public:
  virtual ~FrameSink() = default;
  [[nodiscard]] virtual std::error_code Send(const bus::CanFrame& frame) noexcept = 0;
};

struct PacerStats {
  std::uint64_t sent = 0;             ///< Frames the sink accepted.
  std::uint64_t send_errors = 0;      ///< Frames the sink refused (recorded with their errno).
  std::uint64_t underruns = 0;        ///< Times the input ring was empty while the producer ran.
  std::uint64_t records_dropped = 0;  ///< SendRecords lost because the writer fell behind.
};

/// Sends the frames of `input` at start_ns + nominal_ns. Thread-compatible: Run() on one thread
/// (the consumer of `input` and the producer of `records`).
class FramePacer {
 public:
  /// spin_ns: margin of the hybrid wait (WaitUntilNs); 0 = clock_nanosleep only. The pacer's
  /// thread is busy for up to spin_ns per frame: keep frames/s * (spin + send time) well under
  /// the CPU, or a SCHED_FIFO pacer runs into the kernel's RT throttling
  /// (sched_rt_runtime_us, typically 50 ms stalled per second).
  FramePacer(SpscRing<PacedFrame>& input, SpscRing<SendRecord>& records, FrameSink& sink,
             std::int64_t spin_ns = 0) noexcept
      : input_(input), records_(records), sink_(sink), spin_ns_(spin_ns) {}

  /// Paces until `input` is empty after producer_done was set, or until stop is set. Each frame
  /// waits with WaitUntilNs(start_ns + nominal_ns, spin_ns), so it never leaves before its
  /// deadline. Frames whose deadline has passed are sent at once (and show up late in their
  /// records). An empty
  /// input while the producer runs is an underrun: the pacer sleeps underrun_wait_ns and looks
  /// again. No allocation, no locks, no I/O other than sink.Send.
  PacerStats Run(std::int64_t start_ns, const std::atomic<bool>& producer_done,
                 const std::atomic<bool>& stop, std::int64_t underrun_wait_ns = 50'000) noexcept;

 private:
  SpscRing<PacedFrame>& input_;
  SpscRing<SendRecord>& records_;
  FrameSink& sink_;
  std::int64_t spin_ns_ = 0;
};

}  // namespace wheelhil::emulator::realtime
