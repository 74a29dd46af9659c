#pragma once
/// `wheelhil bench [--json FILE] [--quick] [--uml] [--no-rt] [--cpu N] [--fifo-priority P]`:
/// measures physics speed, bus throughput, real-time jitter and peak memory in one run and
/// prints a table (and writes JSON); `wheelhil bench --check FILE` verifies that a JSON report
/// carries every documented key. See docs/performance.md. Thread-compatible.

#include <CLI/CLI.hpp>

#include <optional>
#include <string>

#include "emulator/bench/bench_runner.h"

namespace wheelhil::emulator {

class BenchCommand {
 public:
  /// Adds the `bench` subcommand to `app` (call before parsing).
  explicit BenchCommand(CLI::App& app);
  /// After parsing: the exit code when `bench` ran, else nullopt.
  std::optional<int> Run();

 private:
  CLI::App* app_ = nullptr;
  CLI::App* bench_ = nullptr;
  bench::BenchOptions options_;
  std::string json_path_;
  std::string check_path_;
  std::string worker_;
  bool no_rt_ = false;
};

}  // namespace wheelhil::emulator
