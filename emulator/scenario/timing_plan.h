#pragma once
/// How a run keeps time with its firmware, decided once: which clock (the firmware's virtual
/// clock in lockstep, or the wall clock), who produces SYNC, and which bus. ResolveTiming is a
/// pure function of the scenario's timing block, the command line and the bus; the runner, the
/// firmware link and the scheduler read the plan it returns and decide nothing of it themselves
/// (docs/virtual-time.md).
/// Thread-compatible value type.

#include <string>

#include "emulator/firmware/firmware_link.h"
#include "emulator/scenario/scenario.h"

namespace wheelhil::emulator::scenario {

struct TimingPlan {
  enum class Clock {
    kVirtual,  ///< Lockstep: the firmware's processes on the emulator's clock.
    kWall,     ///< Real time: virtual time paced to the wall clock, nothing waited for.
  };
  Clock clock = Clock::kVirtual;
  bool firmware_produces_sync = true;  ///< Else the emulator produces SYNC.
  bool kernel_bus = false;             ///< A kernel CAN interface (--can), not the private bus.

  bool lockstep() const { return clock == Clock::kVirtual; }
  bool virtual_clock() const { return clock == Clock::kVirtual; }
  firmware::FirmwareLink::Pacing pacing() const;
  /// "virtual", "wall" (events.jsonl's run_start).
  const char* clock_name() const;
};

/// What the plan is decided from.
struct TimingChoice {
  TimingSpec spec;               ///< The scenario's timing block (the command line applied).
  std::string source_path;       ///< The scenario file, for the errors.
  bool realtime = false;         ///< --realtime.
  std::string can_iface;         ///< --can (empty: the private userspace bus).
  bool firmware_command = true;  ///< The scenario starts the firmware (firmware.command).
};

/// Throws std::invalid_argument, naming the scenario file and what to change, for a
/// combination that cannot run: a firmware attached from outside (no firmware.command) in
/// lockstep.
TimingPlan ResolveTiming(const TimingChoice& choice);

}  // namespace wheelhil::emulator::scenario
