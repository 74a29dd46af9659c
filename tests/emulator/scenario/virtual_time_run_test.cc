// Runs on the firmware's virtual clock (timing.clock: virtual; docs/virtual-time.md), end to
// end through RunScenario: a customer's firmware (tests/customer_firmware/) that knows nothing
// of wheelhil is the CANopen master and SYNC producer and publishes its pose in its own frames;
// the reference firmware runs with its shipped config (SYNC producer, cycle deadline on).
// Same scenario and seed -> byte-identical can.log; a firmware that never blocks ends the run
// with its thread named.
#include <signal.h>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "emulator/firmware/virtual_clock.h"
#include "emulator/scenario/runner.h"
#include "emulator/scenario/scenario.h"
#include "tests/emulator/scenario/runner_test_support.h"
#include "tests/command_output.h"

namespace wheelhil::emulator::scenario {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::Not;
using testing::Slurp;

const std::string kCustomerC =
    std::string(WHEELHIL_SOURCE_DIR) + "/tests/data/customer_firmware/c_epoll_odometry.yaml";

class VirtualTimeRun : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / fs::path("wheelhil_vtime_run_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

// The payload of the last frame with `id` in a candump -L log ("(t) iface ID#HEX").
std::vector<std::uint8_t> LastPayload(const std::string& log, const std::string& id) {
  std::vector<std::uint8_t> out;
  std::istringstream lines(log);
  std::string line;
  const std::string key = " " + id + "#";
  while (std::getline(lines, line)) {
    const auto at = line.find(key);
    if (at == std::string::npos) continue;
    out.clear();
    const std::string hex = line.substr(at + key.size());
    for (std::size_t i = 0; i + 1 < hex.size(); i += 2) {
      out.push_back(static_cast<std::uint8_t>(std::stoi(hex.substr(i, 2), nullptr, 16)));
    }
  }
  return out;
}

std::int32_t I32(const std::vector<std::uint8_t>& d, std::size_t at) {
  return static_cast<std::int32_t>(std::uint32_t{d[at]} | std::uint32_t{d[at + 1]} << 8 |
                                   std::uint32_t{d[at + 2]} << 16 | std::uint32_t{d[at + 3]} << 24);
}

// The last row's x of truth.csv (t_s,x_m,...).
double FinalTruthX(const fs::path& dir) {
  std::istringstream lines(Slurp(dir / "truth.csv"));
  std::string line, last;
  while (std::getline(lines, line)) {
    if (!line.empty()) last = line;
  }
  return std::stod(last.substr(last.find(',') + 1));
}

// The x of the last `stream` row of estimate.csv (t_s,cycle,stream,x,...).
double LastEstimateX(const fs::path& dir, const std::string& stream) {
  std::istringstream lines(Slurp(dir / "estimate.csv"));
  std::string line;
  double x = std::nan("");
  const std::string key = "," + stream + ",";
  while (std::getline(lines, line)) {
    const auto at = line.find(key);
    if (at != std::string::npos) x = std::stod(line.substr(at + key.size()));
  }
  return x;
}

// `s` run three times, into dir/a, dir/b and dir/c: their can.log must be the same bytes. The
// first hands the firmware every frame in a turn of its own (no runahead); the second run also
// forecasts the bus at each turn that ends the firmware's run through frames
// and checks it is handed exactly those (check_runahead: a difference fails it); in the third
// the firmware runs ahead through the forecasts on its own clock (runahead). Returns the first
// run's result and its can.log.
std::pair<RunResult, std::string> RunTwiceSameBytes(const Scenario& s, const fs::path& dir) {
  RunOptions one_by_one = testing::BuildTreeRunOptions(dir / "a");
  one_by_one.runahead = RunOptions::Runahead::kOff;
  RunResult a = RunScenario(s, one_by_one);
  RunOptions checked = testing::BuildTreeRunOptions(dir / "b");
  checked.check_runahead = true;
  const RunResult b = RunScenario(s, checked);
  EXPECT_EQ(a.failure, b.failure);
  EXPECT_TRUE(b.report["wall"].contains("runahead_check"));
  RunOptions ahead = testing::BuildTreeRunOptions(dir / "c");
  ahead.runahead = RunOptions::Runahead::kOn;
  const RunResult c = RunScenario(s, ahead);
  EXPECT_EQ(a.failure, c.failure);
  EXPECT_EQ(Slurp(dir / "a" / "can.log"), Slurp(dir / "c" / "can.log"));
  std::string log = Slurp(dir / "a" / "can.log");
  EXPECT_EQ(log, Slurp(dir / "b" / "can.log"));
  return {std::move(a), std::move(log)};
}

// A customer firmware's scenario run twice: the same bytes; the firmware's pose, scored through
// its own DBC (firmware.outputs), meets the scenario's expectations; and its last pose frame
// `id` (x, y: int32, 0.1 mm), decoded here by hand, is what the binding read (the DBC's unit is
// mm, m or cm) and where the robot ended (1 m straight), within a few encoder counts (0.24 mm
// each). Returns the first run's can.log.
std::string ExpectCustomerRun(const fs::path& dir, const std::string& scenario,
                              const std::string& id) {
  const Scenario s = LoadScenarioFile(std::string(WHEELHIL_SOURCE_DIR) +
                                      "/tests/data/customer_firmware/" + scenario);
  const auto [a, log] = RunTwiceSameBytes(s, dir);
  EXPECT_EQ(a.failure, "");
  EXPECT_EQ(a.report["verdict"], "pass") << a.report["expectations"].dump(1);
  EXPECT_GE(a.report["metrics"]["pose"]["frames"].get<int>(), 100);
  EXPECT_THAT(log, HasSubstr(" 000#0100"));
  // Every timed wait was the library's.
  EXPECT_THAT(Slurp(dir / "a" / "events.jsonl"), Not(HasSubstr("firmware_host_clock_wait")));
  const auto pose = LastPayload(log, id);
  EXPECT_EQ(pose.size(), 8u) << id;
  if (pose.size() == 8u) {
    EXPECT_NEAR(I32(pose, 0) * 1e-4, LastEstimateX(dir / "a", "pose"),
                1.5e-6);  // estimate.csv: 1 um
    EXPECT_NEAR(I32(pose, 0) * 1e-4, FinalTruthX(dir / "a"), 0.005);
    EXPECT_NEAR(I32(pose, 4) * 1e-4, 0.0, 0.005);
  }
  return log;
}

// The shipped scenarios the runahead tests run (firmware SYNC every 0.25 s; faults of every
// kind: sensor, frame, device, bus).
constexpr const char* kRunaheadScenarios[] = {"smoke/paper000_slip_short", "faults_demo",
                                              "bus_faults"};

// Shipped scenario `name` run one frame at a time into dir/plain and with `with` set into
// dir/other: the second must not fail, and can.log, events.jsonl and the report (without its
// wall block) must be those of the first. Returns both results.
std::pair<RunResult, RunResult> RunPlainAndWith(const fs::path& dir, const char* name,
                                                const std::function<void(RunOptions&)>& with) {
  const Scenario s =
      LoadScenarioFile(fmt::format("{}/scenarios/{}.yaml", WHEELHIL_SOURCE_DIR, name));
  RunOptions one_by_one = testing::BuildTreeRunOptions(dir / "plain");
  one_by_one.runahead = RunOptions::Runahead::kOff;
  RunResult plain = RunScenario(s, one_by_one);
  RunOptions o = testing::BuildTreeRunOptions(dir / "other");
  with(o);
  RunResult other = RunScenario(s, o);
  EXPECT_EQ(other.failure, "");
  EXPECT_EQ(plain.report["verdict"], "pass");
  EXPECT_EQ(Slurp(dir / "plain" / "can.log"), Slurp(dir / "other" / "can.log"));
  EXPECT_EQ(Slurp(dir / "plain" / "events.jsonl"), Slurp(dir / "other" / "events.jsonl"));
  EXPECT_EQ(testing::ReportWithoutWall(dir / "plain"), testing::ReportWithoutWall(dir / "other"));
  return {std::move(plain), std::move(other)};
}

// The bus forecast a firmware could run ahead through (BusForecast): for a firmware that sends
// twice per 0.25 s cycle, the run hands it exactly the forecast frames at their instants (a
// difference fails the checked run), and it would need far fewer hand-overs. The forecast's
// copies of the devices and fault injectors leave the run's record as it is.
TEST_F(VirtualTimeRun, TheRunHandsTheFirmwareExactlyTheBusForecast) {
  for (const char* name : kRunaheadScenarios) {
    SCOPED_TRACE(name);
    const auto [plain, checked] = RunPlainAndWith(dir_ / fs::path(name).filename(), name,
                                                  [](RunOptions& o) { o.check_runahead = true; });
    const auto& wall = checked.report["wall"];
    const auto& ra = wall["runahead_check"];
    EXPECT_GE(ra["frames_run_through"].get<int>(), 100) << ra.dump();
    EXPECT_GE(ra["ended_by_send"].get<int>(), 2) << ra.dump();
    // Two turns a cycle (its SYNC, its outputs) where the run needs ~116 a second.
    EXPECT_LE(ra["handovers_per_sim_s"].get<double>(), 15.0) << ra.dump();
    EXPECT_GE(wall["handovers_per_sim_s"].get<double>(), 100.0) << wall.dump();
  }
}

// Runahead: the forecast frames go into the firmware's rings ahead of their instants and the
// firmware moves its clock itself through them and its own deadlines until it sends. What it
// sees, and so every artefact, is what it would have seen one frame at a time (can.log,
// events.jsonl, the report: the same bytes). How many turns it saves depends on the load (the
// host takes the clock back when it finds a thread asleep outside the library's waits): on an
// idle machine ~12 hand-overs a simulated second where the run needs ~116 (paper000_slip over
// 42 s: 8.8; docs/performance.md), so only that it ran ahead at all is checked here.
TEST_F(VirtualTimeRun, TheFirmwareRunsAheadThroughTheForecastAndNothingChanges) {
  for (const char* name : kRunaheadScenarios) {
    SCOPED_TRACE(name);
    const auto [plain, ahead] =
        RunPlainAndWith(dir_ / fs::path(name).filename(), name,
                        [](RunOptions& o) { o.runahead = RunOptions::Runahead::kOn; });
    const auto& wall = ahead.report["wall"];
    EXPECT_GE(wall["runahead"]["frames_run_through"].get<int>(), 100) << wall.dump();
    EXPECT_GE(wall["runahead"]["local_advances"].get<int>(), 100) << wall.dump();
    EXPECT_FALSE(plain.report["wall"].contains("runahead"));
  }
}

// Runahead through the firmware's own sends (emulator/scenario/runahead_sends.h): paper 002's
// firmware sends its SYNC every 2 ms (foreseen: same bytes, same spacing) and its five output
// frames 1 ms after each (no device reads them; the bus has room for them). Its window goes on
// through both, where one that ended at every send would give ~1000 hand-overs a simulated
// second, and every artefact is what it is one frame at a time.
TEST_F(VirtualTimeRun, TheFirmwareRunsAheadThroughItsOwnSendsAndNothingChanges) {
  const auto [plain, ahead] =
      RunPlainAndWith(dir_ / "paper002", "paper002_velocity",
                      [](RunOptions& o) { o.runahead = RunOptions::Runahead::kOn; });
  const auto& wall = ahead.report["wall"];
  EXPECT_GE(wall["runahead"]["sends_through"].get<int>(), 20000) << wall.dump();
  // ~50 on an idle machine; windows end sooner under load (141 seen with ASan at -j2).
  EXPECT_LE(wall["handovers_per_sim_s"].get<double>(), 300.0) << wall.dump();
  EXPECT_GE(plain.report["wall"]["handovers_per_sim_s"].get<double>(), 900.0);
}

TEST_F(VirtualTimeRun, CustomerCFirmwareIsTheMasterAndItsRunsAreByteIdentical) {
  const std::string log = ExpectCustomerRun(dir_, "c_epoll_odometry.yaml", "3A0");
  // Its own CANopen start-up: TPDO1 made synchronous by SDO, NMT start, then SYNC every 10 ms.
  EXPECT_THAT(log, HasSubstr(" 601#2F00180201000000"));
  EXPECT_THAT(log, HasSubstr(" 581#6000180200000000"));
  EXPECT_THAT(log, HasSubstr(" 080#"));
  // Every SYNC on the bus is the firmware's: one per 10 ms of its timerfd, counted in the report.
  EXPECT_GT(testing::ReportWithoutWall(dir_ / "a")["cycles"].get<int>(), 400);
}

TEST_F(VirtualTimeRun, CustomerCppFirmwareWithConditionVariableTimingIsByteIdentical) {
  ExpectCustomerRun(dir_, "cpp_cv_odometry.yaml", "3B0");
}

TEST_F(VirtualTimeRun, CustomerPythonCanFirmwareIsByteIdentical) {
  ExpectCustomerRun(dir_, "python_can_odometry.yaml", "3C0");
}

// Closed loop through a motor controller that is not CANopen: a `dbc` device of the
// controller's own DBC takes the firmware's speed set points and reports wheel positions; the
// firmware stops after 1 m of wheel travel. Same bytes run to run.
TEST_F(VirtualTimeRun, CustomerFirmwareDrivesADbcMotorControllerClosedLoop) {
  const Scenario s = LoadScenarioFile(std::string(WHEELHIL_SOURCE_DIR) +
                                      "/tests/data/customer_firmware/python_can_motor_drive.yaml");
  const auto [a, log] = RunTwiceSameBytes(s, dir_);
  ASSERT_EQ(a.failure, "");
  EXPECT_EQ(a.report["verdict"], "pass") << a.report["expectations"].dump(1);
  const nlohmann::json& cl = a.report["metrics"]["closed_loop"];
  EXPECT_LT(cl["goal_error_m"].get<double>(), 0.02);
  EXPECT_NEAR(cl["final_x_m"].get<double>(), 1.0, 0.02);
  // Its set points (0x310, enable set) and the controller's feedback (0x311, 0x312) on the bus.
  EXPECT_THAT(log, HasSubstr(" 310#"));
  EXPECT_THAT(log, HasSubstr(" 312#"));
  EXPECT_EQ(LastPayload(log, "310"), (std::vector<std::uint8_t>{0, 0, 0, 0, 1}));  // stopped
}

// The work in a forked child, the parent only waiting for it: the child is on the clock from
// its first instruction, the parent (asleep in waitpid) is blocked.
TEST_F(VirtualTimeRun, AForkedChildRunsOnTheSameClock) {
  Scenario s = LoadScenarioFile(kCustomerC);
  s.firmware.command += " --fork 1";
  const auto [a, log] = RunTwiceSameBytes(s, dir_);
  ASSERT_EQ(a.failure, "");
  // The same bytes as the firmware without the fork.
  const RunResult c =
      RunScenario(LoadScenarioFile(kCustomerC), testing::BuildTreeRunOptions(dir_ / "c"));
  ASSERT_EQ(c.failure, "");
  EXPECT_EQ(log, Slurp(dir_ / "c" / "can.log"));
}

// Two Python threads (a can.Notifier feeding a can.BufferedReader; the main loop's
// get_message(timeout) is a timed semaphore wait, the GIL hand-over a timed condition wait).
TEST_F(VirtualTimeRun, CustomerPythonNotifierThreadIsByteIdentical) {
  ExpectCustomerRun(dir_, "python_can_notifier.yaml", "3C0");
}

TEST_F(VirtualTimeRun, AFirmwareThatNeverBlocksEndsTheRunWithItsThreadNamed) {
  Scenario s = LoadScenarioFile(kCustomerC);
  s.firmware.command += " --spin-after-s 0.5";
  s.timing.timeout_s = 1.0;
  const RunResult r = RunScenario(s, testing::BuildTreeRunOptions(dir_ / "spin"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.failure, HasSubstr("did not block within 1 s of wall time"));
  EXPECT_THAT(r.failure, HasSubstr("thread 'c_epoll_odometr'"));
  EXPECT_THAT(r.failure, HasSubstr("zero timeout"));
  const std::string events = Slurp(dir_ / "spin" / "events.jsonl");
  EXPECT_THAT(events, HasSubstr("\"firmware_busy\""));  // at half the limit
  EXPECT_THAT(events, HasSubstr("\"firmware_not_blocking\""));
  // What was recorded before stays: the start-up and half a second of cycles.
  EXPECT_THAT(Slurp(dir_ / "spin" / "can.log"), HasSubstr(" 3A0#"));
}

// A super loop (the main thread polls its epoll set with a zero timeout and never blocks) stops
// virtual time: the run fails naming the thread and the way out. With `timing.spin_cost_s` each
// empty poll costs that much virtual time: the firmware runs, produces its SYNC every 10 ms
// (late by at most the cost) and its runs are byte-identical.
TEST_F(VirtualTimeRun, ASuperLoopFirmwareRunsWithASpinCost) {
  Scenario s = LoadScenarioFile(kCustomerC);
  s.firmware.command += " --superloop 1";
  s.timing.duration_s = 2.0;
  s.expectations.clear();
  Scenario stuck = s;
  stuck.timing.timeout_s = 1.0;
  const RunResult r = RunScenario(stuck, testing::BuildTreeRunOptions(dir_ / "stuck"));
  EXPECT_THAT(r.failure, HasSubstr("zero timeout"));
  EXPECT_THAT(r.failure, HasSubstr("can run with timing.spin_cost_s"));
  s.timing.spin_cost_s = 5e-4;
  const auto [a, log] = RunTwiceSameBytes(s, dir_);
  ASSERT_EQ(a.failure, "");
  EXPECT_NEAR(a.report["cycles"].get<double>(), 200.0, 2.0);
  EXPECT_THAT(log, HasSubstr(" 3A0#"));
  EXPECT_LT(a.report["metrics"]["pose"]["final_position_error_m"].get<double>(), 0.01);
}

// A raw `nanosleep` (a `syscall` instruction of the firmware's own, as a Go runtime makes it) is
// not the library's: the run names the thread and the call (an event and a warning), once.
TEST_F(VirtualTimeRun, ATimedWaitThatBypassesTheLibraryIsNamed) {
  Scenario s = LoadScenarioFile(kCustomerC);
  s.firmware.command += " --raw-sleep-after-s 0.5";
  s.timing.duration_s = 1.5;
  s.expectations.clear();
  (void)RunScenario(s, testing::BuildTreeRunOptions(dir_ / "raw"));
  const std::string events = Slurp(dir_ / "raw" / "events.jsonl");
  EXPECT_THAT(events, HasSubstr("\"event\":\"firmware_host_clock_wait\""));
  EXPECT_THAT(events, HasSubstr("thread 'c_epoll_odometr'"));
  EXPECT_THAT(events, HasSubstr("is in nanosleep, a timed wait that bypassed"));
  std::size_t n = 0;
  for (auto at = events.find("firmware_host_clock_wait"); at != std::string::npos;
       at = events.find("firmware_host_clock_wait", at + 1)) {
    ++n;
  }
  EXPECT_EQ(n, 1u);  // (without the flag there is none: CustomerCFirmwareIsTheMaster...)
}

TEST(ClassifyKernelWait, TimedWaitsOnlyFromProcSyscallLines) {
  auto call = [](const std::string& line) {
    const firmware::HostClockWait w = firmware::ClassifyKernelWait(line);
    return w.call == nullptr ? std::string() : std::string(w.call);
  };
  const std::string tail = " 0x7ffd1000 0x7f001000";
  EXPECT_EQ(call("35 0x7ffd0000 0x0 0x0 0x0 0x0 0x0" + tail), "nanosleep");
  EXPECT_EQ(call("230 0x1 0x1 0x7ffd0000 0x0 0x0 0x0" + tail), "clock_nanosleep");
  // futex: FUTEX_WAIT_BITSET | PRIVATE with a timeout; without one; a wake.
  EXPECT_EQ(call("202 0x55550000 0x89 0x0 0x7ffd0000 0x0 0xffffffff" + tail), "futex");
  EXPECT_EQ(call("202 0x55550000 0x80 0x0 0x0 0x0 0x0" + tail), "");
  EXPECT_EQ(call("202 0x55550000 0x81 0x1 0x0 0x0 0x0" + tail), "");
  // poll / epoll_wait: -1 waits forever, a positive timeout is timed.
  EXPECT_EQ(call("7 0x7ffd0000 0x2 0xffffffff 0x0 0x0 0x0" + tail), "");
  EXPECT_EQ(call("7 0x7ffd0000 0x2 0x64 0x0 0x0 0x0" + tail), "poll");
  EXPECT_EQ(call("232 0x5 0x7ffd0000 0x1 0xffffffff 0x0 0x0" + tail), "");
  EXPECT_EQ(call("232 0x5 0x7ffd0000 0x1 0xa 0x0 0x0" + tail), "epoll_wait");
  EXPECT_EQ(call("271 0x7ffd0000 0x2 0x0 0x0 0x8 0x0" + tail), "");
  EXPECT_EQ(call("271 0x7ffd0000 0x2 0x7ffd2000 0x0 0x8 0x0" + tail), "ppoll");
  // Not in a system call, running, a read, garbage.
  EXPECT_EQ(call("-1 0x7ffd0000 0x7f001000"), "");
  EXPECT_EQ(call("running"), "");
  EXPECT_EQ(call("0 0x3 0x7ffd0000 0x10 0x0 0x0 0x0" + tail), "");
  EXPECT_EQ(call("35 0x7ffd"), "");
}

TEST_F(VirtualTimeRun, AFirmwareThatExitsEndsTheRunAtTheSameInstantEveryTime) {
  Scenario s = LoadScenarioFile(kCustomerC);
  s.firmware.command += " --exit-after-s 1.0";
  // Seen at the first instant after its exit: the same record (and failure) on every run.
  const auto [a, log] = RunTwiceSameBytes(s, dir_);
  EXPECT_EQ(a.exit_code, 1);
  EXPECT_THAT(a.failure, HasSubstr("the firmware exited with status 3 during the run"));
  EXPECT_EQ(Slurp(dir_ / "a" / "events.jsonl"), Slurp(dir_ / "b" / "events.jsonl"));
}

// A firmware that dies as soon as it opened the bus is said to have, not to have died before
// opening it.
TEST_F(VirtualTimeRun, AFirmwareThatDiesRightAfterOpeningTheBusIsSaidToHaveOpenedIt) {
  Scenario s = LoadScenarioFile(kCustomerC);
  s.firmware.command += " --abort-after-bind 1";
  const RunResult r = RunScenario(s, testing::BuildTreeRunOptions(dir_ / "abort"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.failure, HasSubstr("killed by signal 6 (SIGABRT) during the run"));
}

// A firmware that execs itself again without the clock library (keeping the bus library) runs
// on the host's clock from then on: the run names it (an event and a warning, once).
TEST_F(VirtualTimeRun, AFirmwareThatExecsWithoutTheClockLibraryIsNamed) {
  Scenario s = LoadScenarioFile(kCustomerC);
  s.firmware.command += " --reexec-without libwheelhil_vtime";
  s.timing.duration_s = 1.0;
  s.timing.timeout_s = 2.0;
  s.expectations.clear();
  (void)RunScenario(s, testing::BuildTreeRunOptions(dir_ / "reexec"));
  const std::string events = Slurp(dir_ / "reexec" / "events.jsonl");
  EXPECT_THAT(events, HasSubstr("\"event\":\"firmware_off_the_clock\""));
  EXPECT_THAT(events, HasSubstr("exec'd a program without libwheelhil_vtime.so (its LD_PRELOAD "
                                "no longer has it): it runs on the host's clock"));
  std::size_t n = 0;
  for (auto at = events.find("firmware_off_the_clock"); at != std::string::npos;
       at = events.find("firmware_off_the_clock", at + 1)) {
    ++n;
  }
  EXPECT_EQ(n, 1u);
}

// report.json's wall block says where the wall time went: the firmware's turns (at least one
// per SYNC it produces: each follows its timerfd), and the stages, which with the rest add up
// to the run's wall time.
TEST_F(VirtualTimeRun, TheWallBlockAccountsForHandoversAndStages) {
  Scenario s = LoadScenarioFile(kCustomerC);
  s.timing.duration_s = 1.0;
  s.expectations.clear();
  const RunResult r = RunScenario(s, testing::BuildTreeRunOptions(dir_ / "acct"));
  ASSERT_EQ(r.failure, "");
  const nlohmann::json& w = r.report["wall"];
  const auto handovers = w["handovers"].get<std::uint64_t>();
  EXPECT_GE(handovers, r.report["cycles"].get<std::uint64_t>());
  EXPECT_GT(r.report["cycles"].get<int>(), 90);
  const double virtual_s = w["virtual_s"].get<double>();
  EXPECT_GT(virtual_s, 1.0);
  EXPECT_DOUBLE_EQ(w["handovers_per_sim_s"].get<double>(), handovers / virtual_s);
  EXPECT_DOUBLE_EQ(w["handover_us_each"].get<double>(),
                   w["handover_s"].get<double>() / handovers * 1e6);
  double staged = 0;
  for (const char* k : {"handover_s", "physics_s", "devices_bus_s", "other_s"}) {
    EXPECT_GT(w[k].get<double>(), 0.0) << k;
    staged += w[k].get<double>();
  }
  staged += w["forecast_s"].get<double>();  // runahead's forecasts (none may have been made)
  EXPECT_NEAR(staged, w["wall_time_s"].get<double>(), 1e-6);
  ASSERT_TRUE(w["firmware_cpu_s"].is_number()) << w.dump();
  EXPECT_GE(w["firmware_cpu_s"].get<double>(), 0.0);
  ASSERT_TRUE(w["kernel_looks"].is_number()) << w.dump();
  ASSERT_TRUE(w["blocked_seen_in_kernel"].is_number()) << w.dump();
  // The start (world, devices, firmware, boot) is a part of the wall time.
  ASSERT_TRUE(w["before_motion_s"].is_number()) << w.dump();
  EXPECT_GT(w["before_motion_s"].get<double>(), 0.0);
  EXPECT_LT(w["before_motion_s"].get<double>(), w["wall_time_s"].get<double>());
}

// The waits of the C firmware (its epoll set of a timerfd, its reader thread's receive) are
// ones only the emulator can end, so it knows the firmware blocked without asking the kernel.
// The same firmware with a pipe in its epoll set (the self-pipe of a signal handler; never
// written in the run) waits where only the kernel knows: a look in /proc per turn or more.
// What it does is the same either way. On a busy machine either run looks in the kernel more
// (at threads woken but not yet run), but finds the firmware blocked there only with the pipe.
TEST_F(VirtualTimeRun, WaitsOnlyTheEmulatorCanEndNeedNoLookInTheKernel) {
  auto run = [&](const std::string& name, bool self_pipe) {
    Scenario s = LoadScenarioFile(kCustomerC);
    s.timing.duration_s = 1.0;
    s.expectations.clear();
    if (self_pipe) s.firmware.command += " --self-pipe 1";
    const RunResult r = RunScenario(s, testing::BuildTreeRunOptions(dir_ / name));
    EXPECT_EQ(r.failure, "") << name;
    return r.report["wall"];
  };
  const nlohmann::json vouched = run("vouched", false);
  const nlohmann::json piped = run("piped", true);
  const auto turns = vouched["handovers"].get<double>();
  ASSERT_GT(turns, 100);
  EXPECT_LT(vouched["blocked_seen_in_kernel"].get<double>(), 0.2 * turns) << vouched.dump();
  EXPECT_GT(piped["blocked_seen_in_kernel"].get<double>(), 0.9 * piped["handovers"].get<double>())
      << piped.dump();
  EXPECT_GE(piped["kernel_looks"].get<double>(), piped["blocked_seen_in_kernel"].get<double>());
  EXPECT_EQ(Slurp(dir_ / "vouched" / "can.log"), Slurp(dir_ / "piped" / "can.log"));
  EXPECT_EQ(Slurp(dir_ / "vouched" / "estimate.csv"), Slurp(dir_ / "piped" / "estimate.csv"));
}

// --stop-at: the firmware is stopped at a virtual instant; gdb (batch mode) attaches, breaks in
// the C firmware's frame handler, prints a variable and detaches; virtual time waited for it
// all along, so verdict, can.log and estimate.csv are those of a run without the debugger.
TEST_F(VirtualTimeRun, AFirmwareStoppedForADebuggerIsWaitedForAndChangesNothing) {
  if (std::system("command -v gdb >/dev/null 2>&1") != 0) GTEST_SKIP() << "no gdb";
  auto run = [&](const std::string& name, bool debug, std::string* gdb_out) {
    Scenario s = LoadScenarioFile(kCustomerC);
    s.timing.duration_s = 1.0;
    s.expectations.clear();
    RunOptions o = testing::BuildTreeRunOptions(dir_ / name);
    std::thread gdb;
    if (debug) {
      o.stop_firmware_at_ns = 800'000'000;
      o.on_firmware_stopped = [&](pid_t pid) {
        gdb = std::thread([pid, gdb_out] {
          const std::string cmd = fmt::format(
              "gdb -p {} -batch -ex 'handle SIG64 nostop noprint pass' "
              "-ex 'break c_epoll_odometry.c:87' -ex continue "
              "-ex 'print g_nodes[0].have_position' -ex delete -ex detach 2>&1",
              pid);
          *gdb_out = test_support::CommandOutput(cmd);
          ::kill(-pid, SIGCONT);  // as the printed hint says, should the detach leave it stopped
        });
      };
    }
    const RunResult r = RunScenario(s, o);
    if (gdb.joinable()) gdb.join();
    return r;
  };
  std::string gdb_out;
  const RunResult plain = run("plain", false, nullptr);
  const RunResult debugged = run("debugged", true, &gdb_out);
  if (gdb_out.find("ptrace: Operation not permitted") != std::string::npos) {
    GTEST_SKIP() << "this host does not let gdb attach (ptrace scope): " << gdb_out;
  }
  ASSERT_EQ(plain.failure, "");
  ASSERT_EQ(debugged.failure, "") << gdb_out;
  EXPECT_THAT(gdb_out, HasSubstr("Breakpoint 1 at"));
  EXPECT_THAT(gdb_out, HasSubstr("$1 = 1")) << gdb_out;  // the encoders' TPDOs are coming in
  EXPECT_THAT(gdb_out, HasSubstr("detached"));
  EXPECT_EQ(debugged.report["verdict"], plain.report["verdict"]);
  EXPECT_EQ(debugged.report["metrics"], plain.report["metrics"]);
  for (const char* f : {"can.log", "estimate.csv", "truth.csv"}) {
    EXPECT_EQ(Slurp(dir_ / "debugged" / f), Slurp(dir_ / "plain" / f)) << f;
  }
  EXPECT_THAT(Slurp(dir_ / "debugged" / "events.jsonl"),
              HasSubstr("\"event\":\"firmware_stopped\""));
}

// --stop-at needs the virtual clock: in real time the run is refused with why.
TEST_F(VirtualTimeRun, StopAtOffTheVirtualClockIsRefused) {
  Scenario s = LoadScenarioFile(kCustomerC);
  RunOptions o = testing::BuildTreeRunOptions(dir_ / "wall");
  o.realtime = true;
  o.stop_firmware_at_ns = 1'000'000'000;
  EXPECT_THAT([&] { (void)RunScenario(s, o); },
              ThrowsMessage<std::invalid_argument>(
                  HasSubstr("--stop-at stops the firmware on the virtual clock, which this run "
                            "does not have")));
}

// A run on the virtual clock leaves nothing in the temporary directory: its private bus, clock
// page and whatever the firmware put there go with it.
TEST_F(VirtualTimeRun, ARunLeavesNothingInTheTemporaryDirectory) {
  Scenario s = LoadScenarioFile(kCustomerC);
  s.timing.duration_s = 0.5;
  s.expectations.clear();
  const fs::path tmp = dir_ / "tmp";
  fs::create_directories(tmp);
  const char* old = std::getenv("TMPDIR");
  const std::string saved = old != nullptr ? old : "";
  ::setenv("TMPDIR", tmp.c_str(), 1);
  const RunResult r = RunScenario(s, testing::BuildTreeRunOptions(dir_ / "out"));
  if (old != nullptr) {
    ::setenv("TMPDIR", saved.c_str(), 1);
  } else {
    ::unsetenv("TMPDIR");
  }
  EXPECT_EQ(r.failure, "");
  std::vector<std::string> left;
  for (const auto& e : fs::directory_iterator(tmp)) left.push_back(e.path().filename().string());
  EXPECT_THAT(left, ::testing::IsEmpty());
}

// The same firmware and scenario in real time (`--realtime`): nothing preloaded but the bus, the
// firmware on the host's clock, and still the only SYNC producer.
TEST_F(VirtualTimeRun, CustomerCFirmwareRunsUnchangedInRealTime) {
  Scenario s = LoadScenarioFile(kCustomerC);
  s.timing.duration_s = 1.5;
  RunOptions o = testing::BuildTreeRunOptions(dir_ / "rt");
  o.realtime = true;
  const RunResult r = RunScenario(s, o);
  ASSERT_EQ(r.failure, "");
  const std::string log = Slurp(dir_ / "rt" / "can.log");
  EXPECT_THAT(log, HasSubstr(" 000#0100"));
  EXPECT_THAT(log, HasSubstr(" 3A0#"));
  // Every SYNC is the firmware's (10 ms): about 1.5 s / 10 ms of motion after its start-up.
  const int syncs = r.report["cycles"].get<int>();
  EXPECT_GT(syncs, 100);
  EXPECT_LT(syncs, 260);
  std::size_t in_log = 0;
  for (std::size_t at = log.find(" 080#"); at != std::string::npos;
       at = log.find(" 080#", at + 1)) {
    ++in_log;
  }
  // `cycles` counts the motion phase's; the log has the start-up's too (under 1 s of them).
  EXPECT_GE(in_log + 1, static_cast<std::size_t>(syncs));  // the last may still be on the wire
  EXPECT_LE(in_log, static_cast<std::size_t>(syncs) + 100);
}

TEST_F(VirtualTimeRun, ReferenceFirmwareProducesSyncWithItsShippedConfig) {
  Scenario s = LoadScenarioFile(std::string(WHEELHIL_SOURCE_DIR) +
                                "/scenarios/smoke/paper000_slip_short.yaml");
  s.timing.firmware_produces_sync = true;
  const auto [a, log] = RunTwiceSameBytes(s, dir_);
  ASSERT_EQ(a.failure, "");
  EXPECT_EQ(a.exit_code, 0) << a.report["expectations"].dump();
  EXPECT_EQ(testing::ReportWithoutWall(dir_ / "a"), testing::ReportWithoutWall(dir_ / "b"));
  // Its config went through unchanged: it produces SYNC and keeps its cycle deadline.
  const std::string cfg = Slurp(dir_ / "a" / "firmware_config.yaml");
  EXPECT_THAT(cfg, HasSubstr("produce: true"));
  EXPECT_THAT(cfg, HasSubstr("deadline_s: 0.2"));
  EXPECT_EQ(a.report["cycles"].get<int>(), 38);  // 9.5 s at 4 Hz
}

// Every shipped paper and suspension scenario with the reference firmware as SYNC producer on the
// virtual clock (its shipped config, the scenario's own overrides) meets its expectations. The
// Release build only (as the golden artefacts): the sanitizer build checks memory, not results.
TEST_F(VirtualTimeRun, ShippedScenariosMeetTheirExpectationsWithTheFirmwareProducingSync) {
#ifdef WHEELHIL_SANITIZED
  GTEST_SKIP() << "results are checked in the Release build";
#endif
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(std::string(WHEELHIL_SOURCE_DIR) + "/scenarios")) {
    if (e.path().extension() == ".yaml") files.push_back(e.path());
  }
  std::sort(files.begin(), files.end());
  ASSERT_GE(files.size(), 15u);
  for (const auto& f : files) {
    Scenario s = LoadScenarioFile(f.string());
    s.timing.firmware_produces_sync = true;
    const RunResult r = RunScenario(s, testing::BuildTreeRunOptions(dir_ / f.stem()));
    EXPECT_EQ(r.failure, "") << f.filename();
    EXPECT_EQ(r.exit_code, 0) << f.filename() << ": " << r.report["expectations"].dump();
  }
}

TEST_F(VirtualTimeRun, AStaticFirmwareIsRefusedBeforeTheRun) {
  Scenario s = LoadScenarioFile(kCustomerC);
  s.firmware.command = std::string(WHEELHIL_BINARY_DIR) + "/bin/vtime_probe_static sleeps";
  EXPECT_THROW(
      {
        try {
          RunScenario(s, testing::BuildTreeRunOptions(dir_ / "static"));
        } catch (const std::invalid_argument& e) {
          EXPECT_THAT(e.what(), HasSubstr("statically linked"));
          throw;
        }
      },
      std::invalid_argument);
}

}  // namespace
}  // namespace wheelhil::emulator::scenario
