#include "emulator/scenario/bus_forecast.h"

#include <algorithm>
#include <utility>

namespace wheelhil::emulator::scenario {

BusForecast::BusForecast(const sim::BusHub& hub,
                         const std::vector<std::unique_ptr<Device>>& devices,
                         const sim::RunContext& run, std::int64_t step_ns)
    : real_run_(run), step_ns_(step_ns) {
  run_.now_ns = run.now_ns;
  run_.motion0_s = run.motion0_s;
  run_.motion0_ns = run.motion0_ns;
  devices_.reserve(devices.size());
  for (const auto& d : devices) devices_.push_back(d->Clone());
  hub_ = hub.CopyForForecast(devices_, run_, [this](const bus::CanFrame& f) {
    completed_.push_back(f);
    return true;
  });
  hub_->SetWireTap([this](const WireFrame& w) { wire_.push_back(w); });
}

BusForecast::~BusForecast() = default;

bool BusForecast::RunTo(std::int64_t until_ns, PhysicsStage& physics, FaultPlan& faults,
                        std::size_t max_frames,
                        const std::vector<std::pair<std::int64_t, bus::CanFrame>>& foreseen) {
  FaultEventLog& log = faults.log();
  const std::size_t logged = log.size();
  bool whole = true;
  auto next_foreseen = foreseen.begin();
  while (next_foreseen != foreseen.end() && next_foreseen->first <= run_.now_ns) ++next_foreseen;
  while (run_.now_ns + step_ns_ <= until_ns && frames_.size() < max_frames) {
    const std::int64_t t = run_.now_ns + step_ns_;
    const auto step = t > real_run_.now_ns
                          ? physics.PeekMotionStep((t - real_run_.now_ns) / step_ns_)
                          : std::nullopt;
    if (!step || run_.failed()) {
      whole = false;
      break;
    }
    run_.now_ns = t;
    const auto& readings = *step->readings;
    StepDevicesAt(
        t, step_ns_, true, *step->body, *step->wheels,
        [&](std::size_t d) {
          return d < readings.size() ? std::span<const double>(readings[d])
                                     : std::span<const double>();
        },
        devices_, *hub_, faults, run_);
    hub_->AdvanceTo(t);
    for (const bus::CanFrame& f : completed_) frames_.push_back({t, f});
    completed_.clear();
    for (; next_foreseen != foreseen.end() && next_foreseen->first <= t; ++next_foreseen) {
      if (next_foreseen->first == t) hub_->EnqueueFromFirmware(next_foreseen->second);
    }
  }
  log.Truncate(logged);
  return whole;
}

std::vector<firmware::RunaheadSendPlan::Gap> BusForecast::SendGaps(std::int64_t first_ns,
                                                                   std::int64_t step_ns) const {
  std::vector<firmware::RunaheadSendPlan::Gap> gaps;
  const std::int64_t bit_ns = hub_->bit_time_ns();
  // A frame that started before reached_ns() but had not completed is not in wire_; one that
  // started before `known` did, however long (an extended frame of 8 bytes, worst stuffing).
  bus::CanFrame longest;
  longest.extended = true;
  longest.len = 8;
  const std::int64_t known =
      reached_ns() -
      static_cast<std::int64_t>(CanFrameBits(longest, StuffingMode::kWorstCase)) * bit_ns;
  auto free_of = [bit_ns](const WireFrame& w) {
    return w.start_ns + static_cast<std::int64_t>(w.bits) * bit_ns;
  };
  for (std::int64_t t = first_ns; step_ns > 0 && t <= reached_ns(); t += step_ns) {
    firmware::RunaheadSendPlan::Gap g;
    // The first frame still on the bus at t, or starting at or after it.
    std::size_t i = static_cast<std::size_t>(
        std::partition_point(wire_.begin(), wire_.end(),
                             [&](const WireFrame& w) { return free_of(w) <= t; }) -
        wire_.begin());
    std::int64_t x = t;
    for (; i < wire_.size() && wire_[i].start_ns <= x; ++i) {
      // One that started before x holds the bus; one starting at x won an arbitration that a
      // frame queued at t would have taken part in.
      if (wire_[i].start_ns == x) g.max_key = std::max(g.max_key, ArbitrationKey(wire_[i].frame));
      x = std::max(x, free_of(wire_[i]));
    }
    g.idle_ns = x;
    g.busy_ns = std::max(x, std::min(known, i < wire_.size() ? wire_[i].start_ns : known));
    gaps.push_back(g);
  }
  return gaps;
}

}  // namespace wheelhil::emulator::scenario
