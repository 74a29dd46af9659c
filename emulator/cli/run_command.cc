#include "emulator/cli/run_command.h"

#include <unistd.h>

#include <cmath>

#include <cstdlib>
#include <filesystem>
#include <stdexcept>
#include <system_error>

#include <fmt/format.h>

#include "bus/install_paths.h"
#include "emulator/cli/bus_commands.h"
#include "emulator/scenario/runner.h"
#include "emulator/scenario/scenario.h"
#include "emulator/sim/run_context.h"

namespace wheelhil::emulator {

namespace {

namespace fs = std::filesystem;

// $WHEELHIL_DBC_DIR, else the shipped files of a build tree or an install.
std::string FindDbcDir() {
  if (const char* env = std::getenv("WHEELHIL_DBC_DIR"); env != nullptr && env[0] != '\0') {
    return env;
  }
  return bus::FindShippedDbcDir(bus::RunningExecutableDir());
}

void PrintSummary(const nlohmann::json& r) {
  fmt::print("\n{} (seed {}): {:.2f} s simulated in {:.2f} s wall ({:.0f}x real time)\n",
             r.value("scenario", std::string()), r.value("seed", std::uint64_t{0}),
             r.value("sim_time_s", 0.0), r["wall"].value("wall_time_s", 0.0),
             r["wall"].value("real_time_factor", 0.0));
  const auto& m = r["metrics"];
  const char* streams[] = {"pose", "pose_raw"};
  fmt::print("{:<10} {:>14} {:>14} {:>12} {:>12} {:>12}\n", "stream", "final_err_m", "heading_err",
             "ape_rmse_m", "distance_m", "rotation");
  for (const char* s : streams) {
    if (!m.contains(s)) continue;
    const auto& p = m[s];
    fmt::print("{:<10} {:>14.4f} {:>14.4f} {:>12.4f} {:>12.3f} {:>12.3f}\n", s,
               p.value("final_position_error_m", 0.0), p.value("final_heading_error_rad", 0.0),
               p.value("ape_rmse_m", 0.0), p.value("distance_m", 0.0),
               p.value("rotation_rad", 0.0));
  }
  for (const char* s : {"fused", "odometry", "accel"}) {
    if (m.contains(s)) {
      fmt::print("{:<10} velocity RMSE {:.4f} m/s\n", s, m[s].value("velocity_rmse_m_s", 0.0));
    }
  }
  if (m.contains("correction")) {
    fmt::print("correction: uncorrected / corrected final error = {:.2f}\n",
               m["correction"].value("uncorrected_over_corrected", 0.0));
  }
  if (m.contains("slip") && m["slip"].contains("precision")) {
    fmt::print("slip detection: precision {:.2f}, recall {:.2f}, {} truth intervals\n",
               m["slip"].value("precision", 0.0), m["slip"].value("recall", 0.0),
               m["slip"].value("truth_intervals", 0));
  }
  if (m.contains("bus")) {
    fmt::print("bus: {} frames, load {:.1f} %, {} drops\n", m["bus"].value("frames", 0),
               100.0 * m["bus"].value("load", 0.0), m["bus"].value("drops", 0));
  }
  for (const auto& e : r.value("expectations", nlohmann::json::array())) {
    fmt::print("  [{}] {}{}\n", e.value("passed", false) ? "PASS" : "FAIL",
               e.value("text", std::string()),
               e.contains("value") ? fmt::format("  (value {})", e["value"].dump()) : "");
  }
  if (r.contains("failure")) fmt::print("run failed: {}\n", r["failure"].get<std::string>());
  fmt::print("verdict: {}\n", r.value("verdict", std::string()));
}

}  // namespace

RunCommand::RunCommand(CLI::App& app) {
  run_ = app.add_subcommand("run", "Run a scenario with the firmware in the loop");
  run_->footer(
      "Artefacts (in --out, default ./out/run):\n"
      "  can.log               every frame on the bus, candump -L format, virtual timestamps\n"
      "  report.json           verdict, metrics, expectations, events (docs/scenarios.md)\n"
      "  report.html           the same as a self-contained page with plots\n"
      "  events.jsonl          slip intervals, faults, firmware events, one JSON object a line\n"
      "  truth.csv, truth.tum  ground truth (body pose, wheel speeds, slip) / its pose, TUM\n"
      "  estimate.csv          the firmware's decoded outputs, one row a cycle\n"
      "  estimate.tum, estimate_raw.tum   the firmware's pose streams, TUM format\n"
      "  firmware.log          the firmware's stdout and stderr\n"
      "  firmware_config.yaml  the firmware config the run used\n"
      "  firmware.core         only after a crash: its core (first frames in firmware.log)\n"
      "Exit status: 0 every expectation holds, 1 the run or an expectation failed, 2 input "
      "error.");
  run_->add_option("scenario", scenario_, "Scenario file (scenarios/*.yaml)")->required();
  run_->add_option("--out", out_, "Output directory (can.log, report.json, ...)");
  run_->add_option("--seed", seed_, "Seed (overrides the scenario's)");
  run_->add_option("--can", can_,
                   "SocketCAN interface (vcan0, can0); default: a private userspace bus");
  run_->add_flag("--realtime", realtime_, "Pace virtual time to the wall clock");
  run_->add_flag("--quiet", quiet_, "No progress line and no summary");
  run_->add_option("--cpu", cpu_,
                   "Lockstep: run emulator, bus and firmware on this CPU (default: the CPU the "
                   "run starts on; -1: no pinning)");
  run_->add_option("--physics-thread", physics_thread_,
                   "Lockstep: step the physics of the motion phase on a worker thread on another "
                   "CPU (auto: when the run may use more than one CPU; results are identical)")
      ->check(CLI::IsMember({"auto", "on", "off"}));
  run_->add_option("--clock", clock_,
                   "Lockstep: virtual, the only clock (the firmware on the emulator's clock, "
                   "any firmware, docs/virtual-time.md); cooperative, the retired FW_Status "
                   "handshake, is refused with what replaced it")
      ->check(CLI::Validator(
          [](std::string& v) {
            return v == "virtual" || v == "cooperative" ? std::string()
                                                        : "'" + v + "' is not virtual";
          },
          "{virtual}"));
  run_->add_option("--stop-at", stop_at_s_,
                   "Virtual clock: stop the firmware when virtual time (can.log's clock) reaches "
                   "T seconds, for a debugger (it prints how to attach; virtual time waits for "
                   "the firmware while it is stopped or traced)")
      ->check(CLI::NonNegativeNumber);
  run_->add_option("--runahead", runahead_,
                   "Virtual clock: the firmware runs ahead through the bus forecast on its own "
                   "clock, with the same results (auto, the default: where that took less wall "
                   "time than the turns it saved; on: wherever it saved turns; "
                   "docs/virtual-time.md, Runahead)")
      ->check(CLI::IsMember({"auto", "on", "off"}));
  run_->add_flag("--check-runahead", check_runahead_,
                 "Virtual clock: forecast the bus at every turn that ends the firmware's run "
                 "through frames, check the run hands it exactly those, and count the hand-overs "
                 "runahead would leave (report.json wall.runahead_check; docs/virtual-time.md)");
  run_->add_option("--logs", logs_,
                   "Also write the bus log in these formats beside can.log (asc: can.asc, blf: "
                   "can.blf; Vector's formats), and mcap: the whole run as run.mcap (Foxglove); "
                   "overrides the scenario's logs:")
      ->delimiter(',')
      ->check(CLI::IsMember({"asc", "blf", "mcap"}));
  run_->add_option("--sync-producer", sync_producer_,
                   "firmware or emulator; overrides timing.sync_producer")
      ->check(CLI::IsMember({"firmware", "emulator"}));
}

std::optional<int> RunCommand::Run() {
  if (!run_->parsed()) return std::nullopt;
  scenario::Scenario sc;
  try {
    sc = scenario::LoadScenarioFile(scenario_);
  } catch (const std::invalid_argument& e) {
    fmt::print(stderr, "wheelhil run: {}\n", e.what());
    return 2;
  }
  if (clock_ == "cooperative") {
    fmt::print(stderr, "wheelhil run: --clock cooperative: {}\n",
               scenario::kCooperativeClockRetired);
    return 2;
  }
  if (!logs_.empty()) sc.log_formats = logs_;
  if (!sync_producer_.empty()) {
    sc.timing.firmware_produces_sync = sync_producer_ == "firmware";
    sc.timing.sync_producer_named = true;
  }
  scenario::RunOptions o;
  o.out_dir = out_;
  o.seed = seed_;
  o.can_iface = can_;
  o.realtime = realtime_;
  o.cpu = cpu_;
  o.physics_thread = physics_thread_ == "on"    ? scenario::RunOptions::PhysicsThread::kOn
                     : physics_thread_ == "off" ? scenario::RunOptions::PhysicsThread::kOff
                                                : scenario::RunOptions::PhysicsThread::kAuto;
  if (stop_at_s_) o.stop_firmware_at_ns = std::llround(*stop_at_s_ * 1e9);
  o.check_runahead = check_runahead_;
  using RA = scenario::RunOptions::Runahead;
  o.runahead = runahead_ == "on" ? RA::kOn : runahead_ == "off" ? RA::kOff : RA::kAuto;
  o.progress = !quiet_ && ::isatty(2);
  o.progress_lines_s = quiet_ ? 0 : 10;
  if (!quiet_) {
    o.on_private_bus = [](const std::string& bus, const std::string& dir) {
      fmt::print(stderr,
                 "wheelhil run: the firmware's bus is {}, a private userspace bus in {}; to "
                 "watch it: wheelhil exec --runtime-dir {} -- candump -L {}\n",
                 bus, dir, dir, bus);
    };
  }
  o.bin_dir = bus::RunningExecutableDir();
  o.dbc_dir = FindDbcDir();
  o.ucan_child_env = [](const std::string& dir) { return UcanChildEnvironment(dir); };
  // Ctrl-C, a CI job's timeout (SIGTERM) or a closed terminal end the run as a failure would:
  // the firmware stopped, its private bus removed, what was recorded written.
  sim::InstallInterruptHandlers();
  try {
    const auto result = scenario::RunScenario(sc, o);
    if (!quiet_) PrintSummary(result.report);
    return result.exit_code;
  } catch (const std::invalid_argument& e) {
    fmt::print(stderr, "wheelhil run: {}\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    fmt::print(stderr, "wheelhil run: {}\n", e.what());
    return 1;
  }
}

}  // namespace wheelhil::emulator
