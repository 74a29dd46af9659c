#include "emulator/sim/event_loop.h"

#include <algorithm>

#include "emulator/realtime/realtime_pacer.h"

namespace wheelhil::emulator::sim {

void RealtimeWait::StartPhase(std::int64_t t_ns) {
  anchor_t_ns_ = t_ns;
  anchor_wall_ns_ = realtime::MonotonicNowNs();
}

void RealtimeWait::WaitFor(std::int64_t t_ns) {
  (void)realtime::SleepUntilNs(anchor_wall_ns_ + (t_ns - anchor_t_ns_));
}

std::uint64_t EventLoop::Run(const Phase& phase) {
  std::uint64_t instants = 0;
  wait_.StartPhase(run_.now_ns);
  while (!(phase.done && phase.done())) {
    std::int64_t t = kNever;
    for (const EventSource* s : phase.sources) t = std::min(t, s->NextEventNs());
    if (t == kNever) break;
    wait_.WaitFor(t);
    ++instants;
    for (EventSource* s : phase.sources) {
      if (s->NextEventNs() != t) continue;
      if (run_.failed() && s->StopsOnFailure()) return instants;
      s->Fire(t);
    }
  }
  return instants;
}

}  // namespace wheelhil::emulator::sim
