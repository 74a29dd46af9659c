#include "emulator/realtime/realtime_pacer.h"

#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <sys/prctl.h>

#include <cerrno>
#include <cstring>

#include <fmt/format.h>

namespace wheelhil::emulator::realtime {

std::int64_t MonotonicNowNs() noexcept {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return TimespecToNs(ts);
}

int SleepUntilNs(std::int64_t t_ns) noexcept {
  if (t_ns < 0) return EINVAL;
  const timespec ts = NsToTimespec(t_ns);
  int rc;
  do {
    rc = ::clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
  } while (rc == EINTR);
  return rc;
}

namespace {
inline void CpuRelax() noexcept {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#elif defined(__aarch64__)
  asm volatile("yield");
#endif
}
}  // namespace

std::int64_t WaitUntilNs(std::int64_t t_ns, std::int64_t spin_ns) noexcept {
  if (spin_ns <= 0) {
    SleepUntilNs(t_ns);
  } else if (const std::int64_t wake_ns = t_ns - spin_ns; wake_ns > MonotonicNowNs()) {
    SleepUntilNs(wake_ns);
  }
  // Also after a plain sleep: a failed or interrupted sleep must not let the frame go early.
  std::int64_t now = MonotonicNowNs();
  while (now < t_ns) {
    CpuRelax();
    now = MonotonicNowNs();
  }
  return now;
}

std::vector<std::int64_t> MeasureWakeErrorsNs(std::int64_t period_ns, int count,
                                              std::int64_t spin_ns) {
  std::vector<std::int64_t> errors;
  if (count <= 0 || period_ns <= 0) return errors;
  errors.reserve(static_cast<std::size_t>(count));
  const std::int64_t start_ns = MonotonicNowNs() + period_ns;
  for (int k = 0; k < count; ++k) {
    const std::int64_t deadline_ns = PeriodicDeadlineNs(start_ns, period_ns, k);
    errors.push_back(WaitUntilNs(deadline_ns, spin_ns) - deadline_ns);
  }
  return errors;
}

RealtimeStatus ApplyRealtimeSettings(const RealtimeOptions& options) {
  RealtimeStatus status;
  if (options.lock_memory) {
    if (::mlockall(MCL_CURRENT | MCL_FUTURE) == 0) {
      status.memory_locked = true;
    } else {
      const int e = errno;
      status.notes.push_back(
          fmt::format("mlockall refused ({}): pages may fault on the send path; raise `ulimit -l` "
                      "(RLIMIT_MEMLOCK) or grant CAP_IPC_LOCK",
                      std::strerror(e)));
    }
  }
  if (options.sched_fifo) {
    sched_param param{};
    param.sched_priority = options.fifo_priority;
    const int rc = ::pthread_setschedparam(::pthread_self(), SCHED_FIFO, &param);
    if (rc == 0) {
      status.sched_fifo = true;
    } else {
      status.notes.push_back(fmt::format(
          "SCHED_FIFO priority {} refused ({}): running under the normal scheduler; allow it "
          "with `ulimit -r {}` (RLIMIT_RTPRIO), CAP_SYS_NICE, or a container/cgroup with "
          "real-time runtime (cpu.rt_runtime_us)",
          options.fifo_priority, std::strerror(rc), options.fifo_priority));
    }
  }
  if (options.timer_slack_ns > 0 &&
      ::prctl(PR_SET_TIMERSLACK, static_cast<unsigned long>(options.timer_slack_ns), 0, 0, 0) !=
          0) {
    const int e = errno;
    status.notes.push_back(fmt::format("timer slack {} ns refused ({}): sleeps may end late",
                                       options.timer_slack_ns, std::strerror(e)));
  }
  if (const int slack = ::prctl(PR_GET_TIMERSLACK, 0, 0, 0, 0); slack >= 0) {
    status.timer_slack_ns = slack;
  }
  if (options.cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    if (options.cpu >= CPU_SETSIZE) {
      status.notes.push_back(fmt::format("CPU {} does not exist: not pinned", options.cpu));
    } else {
      CPU_SET(options.cpu, &set);
      const int rc = ::pthread_setaffinity_np(::pthread_self(), sizeof(set), &set);
      if (rc == 0) {
        status.pinned_cpu = options.cpu;
      } else {
        status.notes.push_back(fmt::format("pinning to CPU {} refused ({}): not pinned",
                                           options.cpu, std::strerror(rc)));
      }
    }
  }
  return status;
}

PacerStats FramePacer::Run(std::int64_t start_ns, const std::atomic<bool>& producer_done,
                           const std::atomic<bool>& stop, std::int64_t underrun_wait_ns) noexcept {
  PacerStats stats;
  PacedFrame next;
  while (!stop.load(std::memory_order_relaxed)) {
    if (!input_.TryPop(next)) {
      // Read `done` before looking again: a frame pushed before done was set is then seen.
      if (producer_done.load(std::memory_order_acquire)) {
        if (!input_.TryPop(next)) break;
      } else {
        ++stats.underruns;
        SleepUntilNs(MonotonicNowNs() + underrun_wait_ns);
        continue;
      }
    }
    const std::int64_t woke_ns = WaitUntilNs(start_ns + next.nominal_ns, spin_ns_) - start_ns;
    const std::error_code ec = sink_.Send(next.frame);
    const std::int64_t sent_ns = MonotonicNowNs() - start_ns;
    if (ec) {
      ++stats.send_errors;
    } else {
      ++stats.sent;
    }
    SendRecord record;
    record.nominal_ns = next.nominal_ns;
    record.woke_ns = woke_ns;
    record.sent_ns = sent_ns;
    record.id = next.frame.id;
    record.error = ec ? ec.value() : 0;
    if (!records_.TryPush(record)) ++stats.records_dropped;
  }
  return stats;
}

}  // namespace wheelhil::emulator::realtime
