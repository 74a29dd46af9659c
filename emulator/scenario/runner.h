#pragma once
/// Runs a scenario end to end by wiring the run's components (docs/architecture.md): physics at
/// the scenario's rate (1 kHz default), the scenario's devices (device registry) sampling the
/// ground truth, every frame timed by the CAN bus model (completion timestamps) and put on a
/// real bus - a private userspace bus (UcanBroker in a fresh runtime directory) by default, or
/// a SocketCAN interface - where the firmware under test runs (started from the scenario's
/// command line, `${CAN}`, `${CONFIG}` and `${BIN}` substituted, LD_PRELOAD +
/// WHEELHIL_UCAN_DIR set on the userspace bus).
///
/// Lockstep (default): the firmware's processes run on the run's virtual clock
/// (libwheelhil_vtime.so, docs/virtual-time.md) and virtual time goes on only when all of them
/// are blocked; the firmware is the SYNC producer unless the scenario names the emulator
/// (timing_plan.h decides). Frames from the firmware enter the bus model at the virtual instant
/// they were sent, so the same scenario and seed give the same can.log byte for byte. Realtime:
/// virtual time is paced to the wall clock, nothing is waited for.
/// The run is scored by the metric components the scenario selects (emulator/scoring).
///
/// Leaves in out_dir: can.log, truth.csv, estimate.csv, truth.tum, estimate.tum (pose stream),
/// estimate_raw.tum (pose_raw), events.jsonl, report.json, report.html, firmware.log, and the
/// firmware config actually used (firmware_config.yaml). Thread-compatible (one run at a time
/// per process: it sets WHEELHIL_UCAN_DIR in this process's environment).

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "emulator/scenario/scenario.h"

namespace wheelhil::emulator::scenario {

struct RunOptions {
  std::string out_dir = "out";
  std::optional<std::uint64_t> seed;  ///< Overrides the scenario's seed.
  std::string can_iface;              ///< Empty: private userspace bus "ucan0".
  bool realtime = false;              ///< Overrides timing.mode.
  bool progress = false;              ///< Progress line on stderr (a terminal).
  /// Not a terminal: a plain progress line on stderr every `progress_lines_s` of wall time
  /// (0: none), for CI logs of long runs.
  double progress_lines_s = 0;
  /// Called once the private userspace bus is up, before the firmware starts: its name and
  /// runtime directory (where other SocketCAN programs can attach to watch it).
  std::function<void(const std::string& bus, const std::string& runtime_dir)> on_private_bus;
  /// Virtual clock: the firmware's process group is stopped (SIGSTOP) once the bus's clock
  /// reaches this many ns (can.log's time; -1: never), for a debugger to attach; virtual time
  /// then waits for it for as long as it is stopped or traced (docs/virtual-time.md,
  /// "Debugging"). `on_firmware_stopped` is called with its pid then.
  std::int64_t stop_firmware_at_ns = -1;
  /// Virtual clock, motion phase with a physics worker: at every turn that ends a firmware's
  /// run through the frames (it sent, a deadline of its came, or the forecast ran out), the
  /// bus is forecast up to the firmware's next deadline (BusForecast), and each later turn
  /// checks that the run hands the firmware exactly the forecast frames at their instants; a
  /// difference fails the run. report.json's wall.runahead_check counts the turns a firmware
  /// that ran ahead through the forecasts would have needed.
  bool check_runahead = false;
  /// Virtual clock, motion phase with a physics worker, the firmware the SYNC producer:
  /// runahead (docs/virtual-time.md). At every turn that ends the firmware's run through frames
  /// the bus is forecast, the forecast frames put in the firmware's rings ahead, and the
  /// firmware moves its clock itself through them and its own deadlines until it sends; the
  /// run then moves its bus up to there, checking it hands the firmware exactly those frames.
  /// kOn makes a window wherever one saved enough turns last time; kAuto (the default) only
  /// where one took less wall time than the turns it saved (on a loaded machine, or with a
  /// firmware that sends every few frames, the run goes one frame at a time). Either way every
  /// artefact is what kOff gives.
  enum class Runahead { kOff, kOn, kAuto };
  Runahead runahead = Runahead::kAuto;
  std::function<void(pid_t pid)> on_firmware_stopped;
  std::string bin_dir;                ///< ${BIN}; directory of wheelhil-fw.
  std::string dbc_dir;                ///< Directory of the bus/dbc files.
  /// Lockstep only: the CPU the run (emulator, bus and firmware process) is confined to.
  /// Lockstep is strictly sequential, and on one CPU each hand-over between emulator and
  /// firmware is a cheap local context switch instead of a cross-CPU wake-up. nullopt: the CPU
  /// the run starts on; -1: no confinement. Also puts the run at SCHED_BATCH, so that a woken
  /// side does not preempt the one still writing its frames.
  std::optional<int> cpu;
  /// Lockstep only: step the physics of the motion phase on a worker thread on another allowed
  /// CPU, ahead of the run's thread (results are the same bits either way); the accel4 sensor
  /// readings and the can.log formatting go to that CPU too. kAuto: when the run may use more
  /// than one CPU.
  enum class PhysicsThread { kAuto, kOn, kOff };
  PhysicsThread physics_thread = PhysicsThread::kAuto;
  /// Environment a child needs on a private userspace bus in `runtime_dir` (LD_PRELOAD ...).
  std::function<std::vector<std::pair<std::string, std::string>>(const std::string&)>
      ucan_child_env;
};

struct RunResult {
  /// 0 every expectation holds; 1 an expectation failed or the run failed (timeout, firmware
  /// exit, bus error); 2 usage or input error.
  int exit_code = 1;
  std::string failure;  ///< Why the run failed (empty when it ran to the end).
  nlohmann::json report;
};

/// Runs the scenario; never throws for run-time failures (they are in RunResult.failure);
/// input errors (bad DBC directory, unwritable out_dir) throw std::invalid_argument.
RunResult RunScenario(const Scenario& scenario, const RunOptions& options);

}  // namespace wheelhil::emulator::scenario
