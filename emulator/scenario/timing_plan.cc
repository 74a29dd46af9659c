#include "emulator/scenario/timing_plan.h"

#include <stdexcept>

#include <fmt/format.h>

namespace wheelhil::emulator::scenario {

firmware::FirmwareLink::Pacing TimingPlan::pacing() const {
  using Pacing = firmware::FirmwareLink::Pacing;
  switch (clock) {
    case Clock::kVirtual:
      return Pacing::kVirtualClock;
    case Clock::kCooperative:
      return Pacing::kLockstep;
    case Clock::kWall:
      break;
  }
  return Pacing::kRealTime;
}

const char* TimingPlan::clock_name() const {
  switch (clock) {
    case Clock::kVirtual:
      return "virtual";
    case Clock::kCooperative:
      return "cooperative";
    case Clock::kWall:
      break;
  }
  return "wall";
}

TimingPlan ResolveTiming(const TimingChoice& c) {
  const TimingSpec& t = c.spec;
  TimingPlan plan;
  plan.kernel_bus = !c.can_iface.empty();
  const bool lockstep = t.lockstep && !c.realtime;
  // No virtual clock without a firmware process to put on it (an attached firmware keeps its
  // own clock). On a kernel interface the firmware's clock is virtual as on the private bus;
  // only its bus is the kernel's.
  const bool virtual_time = lockstep && t.virtual_clock && c.firmware_command;
  plan.clock = !lockstep      ? TimingPlan::Clock::kWall
               : virtual_time ? TimingPlan::Clock::kVirtual
                              : TimingPlan::Clock::kCooperative;
  plan.firmware_produces_sync = t.sync_producer_named ? t.firmware_produces_sync : virtual_time;
  if (plan.firmware_produces_sync && plan.handshake()) {
    const std::string why = !t.virtual_clock  ? std::string("timing.clock: cooperative")
                            : plan.kernel_bus ? "kernel interface " + c.can_iface
                                              : std::string("no firmware.command");
    throw std::invalid_argument(fmt::format(
        "{}: timing.sync_producer: firmware: a firmware that produces SYNC runs in lockstep only "
        "on the virtual clock, which this run does not have ({}; use --realtime, or "
        "sync_producer: emulator)",
        c.source_path, why));
  }
  return plan;
}

}  // namespace wheelhil::emulator::scenario
