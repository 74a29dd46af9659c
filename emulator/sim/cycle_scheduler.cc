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
  gate_.Drain();
  if (o_.motion) stages_.AfterMotionStep();
}

void SyncSource::Fire(std::int64_t t_ns) {
  const std::int64_t k = k_++;
  stages_.RecordTruth(t_ns, true);
  stages_.SendSync(t_ns);
  // The SYNC and the frames answering it (the readings at this instant) go out before the
  // physics moves on.
  stages_.AdvanceBus(t_ns + stages_.step_ns() / 2);
  if (k < cycles_) return;
  steps_.Stop();
  if (run_.failed()) return;
  gate_.AfterLastCycle();
}

}  // namespace wheelhil::emulator::sim
