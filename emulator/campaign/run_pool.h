#pragma once
/// Runs scenario runs as child processes, at most `jobs` at a time:
///   RUNNER run SCENARIO --out RUN_DIR --seed N [extra args]
/// (RUNNER is normally this very wheelhil executable; `wheelhil run` gives each run its own
/// private userspace CAN bus, so parallel runs never hear each other). Children get
/// PR_SET_PDEATHSIG(SIGKILL) and their own process group, so killing the campaign - SIGKILL
/// included - takes the runs in flight with it; a run over its timeout has its whole process
/// group killed. stdout/stderr of a run go to RUN_DIR/runner.log. After a child exits, its
/// RUN_DIR/report.json is parsed into a RunRecord. Single-threaded; not reentrant.

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "emulator/campaign/results_store.h"
#include "emulator/campaign/run_report.h"

namespace wheelhil::emulator::campaign {

struct PoolJob {
  RunRecord record;  ///< key, index, point, repeat, seed, params, run_dir filled in
  /// Writes the scenario file and returns its path; called right before the run starts (after
  /// RUN_DIR has been emptied and created). May throw: the run is then stored as "error".
  std::function<std::filesystem::path(const std::filesystem::path& run_dir)> prepare;
  double timeout_s = 600;
};

struct PoolOptions {
  std::string runner_exe;               ///< see ThisExecutable()
  std::vector<std::string> extra_args;  ///< appended after --seed N
  int jobs = 1;
  /// Give each concurrent run its own CPU (`--cpu`, round robin over the CPUs this process may
  /// use by job slot): lockstep runs confine themselves to one CPU, and two left to pick the
  /// one they start on can land on the same.
  bool spread_cpus = true;
  std::string label = "campaign";  ///< progress prefix
  bool progress = true;            ///< print progress to stderr (bar on a TTY, lines otherwise)
};

/// Runs `jobs`; `evaluate` fills passed/failure of a finished record (report already parsed:
/// verdict and metrics set, `report` null when no report came); `done` is called for each
/// finished record in completion order (e.g. to store it). Returns the records in completion
/// order. Throws std::runtime_error when a child cannot be started at all.
std::vector<RunRecord> RunPool(
    std::vector<PoolJob> jobs, const PoolOptions& options,
    const std::function<void(RunRecord&, const RunReport* report)>& evaluate,
    const std::function<void(const RunRecord&)>& done);

/// Absolute path of the running executable (/proc/self/exe).
std::string ThisExecutable();

/// Formats seconds as "1:05" / "1:02:03" (for ETAs).
std::string FormatDuration(double seconds);

}  // namespace wheelhil::emulator::campaign
