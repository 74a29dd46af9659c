#pragma once
/// The run's physics: builds the world of a scenario (floor plane, meshes, friction patches,
/// seeded random patches, bumps; the platform's vehicle at the origin) and steps it. A step
/// from t to t + step commands the vehicle (standstill before the motion; the scenario's motion
/// profile or wheel speeds during it), applies the physical faults active at t (wheel friction,
/// torque disturbance; their start/end become events) and steps the world.
///
/// Closed loop (motion.source firmware): in every phase the driven wheels follow their drives
/// (SetDrives before each step: set point and torque limit of each drive's power stage), so
/// the physics depends on the bus and runs on the run's thread only.
/// With a scripted motion the physics of the motion phase depends on time only, not on the bus
/// or the firmware, so it may run on a worker thread on another CPU, up to 2048 steps ahead of the run's thread
/// (StartWorker; the results are the same bits). The devices' readings that may be taken ahead
/// (Device::ReadsAhead) are taken there too. Thread-compatible otherwise.

#include <sched.h>

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include <nlohmann/json.hpp>

#include "emulator/devices/device.h"
#include "emulator/physics/physics_world.h"
#include "emulator/scenario/scenario.h"
#include "emulator/sim/run_context.h"
#include "emulator/sim/step_pipeline.h"

namespace wheelhil::emulator::scenario {

class PhysicsStage {
 public:
  /// Builds the world; the random patches' and bumps' events go to run.events.
  PhysicsStage(const Scenario& scenario, std::uint64_t seed, sim::RunContext& run);
  ~PhysicsStage();

  std::int64_t step_ns() const { return step_ns_; }
  const physics::RollerVehicle& vehicle() const { return *vehicle_; }

  /// The motion starts at t0_ns (the motion profile's and the faults' time origin).
  void StartMotion(std::int64_t t0_ns);
  /// Closed loop: what the drives' power stages apply in the next step.
  void SetDrives(const std::vector<WheelDrive>& drives);
  /// Steps from t_ns to t_ns + step. False when the worker failed (the reason is in the run).
  bool Step(std::int64_t t_ns, bool motion);

  /// The vehicle after the latest step (the vehicle's own state, or the worker's copy).
  const physics::BodyTruth& body() const { return *body_; }
  const std::vector<physics::WheelTruth>& wheels() const { return *wheels_; }
  /// Device d's readings taken ahead for the latest step (empty without a worker).
  std::span<const double> readings(std::size_t device) const;

  /// A motion step ahead of the latest, not taken (the steps a worker makes only): the vehicle
  /// and the devices' readings after the step that ends `ahead` steps (>= 1) after the latest.
  /// nullopt without a worker, past its last step or further ahead than its ring holds.
  struct StepAhead {
    const physics::BodyTruth* body = nullptr;
    const std::vector<physics::WheelTruth>* wheels = nullptr;
    const std::vector<std::vector<double>>* readings = nullptr;  ///< By device.
  };
  std::optional<StepAhead> PeekMotionStep(std::int64_t ahead);

  /// Runs the next `steps` motion steps on a worker on `cpus` (nullptr: inherited), taking the
  /// readings ahead for the devices that allow it. Call after StartMotion. `fall_back`: when
  /// the worker makes the run wait longer than its steps cost it (its CPU taken by another
  /// job), the run's thread takes the rest of the steps back (sim::StepPipeline).
  void StartWorker(std::int64_t steps, const cpu_set_t* cpus,
                   std::vector<std::unique_ptr<Device>>& devices, bool fall_back);
  /// Stops the worker (a failed run leaves it steps ahead).
  void StopWorker();
  bool worker_used() const { return worker_used_; }
  /// The run time (ns) from which the run's thread made the steps itself after a worker; -1
  /// when it did not. Valid until StopWorker.
  std::int64_t inline_from_ns() const;

 private:
  struct StepResult {
    physics::BodyTruth body;
    std::vector<physics::WheelTruth> wheels;
    std::vector<nlohmann::json> events;         // physical fault events of the step
    std::vector<std::vector<double>> readings;  // by device
  };
  void BuildWorld(std::uint64_t seed);
  void AddBumps(Terrain& terrain);
  void Command(std::int64_t t_ns, bool motion);
  void ApplyPhysicalFaults(double tm_s, std::vector<nlohmann::json>& events);
  void StepWorld(std::int64_t t_ns, bool motion, std::vector<nlohmann::json>& events);

  const Scenario& s_;
  sim::RunContext& run_;
  std::unique_ptr<physics::PhysicsWorld> world_;
  physics::RollerVehicle* vehicle_ = nullptr;
  std::int64_t step_ns_ = 1'000'000;
  double t_motion0_s_ = 0;
  std::int64_t motion0_ns_ = 0;
  const physics::BodyTruth* body_ = nullptr;
  const std::vector<physics::WheelTruth>* wheels_ = nullptr;
  const StepResult* slot_ = nullptr;
  StepResult start_state_;  // the vehicle at the motion start, once a worker owns it
  std::unique_ptr<sim::StepPipeline<StepResult>> pipeline_;
  bool worker_used_ = false;
  std::int64_t worker_t0_ns_ = 0;  // the run time of the worker's step 0
  // Physical faults: per scenario fault, active; per wheel scratch (sized once).
  std::vector<char> physical_on_;
  bool has_physical_faults_ = false;
  std::vector<double> phys_scale_, phys_torque_;
  std::vector<std::optional<Friction>> phys_over_;
  std::vector<char> phys_touched_;
};

}  // namespace wheelhil::emulator::scenario
