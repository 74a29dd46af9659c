#include "emulator/scenario/bus_forecast.h"

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
}

BusForecast::~BusForecast() = default;

bool BusForecast::RunTo(std::int64_t until_ns, PhysicsStage& physics, FaultPlan& faults,
                        std::size_t max_frames) {
  FaultEventLog& log = faults.log();
  const std::size_t logged = log.size();
  bool whole = true;
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
  }
  log.Truncate(logged);
  return whole;
}

}  // namespace wheelhil::emulator::scenario
