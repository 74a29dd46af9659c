#include "emulator/cli/bench_command.h"

#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <iostream>
#include <iterator>

#include <fmt/format.h>

#include "emulator/bench/bench_report.h"
#include "emulator/cli/bus_commands.h"
#include "emulator/cli/finite_number.h"

#ifndef WHEELHIL_SOURCE_DIR
#define WHEELHIL_SOURCE_DIR "."
#endif

namespace wheelhil::emulator {
namespace {

std::string SelfExe() {
  char buf[4096];
  const ssize_t n = ::readlink("/proc/self/exe", buf, sizeof(buf) - 1);
  if (n <= 0) return "wheelhil";
  return std::string(buf, static_cast<std::size_t>(n));
}

int Check(const std::string& path) {
  std::ifstream in(path);
  if (!in) {
    fmt::print(stderr, "wheelhil bench --check: cannot read {}\n", path);
    return 2;
  }
  nlohmann::json report;
  try {
    report = nlohmann::json::parse(in);
  } catch (const std::exception& e) {
    fmt::print(stderr, "{}: not JSON: {}\n", path, e.what());
    return 1;
  }
  const auto problems = bench::CheckReport(report);
  for (const auto& p : problems) fmt::print(stderr, "{}: {}\n", path, p);
  if (problems.empty()) {
    fmt::print("{}: all {} documented keys present\n", path,
               bench::DocumentedMetricKeys().size() + bench::DocumentedTextKeys().size());
  }
  return problems.empty() ? 0 : 1;
}

}  // namespace

BenchCommand::BenchCommand(CLI::App& app) : app_(&app) {
  options_.source_dir = WHEELHIL_SOURCE_DIR;
  bench_ = app.add_subcommand(
      "bench", "Measure physics speed, bus throughput, real-time jitter and peak memory");
  bench_->add_option("--json", json_path_, "Also write the report as JSON to this file");
  bench_->add_flag("--quick", options_.quick, "Shorten every measurement (about 1 s each)");
  bench_->add_flag("--uml", options_.uml,
                   "Measure the kernel vcan inside the user-mode-linux test kernel when the host "
                   "has no vcan0");
  bench_->add_flag("--no-rt", no_rt_, "Real-time row without SCHED_FIFO and mlockall");
  bench_->add_option("--cpu", options_.cpu,
                     "Pin the real-time pacer to this CPU (-1: no pinning; default -2: the last "
                     "online CPU when SCHED_FIFO is granted, else none)");
  bench_->add_option("--bus-cpu", options_.bus_cpu,
                     "Pin the real-time row's bus broker, producer, writer and reader to this CPU "
                     "(-1: no pinning; default -2: the pacer's CPU)");
  bench_
      ->add_option("--spin-us", options_.spin_us,
                   "Real-time pacer: sleep to the deadline minus this margin, then spin (µs; "
                   "0: clock_nanosleep only)")
      ->check(FiniteNumber())
      ->check(CLI::Range(0.0, 1000.0));
  bench_->add_option("--fifo-priority", options_.fifo_priority, "SCHED_FIFO priority (1..99)")
      ->check(CLI::Range(1, 99));
  bench_->add_option("--load-threads", options_.load_threads,
                     "Busy threads during the loaded real-time run (-1: one per core)");
  bench_->add_option("--source-dir", options_.source_dir,
                     "Repository root (platforms, meshes, DBC files)");
  bench_->add_option("--check", check_path_,
                     "Only check that a JSON report has every documented key");
  bench_->add_option("--worker", worker_, "Internal: run one workload, print its JSON")->group("");
}

std::optional<int> BenchCommand::Run() {
  if (!bench_->parsed()) return std::nullopt;
  options_.sched_fifo = !no_rt_;
  if (!check_path_.empty()) return Check(check_path_);
  if (!worker_.empty()) {
    try {
      const nlohmann::json part = bench::RunWorker(worker_, options_);
      std::fflush(stdout);
      fmt::print("{}\n", part.dump());
      return 0;
    } catch (const std::invalid_argument& e) {
      fmt::print(stderr, "wheelhil bench: {}\n", e.what());
      return 2;
    } catch (const std::exception& e) {
      fmt::print(stderr, "wheelhil bench --worker {}: {}\n", worker_, e.what());
      return 1;
    }
  }
  // The lockstep rows run the paper scenarios through `wheelhil run`.
  const CLI::App* run = nullptr;
  try {
    run = app_->get_subcommand("run");
  } catch (const CLI::OptionNotFound&) {
    run = nullptr;
  }
  const std::string lockstep_reason =
      run ? std::string()
          : "`wheelhil run` (the scenario runner with the firmware in the loop) is not in this "
            "build";
  nlohmann::json report;
  try {
    report = bench::RunBench(options_, SelfExe(), UcanChildEnvironment, lockstep_reason);
  } catch (const std::exception& e) {
    fmt::print(stderr, "wheelhil bench: {}\n", e.what());
    return 1;
  }
  fmt::print("{}", bench::FormatTable(report));
  if (!json_path_.empty()) {
    std::ofstream out(json_path_);
    out << report.dump(2) << "\n";
    if (!out) {
      fmt::print(stderr, "wheelhil bench: cannot write {}\n", json_path_);
      return 1;
    }
  }
  return 0;
}

}  // namespace wheelhil::emulator
