#pragma once
/// Runs `wheelhil bench`: every workload (emulator/bench/bench_workloads.h) in its own child
/// process (`<self> bench --worker NAME ...`, result as one JSON line on its stdout), its peak
/// RSS from wait4's ru_maxrss, merged into one report with the machine facts. Figures that
/// could not be measured carry "unavailable: <reason>". Thread-compatible; spawns processes.

#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

namespace wheelhil::emulator::bench {

struct BenchOptions {
  bool quick = false;      ///< Every measurement shortened (about 1 s each).
  std::string source_dir;  ///< Repository root (platforms, meshes, DBC files).
  bool sched_fifo = true;  ///< Real-time row: ask for SCHED_FIFO + mlockall.
  int fifo_priority = 80;
  /// Real-time row: pin the pacer to this CPU; -1 = no pinning, -2 = the last online CPU when
  /// SCHED_FIFO is granted, else no pinning.
  int cpu = -2;
  /// Real-time row: pin broker, producer, writer, reader; -1 = no pinning, -2 = the pacer's
  /// CPU (a send then wakes the broker on its own CPU instead of across CPUs).
  int bus_cpu = -2;
  double spin_us = 50.0;  ///< Real-time row: spin margin of the pacer's wait, µs (0 = sleep).
  int load_threads = -1;  ///< Busy threads of the loaded real-time run; -1 = one per core.
  bool uml = false;       ///< Measure the kernel vcan inside the user-mode-linux test kernel.
};

/// Environment entries a child needs to reach the userspace buses of `runtime_dir` (LD_PRELOAD
/// of libwheelhil_ucan.so, WHEELHIL_UCAN_DIR); see emulator/cli/bus_commands.h.
using UcanEnvironmentFn =
    std::function<std::vector<std::pair<std::string, std::string>>(const std::string&)>;

/// What a child process produced.
struct WorkerOutcome {
  nlohmann::json report = nlohmann::json::object();  ///< Its JSON line ({} on failure).
  double max_rss_mib = 0.0;                          ///< ru_maxrss of the child.
  std::string problem;                               ///< Empty on success.
};

/// Runs argv (argv[0] = program path) with `extra_env` added to this environment, reads the
/// last line of its stdout that starts with '{' as JSON, and waits for it with wait4.
/// expect_json = false: a program that prints no JSON (e.g. `wheelhil run`) is fine. A worker
/// still running after limit_s of wall time (0: the bench's own limit, 45 s with --quick, else
/// 900 s) is killed with its process group, and `problem` says so.
WorkerOutcome RunWorkerProcess(const std::vector<std::string>& argv,
                               const std::vector<std::pair<std::string, std::string>>& extra_env,
                               bool expect_json = true, double limit_s = 0);

/// The full bench. self_exe: path of the wheelhil executable. The lockstep rows run
/// `<self_exe> run scenarios/<paperNNN>*.yaml` (the paper's reference scenario, else the first
/// such file; with --quick a copy cut to 1 s of motion) in a child process and read
/// wall.real_time_factor from its report.json: over a private userspace bus, and (vcan_rtf) with
/// `--can vcan0` on the host's vcan0 or, with `uml`, inside one user-mode-linux guest;
/// lockstep_unavailable non-empty: why they cannot run at all (e.g. no `run` command in this
/// build).
nlohmann::json RunBench(const BenchOptions& options, const std::string& self_exe,
                        const UcanEnvironmentFn& ucan_env, const std::string& lockstep_unavailable);

/// The worker side: runs workload `name` (physics, bus-ucan, bus-vcan, realtime,
/// realtime-loaded; lockstep-kernel: the lockstep runs on $WHEELHIL_VCAN or vcan0, plus (not
/// with --quick) over the userspace bus when $WHEELHIL_UML is set, i.e. inside the guest;
/// lockstep-vcan: the vcan lockstep rows as the full bench measures them) and returns its
/// partial report.
nlohmann::json RunWorker(const std::string& name, const BenchOptions& options);

}  // namespace wheelhil::emulator::bench
