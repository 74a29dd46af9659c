#pragma once
/// BusForecast: the frames the bus will bring the firmware if the firmware sends none. It copies
/// the run's bus (bus model, bus and frame faults) and devices as they are after the latest
/// physics step, and runs the copies through the motion steps the physics worker already made,
/// each step as the run makes it (StepDevicesAt, then the bus to the step's end). A frame for
/// the firmware counts at the end of the step in which it completed: that is when the run hands
/// it over. Until the firmware sends, the run itself then sends the same frames at the same
/// instants (the run's `--check-runahead` compares them), which is what lets the firmware run
/// ahead through them (docs/virtual-time.md, "Runahead").
///
/// The copies never touch the run's outputs: no can.log, no observer, their events go to a
/// RunContext of their own, and what they record in the fault log is taken back at the end of
/// each RunTo. Closed loop (the firmware drives the physics) has no worker, so no forecast.
/// Thread-compatible: the run's thread.

#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include "bus/can_frame.h"
#include "emulator/devices/device.h"
#include "emulator/firmware/virtual_clock.h"
#include "emulator/scenario/fault_plan.h"
#include "emulator/scenario/physics_stage.h"
#include "emulator/sim/bus_hub.h"
#include "emulator/sim/run_context.h"

namespace wheelhil::emulator::scenario {

/// The devices' part of a step that ends at t_ns, the run's and a forecast's alike: the node
/// faults' window edges (motion), every device polled with the vehicle after the step, the
/// frames a frame fault delayed that are due, the device faults' windows.
template <typename ReadingsOf>
void StepDevicesAt(std::int64_t t_ns, std::int64_t step_ns, bool motion,
                   const physics::BodyTruth& body, const std::vector<physics::WheelTruth>& wheels,
                   ReadingsOf readings_of, std::vector<std::unique_ptr<Device>>& devices,
                   sim::BusHub& hub, FaultPlan& faults, sim::RunContext& run) {
  if (motion) faults.StepNodeFaults(t_ns, step_ns, devices, run);
  DeviceWorld world;
  world.body = &body;
  world.wheels = &wheels;
  for (std::size_t d = 0; d < devices.size(); ++d) {
    world.readings = readings_of(d);
    devices[d]->Poll(t_ns, world, hub.port(d));
  }
  hub.ReleaseDelayed();
  for (auto& d : devices) d->EndStep(t_ns);
}

/// A frame for the firmware and the step end at which the run hands it over.
struct ForecastFrame {
  std::int64_t t_ns = 0;
  bus::CanFrame frame;
};

class BusForecast {
 public:
  /// Copies `hub` and `devices` as they are now; the copies' next step is the one after
  /// run.now_ns (the latest physics step). `run` (the run's) must outlive the forecast.
  BusForecast(const sim::BusHub& hub, const std::vector<std::unique_ptr<Device>>& devices,
              const sim::RunContext& run, std::int64_t step_ns);
  ~BusForecast();
  BusForecast(const BusForecast&) = delete;
  BusForecast& operator=(const BusForecast&) = delete;

  /// Runs the copies' motion steps up to the one ending at or before until_ns, or the first
  /// whose frames make `max_frames` or more. False when it stopped earlier: the physics worker
  /// has no such step (none running, past its last step, beyond its ring) or a copy failed;
  /// the frames up to there stand. `foreseen` (instant, frame; in order): frames the firmware
  /// is expected to send, each taken at its instant after that step's frames, as the run takes
  /// a frame of the firmware's.
  bool RunTo(std::int64_t until_ns, PhysicsStage& physics, FaultPlan& faults,
             std::size_t max_frames = SIZE_MAX,
             const std::vector<std::pair<std::int64_t, bus::CanFrame>>& foreseen = {});

  /// For a frame the firmware might send at each grid instant first_ns + k * step_ns up to
  /// reached_ns() that nobody foresaw: the arbitrations it would first take part in and the
  /// idle stretch of the forecast bus it would find after them (firmware::RunaheadSendPlan).
  /// Only what the forecast scheduled for sure counts: a stretch ends where a frame may
  /// have started that had not completed by reached_ns().
  std::vector<firmware::RunaheadSendPlan::Gap> SendGaps(std::int64_t first_ns,
                                                        std::int64_t step_ns) const;

  /// What the firmware gets, in order, from the first forecast step to reached_ns().
  const std::vector<ForecastFrame>& frames() const { return frames_; }
  /// The end of the latest step forecast (the start instant before any).
  std::int64_t reached_ns() const { return run_.now_ns; }

 private:
  const sim::RunContext& real_run_;  // its now_ns: the physics' latest step
  sim::RunContext run_;              // the copies' own: their events and failures go nowhere else
  std::int64_t step_ns_;
  std::vector<std::unique_ptr<Device>> devices_;
  std::unique_ptr<sim::BusHub> hub_;
  std::vector<bus::CanFrame> completed_;  // for the firmware, in the step being forecast
  std::vector<ForecastFrame> frames_;
  std::vector<WireFrame> wire_;  // every frame that completed on the copies' bus, in order
};

}  // namespace wheelhil::emulator::scenario
