#include "emulator/sim/cycle_scheduler.h"

#include <algorithm>
#include <utility>

namespace wheelhil::emulator::sim {

void StepSource::Start(const Options& options) {
  o_ = options;
  fired_ = 0;
  next_ns_ = run_.now_ns + stages_.step_ns();
  physics_failed_ = false;
}

void StepSource::OpenCycle(int cycle, std::int64_t k) {
  cycle_ = cycle;
  cycle_k_ = k;
  first_of_cycle_ = true;
}

void StepSource::Fire(std::int64_t t_ns) {
  ++fired_;
  next_ns_ = t_ns + stages_.step_ns();
  if (!stages_.StepPhysics(t_ns, o_.motion)) {
    physics_failed_ = true;
  } else {
    run_.now_ns = t_ns;
    stages_.StepDevices(t_ns, o_.motion);
  }
  const std::int64_t now = run_.now_ns;
  if (o_.record_truth) stages_.RecordTruth(now, false);
  stages_.AdvanceBus(now);
  if (!gate_.lockstep()) {
    gate_.Drain();
  } else if (o_.wait_boot_answers) {
    gate_.WaitBootAnswers();
  } else if (first_of_cycle_) {
    // The firmware's answer is fixed by the frames it was given once the cycle's last sync
    // answer is on the wire; if one is missing, the next SYNC closes the cycle.
    first_of_cycle_ = false;
    if (gate_.CycleCompleteOnBus()) {
      gate_.WaitStatus(cycle_, cycle_k_);
    } else {
      pending_status_cycle = cycle_;
    }
  }
  if (o_.motion) stages_.AfterMotionStep();
}

void SyncSource::AdvanceBusUntil(const std::function<bool()>& done) {
  const std::int64_t half_step = stages_.step_ns() / 2;
  for (const std::int64_t until = run_.now_ns + period_ns_;
       !done() && stages_.bus_now_ns() < until;) {
    stages_.AdvanceBus(std::min(until, stages_.bus_now_ns() + half_step));
  }
}

void SyncSource::Fire(std::int64_t t_ns) {
  const std::int64_t k = k_++;
  stages_.RecordTruth(t_ns, true);
  const int cycle = stages_.SendSync(t_ns);
  // The SYNC and the frames answering it (the readings at this instant) go out before the
  // physics moves on.
  stages_.AdvanceBus(t_ns + stages_.step_ns() / 2);
  if (gate_.lockstep() && steps_.pending_status_cycle >= 0) {
    // The previous cycle was incomplete on the bus: this SYNC closes it once it is on the wire
    // (an error burst or a flood can hold it back beyond half a step).
    AdvanceBusUntil([&] { return gate_.LatestSyncOnWire(); });
    gate_.WaitStatus(std::exchange(steps_.pending_status_cycle, -1), k - 1);
  }
  if (k < cycles_) {
    steps_.OpenCycle(cycle, k);
    return;
  }
  steps_.Stop();
  if (run_.failed()) return;
  // The last cycle: no physics step follows, so the bus finishes its frames (at most one
  // period) before the answer is awaited.
  if (gate_.lockstep()) AdvanceBusUntil([&] { return gate_.CycleCompleteOnBus(); });
  CloseLastCycle(cycle);
}

void SyncSource::CloseLastCycle(int cycle) {
  if (run_.failed()) return;
  if (!gate_.lockstep() || gate_.CycleCompleteOnBus()) {
    gate_.WaitLastStatus(cycle, cycles_);
  } else {
    // A sync answer of the last SYNC never came (silent node, dropped frame): no later SYNC
    // closes that cycle, so its answer is not awaited.
    run_.events.push_back(nlohmann::json{{"t_s", run_.MotionSeconds(run_.now_ns)},
                                         {"event", "last_cycle_incomplete"},
                                         {"cycle", cycles_}});
  }
}

}  // namespace wheelhil::emulator::sim
