#pragma once
/// `wheelhil run SCENARIO [--out DIR] [--seed N] [--can IFACE] [--realtime] [--timeout S]`: runs a
/// scenario (emulator/scenario/runner.h) with the firmware in the loop, prints a summary table
/// and returns 0 when every expectation holds, 1 when one fails or the run fails, 2 for a usage
/// or input error (bad scenario file: file:line:column: field: problem). Thread-compatible.

#include <CLI/CLI.hpp>

#include <optional>
#include <string>
#include <vector>

namespace wheelhil::emulator {

class RunCommand {
 public:
  /// Adds the `run` subcommand to `app` (call before parsing).
  explicit RunCommand(CLI::App& app);
  /// After parsing: the exit code when `run` ran, else nullopt.
  std::optional<int> Run();

 private:
  CLI::App* run_ = nullptr;
  std::string scenario_;
  std::string out_ = "out/run";
  std::optional<std::uint64_t> seed_;
  std::string can_;
  bool realtime_ = false;
  std::optional<int> cpu_;
  std::string physics_thread_ = "auto";
  std::vector<std::string> logs_;  // --logs
  std::optional<double> stop_at_s_;  // --stop-at
  bool check_runahead_ = false;
  std::string runahead_ = "auto";
  std::string clock_;          // empty: the scenario's timing.clock
  std::string sync_producer_;  // empty: the scenario's timing.sync_producer
  bool quiet_ = false;
};

}  // namespace wheelhil::emulator
