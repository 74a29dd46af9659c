#pragma once
/// What every stage of a run shares: the virtual clock (integer ns since the run start), the
/// instant the motion phase started, the run's event log (events.jsonl, in the order things
/// happened; sorted by time, stably, when the run is scored) and the reason the run failed.
/// A stage that meets a run-time failure records it with Fail and returns; the loop stops at
/// the end of the current stage. An interrupting signal counts as a failure (see below).
/// Thread-compatible.

#include <signal.h>

#include <atomic>
#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "emulator/sim/signal_name.h"

namespace wheelhil::emulator::sim {

/// The signal that asked the run to stop (SIGINT, SIGTERM, SIGHUP; InstallInterruptHandlers),
/// 0 when none did. Async-signal-safe to set; every stage sees the run as failed from then on,
/// so it ends as a failure would: firmware stopped, artefacts written.
inline std::atomic<int> g_interrupt_signal{0};
inline int InterruptSignal() { return g_interrupt_signal.load(std::memory_order_relaxed); }
/// Routes SIGINT, SIGTERM and SIGHUP to g_interrupt_signal, once: a second one has its default
/// effect (a second Ctrl-C kills at once).
inline void InstallInterruptHandlers() {
  struct sigaction sa {};
  sa.sa_handler = [](int sig) { g_interrupt_signal.store(sig, std::memory_order_relaxed); };
  sa.sa_flags = SA_RESTART | SA_RESETHAND;
  sigemptyset(&sa.sa_mask);
  for (int sig : {SIGINT, SIGTERM, SIGHUP}) (void)::sigaction(sig, &sa, nullptr);
}

struct RunContext {
  std::int64_t now_ns = 0;  ///< Virtual time of the latest completed step.
  double motion0_s = 0;     ///< Motion start (s since the run start); 0 before it.
  std::int64_t motion0_ns = 0;
  std::vector<nlohmann::json> events;
  std::string failure;  ///< Empty while the run goes on.

  bool failed() const { return !failure.empty() || InterruptSignal() != 0; }
  /// The first failure wins: it is the cause, later ones are consequences.
  void Fail(std::string why) {
    TakeInterrupt();
    if (failure.empty()) failure = std::move(why);
  }
  /// A pending interruption becomes the failure ("interrupted by signal 2 (SIGINT)").
  void TakeInterrupt() {
    if (const int sig = InterruptSignal(); sig != 0 && failure.empty()) {
      failure = "interrupted by " + SignalName(sig);
    }
  }
  /// Seconds since the motion start of t_ns (since the run start before the motion).
  double MotionSeconds(std::int64_t t_ns) const {
    return static_cast<double>(t_ns) * 1e-9 - motion0_s;
  }
};

}  // namespace wheelhil::emulator::sim
