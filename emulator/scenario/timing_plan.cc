#include "emulator/scenario/timing_plan.h"

#include <stdexcept>

#include <fmt/format.h>

namespace wheelhil::emulator::scenario {

firmware::FirmwareLink::Pacing TimingPlan::pacing() const {
  using Pacing = firmware::FirmwareLink::Pacing;
  return clock == Clock::kVirtual ? Pacing::kVirtualClock : Pacing::kRealTime;
}

const char* TimingPlan::clock_name() const { return clock == Clock::kVirtual ? "virtual" : "wall"; }

TimingPlan ResolveTiming(const TimingChoice& c) {
  const TimingSpec& t = c.spec;
  TimingPlan plan;
  plan.kernel_bus = !c.can_iface.empty();
  const bool lockstep = t.lockstep && !c.realtime;
  if (lockstep && !c.firmware_command) {
    throw std::invalid_argument(fmt::format(
        "{}: a firmware attached from outside (no firmware.command) keeps its own clock, so it "
        "cannot run in lockstep: run it with --realtime (timing.mode: realtime), or give the "
        "scenario its firmware.command so that the run starts it on the virtual clock (the "
        "cooperative FW_Status handshake that ran it in lockstep was retired)",
        c.source_path));
  }
  plan.clock = lockstep ? TimingPlan::Clock::kVirtual : TimingPlan::Clock::kWall;
  // The firmware is the CANopen master, with its own config, unless the scenario names an
  // emulated one (the run rewrites no firmware config, in real time neither).
  plan.firmware_produces_sync = !t.sync_producer_named || t.firmware_produces_sync;
  return plan;
}

}  // namespace wheelhil::emulator::scenario
