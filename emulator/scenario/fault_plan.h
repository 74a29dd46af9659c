#pragma once
/// The one place the scenario's `faults:` list is wired into the run. At the motion start
/// (the origin of every fault window) Arm builds the fault library's injectors (emulator/faults)
/// and hands them to their targets: frame faults to every device's output on the bus hub, bus
/// faults around the bus model, device faults to their device (by CANopen node id, or by name:
/// "gyro", "accel4"), sensor faults to the device owning the channel ("gyro", "accel4.1".."4",
/// "encoder.<wheel>"). Each injector has its own random stream drawn from the run seed in a
/// fixed order. StepNodeFaults switches the scenario's node faults (encoder_emcy,
/// encoder_silent) at their window edges. Physical faults (wheel friction, torque, bumps) act on
/// the physics instead (PhysicsStage). Thread-compatible.

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "emulator/devices/device.h"
#include "emulator/faults/fault_event.h"
#include "emulator/scenario/scenario.h"
#include "emulator/sim/bus_hub.h"
#include "emulator/sim/run_context.h"

namespace wheelhil::emulator::scenario {

class FaultPlan {
 public:
  FaultPlan(const Scenario& scenario, std::uint64_t seed, std::string dbc_dir);

  void Arm(std::int64_t t0_ns, std::vector<std::unique_ptr<Device>>& devices, sim::BusHub& hub);
  /// The node faults' window edges at the end of the motion step that ended at t_ns.
  void StepNodeFaults(std::int64_t t_ns, std::int64_t step_ns,
                      std::vector<std::unique_ptr<Device>>& devices, sim::RunContext& run);
  /// The injectors' log of start/end events (a forecast's copies of them record there too).
  FaultEventLog& log() { return log_; }
  /// The injectors' start/end events, recorded so far, into the run's events.
  void FlushEvents(sim::RunContext& run);
  /// report.json's "faults" block; nullopt when the scenario has no library fault.
  std::optional<nlohmann::json> Metrics(const std::vector<std::unique_ptr<Device>>& devices,
                                        const sim::BusHub& hub) const;

 private:
  const Scenario& s_;
  std::uint64_t seed_;
  std::string dbc_dir_;
  std::int64_t motion0_ns_ = 0;
  bool library_faults_ = false;
  FaultEventLog log_;
};

}  // namespace wheelhil::emulator::scenario
