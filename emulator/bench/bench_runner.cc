#include "emulator/bench/bench_runner.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <thread>

#include <fmt/format.h>

#include "bus/ucan_runtime_dir.h"
#include "emulator/bench/bench_report.h"
#include "emulator/bench/bench_workloads.h"
#include "emulator/campaign/campaign_spec.h"
#include "emulator/campaign/scenario_writer.h"
#include "emulator/firmware/process_scope.h"
#include "emulator/scenario/scenario.h"

namespace wheelhil::emulator::bench {
namespace {

// How long a worker may take (RunBench sets it: --quick runs are short); a guest boot more.
double g_worker_limit_s = 900.0;

std::string WorkerStatus(int status) {
  if (WIFEXITED(status)) return fmt::format("exit code {}", WEXITSTATUS(status));
  if (WIFSIGNALED(status)) return fmt::format("killed by signal {}", WTERMSIG(status));
  return "stopped";
}

std::vector<std::string> CommonWorkerArgs(const BenchOptions& o, const std::string& self_exe,
                                          const std::string& name) {
  std::vector<std::string> argv = {self_exe, "bench",        "--worker",
                                   name,     "--source-dir", o.source_dir};
  if (o.quick) argv.push_back("--quick");
  if (!o.sched_fifo) argv.push_back("--no-rt");
  argv.push_back("--fifo-priority");
  argv.push_back(std::to_string(o.fifo_priority));
  argv.push_back("--cpu");
  argv.push_back(std::to_string(o.cpu));
  argv.push_back("--bus-cpu");
  argv.push_back(std::to_string(o.bus_cpu));
  argv.push_back("--spin-us");
  argv.push_back(fmt::format("{}", o.spin_us));
  argv.push_back("--load-threads");
  argv.push_back(std::to_string(o.load_threads));
  return argv;
}

/// The paper's reference scenario (paper000_slip.yaml, paper001_forward_T10.yaml,
/// paper002_velocity.yaml) when it exists, else scenarios/<name>*.yaml, the first in name order;
/// empty when there is none.
std::string FindScenarioFile(const std::string& source_dir, const std::string& name) {
  const std::vector<std::pair<std::string, std::string>> preferred = {
      {"paper000", "paper000_slip.yaml"},
      {"paper001", "paper001_forward_T10.yaml"},
      {"paper002", "paper002_velocity.yaml"}};
  for (const auto& [paper, file] : preferred) {
    const std::string path = source_dir + "/scenarios/" + file;
    if (paper == name && std::filesystem::is_regular_file(path)) return path;
  }
  std::vector<std::string> found;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(source_dir + "/scenarios", ec)) {
    const std::string file = e.path().filename().string();
    if (e.is_regular_file() && file.rfind(name, 0) == 0 && e.path().extension() == ".yaml") {
      found.push_back(e.path().string());
    }
  }
  std::sort(found.begin(), found.end());
  return found.empty() ? std::string() : found.front();
}

/// Motion phase of every lockstep run with --quick (timing.duration_s of a cut copy), s.
constexpr double kQuickLockstepSimS = 1.0;

std::string SelfExePath() {
  std::error_code ec;
  const std::filesystem::path p = std::filesystem::read_symlink("/proc/self/exe", ec);
  return ec ? std::string("wheelhil") : p.string();
}

/// One lockstep run.
struct LockstepRun {
  nlohmann::json rtf;  ///< wall.real_time_factor of its report.json, or "unavailable: <why>".
  nlohmann::json sim_s;
  /// Where its wall time went: the hand-over counts and the stages' seconds of its report's
  /// wall block (docs/performance.md), null when the run gave no figure.
  nlohmann::json accounts;
  double max_rss_mib = 0.0;
};

/// The accounting part of a report's wall block.
nlohmann::json Accounts(const nlohmann::json& wall) {
  nlohmann::json out = nlohmann::json::object();
  for (const char* key : {"handovers", "handovers_per_sim_s", "handover_us_each", "handover_s",
                          "firmware_cpu_s", "physics_s", "devices_bus_s", "other_s",
                          "wall_time_s"}) {
    if (wall.contains(key)) out[key] = wall[key];
  }
  return out;
}

/// `<self_exe> run <file> --out <tmp> --quiet [--can <iface>]`: the scenario with its reference
/// firmware in the loop, on `iface` (a kernel interface) or, when empty, on the run's private
/// userspace bus. With --quick the run is a copy of the scenario whose motion phase is cut to
/// kQuickLockstepSimS (written like a campaign run's). A run that reports a failure (e.g. the
/// firmware never answered) gives that failure as the reason, never a number.
/// The run's clock, named as the rows say it: the firmware's virtual clock, the firmware the
/// SYNC producer (its shipped config).
std::vector<campaign::Override> VirtualClockOverrides() {
  return {{"timing.clock", "virtual", 0}, {"timing.sync_producer", "firmware", 0}};
}

LockstepRun RunLockstepScenario(const BenchOptions& o, const std::string& self_exe,
                                const std::string& file, const std::string& iface,
                                const std::vector<campaign::Override>& overrides = {}) {
  LockstepRun out;
  const std::string what =
      fmt::format("`wheelhil run {}{}`", std::filesystem::path(file).filename().string(),
                  iface.empty() ? "" : " --can " + iface);
  std::string dir;
  try {
    dir = bus::CreateTempUcanRuntimeDir("wheelhil-bench-run-");
  } catch (const std::exception& e) {
    out.rtf = Unavailable(e.what());
    return out;
  }
  std::string scenario = file;
  if (o.quick || !overrides.empty()) {
    try {
      campaign::CampaignSpec spec;
      spec.file = file;
      spec.name = "bench_quick_lockstep";
      spec.base_scenario = std::filesystem::absolute(file);
      spec.overrides = overrides;
      if (o.quick) spec.overrides.push_back({"timing.duration_s", kQuickLockstepSimS, 0});
      scenario = dir + "/scenario.yaml";
      campaign::WriteRunScenario(spec, campaign::RunSpec{}, scenario);
    } catch (const std::exception& e) {
      out.rtf = Unavailable(fmt::format("cannot cut {} for --quick: {}", file, e.what()));
      scenario.clear();
    }
  }
  if (!scenario.empty()) {
    std::vector<std::string> argv = {self_exe, "run", scenario, "--out", dir + "/run", "--quiet"};
    if (!iface.empty()) {
      argv.push_back("--can");
      argv.push_back(iface);
    }
    const WorkerOutcome w = RunWorkerProcess(argv, {}, /*expect_json=*/false);
    nlohmann::json run_report;
    std::ifstream in(dir + "/run/report.json");
    try {
      if (in) run_report = nlohmann::json::parse(in);
    } catch (const std::exception&) {
      run_report = nlohmann::json();
    }
    const nlohmann::json* rtf = GetPath(run_report, "wall.real_time_factor");
    const nlohmann::json* failure = GetPath(run_report, "failure");
    if (failure && failure->is_string()) {
      out.rtf = Unavailable(fmt::format("{} failed: {}", what, failure->get<std::string>()));
    } else if (rtf && rtf->is_number() && rtf->get<double>() > 0) {
      out.rtf = rtf->get<double>();
      if (const nlohmann::json* wall = GetPath(run_report, "wall"); wall && wall->is_object()) {
        out.accounts = Accounts(*wall);
      }
      const nlohmann::json* sim = GetPath(run_report, "sim_time_s");
      if (sim && sim->is_number()) out.sim_s = *sim;
      out.max_rss_mib = w.max_rss_mib;
    } else {
      out.rtf = Unavailable(fmt::format("{} gave no real_time_factor ({})", what,
                                        w.problem.empty() ? "no report.json" : w.problem));
    }
  }
  std::error_code ec;
  std::filesystem::remove_all(dir, ec);
  return out;
}

/// `num / den` as the row `key` when both are positive numbers, else unavailable (`needs`).
void SetRatio(nlohmann::json& report, const std::string& key, const nlohmann::json* num,
              const nlohmann::json* den, const std::string& needs) {
  if (num != nullptr && den != nullptr && num->is_number() && den->is_number() &&
      den->get<double>() > 0) {
    SetPath(report, key, num->get<double>() / den->get<double>());
  } else {
    SetPath(report, key, Unavailable(needs));
  }
}

/// The physics row of a scenario's platform and floor ("physics.diff2.flat_rtf"); empty when
/// the file does not load or its platform has no physics row.
std::string PhysicsRowOf(const std::string& scenario_file) {
  try {
    const scenario::Scenario s = scenario::LoadScenarioFile(scenario_file);
    const auto& platforms = BenchPlatforms();
    if (std::find(platforms.begin(), platforms.end(), s.platform.name) == platforms.end()) {
      return "";
    }
    return fmt::format("physics.{}.{}_rtf", s.platform.name,
                       s.terrain.meshes.empty() ? "flat" : "mesh");
  } catch (const std::exception&) {
    return "";
  }
}

/// virtual_time.<row>.wall (the run's accounting) and its documented hand-over figures: the
/// run's numbers, else the run's reason (or that its report had none).
void SetHandoverRows(nlohmann::json& report, const std::string& row, const LockstepRun& r) {
  if (!r.accounts.is_null()) SetPath(report, fmt::format("virtual_time.{}.wall", row), r.accounts);
  for (const char* key : HandoverAccountKeys()) {
    nlohmann::json v;
    if (r.accounts.is_object() && r.accounts.contains(key) && r.accounts[key].is_number()) {
      v = r.accounts[key];
    } else if (r.rtf.is_string()) {
      v = r.rtf;
    } else {
      v = Unavailable(fmt::format("report.json had no wall.{}", key));
    }
    SetPath(report, fmt::format("virtual_time.{}.{}", row, key), v);
  }
}

/// The lockstep rows over the private userspace bus: lockstep.<paper>.rtf (and .scenario,
/// .sim_s) and rss.lockstep_mib.
void RunLockstep(const BenchOptions& o, const std::string& self_exe, const std::string& unavailable,
                 nlohmann::json& report, double& peak_mib) {
  double lockstep_mib = 0.0;
  for (const auto& s : BenchScenarios()) {
    const std::string key = fmt::format("lockstep.{}.rtf", s);
    if (!unavailable.empty()) {
      SetPath(report, key, Unavailable(unavailable));
      continue;
    }
    const std::string file = FindScenarioFile(o.source_dir, s);
    if (file.empty()) {
      SetPath(report, key, Unavailable(fmt::format("no scenario file scenarios/{}*.yaml yet", s)));
      continue;
    }
    const LockstepRun r = RunLockstepScenario(o, self_exe, file, "", VirtualClockOverrides());
    SetPath(report, key, r.rtf);
    if (r.rtf.is_number()) {
      SetPath(report, fmt::format("lockstep.{}.scenario", s),
              std::filesystem::path(file).filename().string());
      if (r.sim_s.is_number()) SetPath(report, fmt::format("lockstep.{}.sim_s", s), r.sim_s);
      if (!r.accounts.is_null()) SetPath(report, fmt::format("lockstep.{}.wall", s), r.accounts);
      lockstep_mib = std::max(lockstep_mib, r.max_rss_mib);
    }
    // Its hand-over accounting and its ratio to the physics alone, for the papers the goals
    // name.
    const std::string vkey = fmt::format("virtual_time.{}.rtf", s);
    if (std::find(VirtualTimeBenchScenarios().begin(), VirtualTimeBenchScenarios().end(), s) !=
        VirtualTimeBenchScenarios().end()) {
      const LockstepRun& v = r;
      SetPath(report, vkey, v.rtf);
      SetHandoverRows(report, s, v);
      const std::string physics_row = PhysicsRowOf(file);
      SetRatio(report, fmt::format("virtual_time.{}.vs_physics_alone", s), &v.rtf,
               physics_row.empty() ? nullptr : GetPath(report, physics_row),
               physics_row.empty() ? "no physics row for the scenario's platform"
                                   : "needs " + physics_row);
    }
  }
  // Firmwares written as customers write them (tests/customer_firmware/, built in the build tree
  // only), on the virtual clock.
  for (const auto& [key, name] : {std::pair<std::string, std::string>{"customer_c",
                                                                        "c_epoll_odometry"},
                                  {"customer_python", "python_can_odometry"}}) {
    const std::string row = fmt::format("virtual_time.{}.rtf", key);
    const std::string file = o.source_dir + "/tests/data/customer_firmware/" + name + ".yaml";
    LockstepRun c;
    if (!unavailable.empty()) {
      c.rtf = Unavailable(unavailable);
    } else if (!std::filesystem::exists(file)) {
      c.rtf = Unavailable("no " + file + " (a source tree is needed)");
    } else if (name == "c_epoll_odometry" &&
               !std::filesystem::exists(std::filesystem::path(self_exe).parent_path() / name)) {
      c.rtf = Unavailable("no " + name + " next to wheelhil (a build tree is needed)");
    } else {
      // Whole (5 s of motion): a cut copy would move the file that ${SCENARIO_DIR} names.
      BenchOptions whole = o;
      whole.quick = false;
      c = RunLockstepScenario(whole, self_exe, file, "");
    }
    SetPath(report, row, c.rtf);
    SetHandoverRows(report, key, c);
  }
  if (lockstep_mib > 0) {
    SetPath(report, "rss.lockstep_mib", lockstep_mib);
    peak_mib = std::max(peak_mib, lockstep_mib);
  } else {
    SetPath(report, "rss.lockstep_mib",
            Unavailable(unavailable.empty() ? "no lockstep run completed" : unavailable));
  }
}

/// The lockstep rows on the kernel interface `iface`: lockstep.<paper>.vcan_rtf (.vcan_sim_s)
/// and, with also_ucan, lockstep.<paper>.uml_ucan_rtf: the same run on the private userspace
/// bus in the same kernel (inside the user-mode-linux guest, the figure to compare with).
nlohmann::json LockstepOnKernelBus(const BenchOptions& o, const std::string& self_exe,
                                   const std::string& iface, bool also_ucan) {
  nlohmann::json report = nlohmann::json::object();
  for (const auto& s : BenchScenarios()) {
    const std::string file = FindScenarioFile(o.source_dir, s);
    if (file.empty()) {
      const std::string why = fmt::format("no scenario file scenarios/{}*.yaml yet", s);
      SetPath(report, fmt::format("lockstep.{}.vcan_rtf", s), Unavailable(why));
      if (also_ucan) SetPath(report, fmt::format("lockstep.{}.uml_ucan_rtf", s), Unavailable(why));
      continue;
    }
    // Both rows on the firmware's virtual clock, as the lockstep rows.
    const std::vector<campaign::Override> virtual_clock = VirtualClockOverrides();
    const LockstepRun k = RunLockstepScenario(o, self_exe, file, iface, virtual_clock);
    SetPath(report, fmt::format("lockstep.{}.vcan_rtf", s), k.rtf);
    if (k.sim_s.is_number()) SetPath(report, fmt::format("lockstep.{}.vcan_sim_s", s), k.sim_s);
    if (also_ucan) {
      SetPath(report, fmt::format("lockstep.{}.uml_ucan_rtf", s),
              RunLockstepScenario(o, self_exe, file, "", virtual_clock).rtf);
    }
  }
  return report;
}

/// lockstep.<paper>.vcan_rtf and lockstep.vcan_environment: on the host's vcan0 when it has
/// one, else with --uml inside one user-mode-linux guest for all three runs (`bench --worker
/// lockstep-kernel` run by tests/vcan/uml_run.sh), else unavailable with the reason.
void RunLockstepVcan(const BenchOptions& o, const std::string& self_exe,
                     const std::string& unavailable, nlohmann::json& report) {
  auto all_unavailable = [&](const std::string& why) {
    for (const auto& s : BenchScenarios()) {
      SetPath(report, fmt::format("lockstep.{}.vcan_rtf", s), Unavailable(why));
    }
    SetPath(report, "lockstep.vcan_environment", "none");
  };
  if (!unavailable.empty()) {
    all_unavailable(unavailable);
  } else if (std::filesystem::exists("/sys/class/net/vcan0")) {
    report.merge_patch(LockstepOnKernelBus(o, self_exe, "vcan0", /*also_ucan=*/false));
    SetPath(report, "lockstep.vcan_environment", "host kernel vcan0");
  } else if (!o.uml) {
    all_unavailable(
        "no kernel vcan0 on this machine; `wheelhil bench --uml` runs these inside the "
        "user-mode-linux test kernel");
  } else {
    std::vector<std::string> argv = {o.source_dir + "/tests/vcan/uml_run.sh",
                                     "--timeout",
                                     o.quick ? "300" : "1200",
                                     "--",
                                     self_exe,
                                     "bench",
                                     "--worker",
                                     "lockstep-kernel",
                                     "--source-dir",
                                     o.source_dir};
    if (o.quick) argv.push_back("--quick");
    const WorkerOutcome w = RunWorkerProcess(argv, {});
    for (const auto& s : BenchScenarios()) {
      const std::string key = fmt::format("lockstep.{}.vcan_rtf", s);
      if (!GetPath(w.report, key)) {
        SetPath(report, key,
                Unavailable("user-mode-linux: " + (w.problem.empty() ? "no figure" : w.problem)));
      }
    }
    report.merge_patch(w.report);
    SetPath(report, "lockstep.vcan_environment",
            "vcan0 inside the user-mode-linux test kernel (tests/vcan/uml_run.sh, one guest for "
            "the three runs): UML traps every system call, so compare with "
            "lockstep.<paper>.uml_ucan_rtf, the userspace bus in the same guest");
  }
}

/// Campaign throughput (issue goal: >= 5 runs/s for 10 s paper-000 runs on 2 cores): a
/// campaign of repeats of scenarios/paper000_slip.yaml cut to 10 s, run by `wheelhil campaign`
/// with one job per core, each run on its own private bus with the reference firmware.
/// runs_per_s = runs that left a report.json / wall time of the whole campaign command.
void RunCampaignThroughput(const BenchOptions& o, const std::string& self_exe,
                           const std::string& unavailable, nlohmann::json& report) {
  const std::string key = "campaign.paper000_runs_per_s";
  if (!unavailable.empty()) {
    SetPath(report, key, Unavailable(unavailable));
    return;
  }
  const std::string base = o.source_dir + "/scenarios/paper000_slip.yaml";
  if (!std::filesystem::is_regular_file(base)) {
    SetPath(report, key, Unavailable("no scenarios/paper000_slip.yaml"));
    return;
  }
  std::string dir;
  try {
    dir = bus::CreateTempUcanRuntimeDir("wheelhil-bench-campaign-");
  } catch (const std::exception& e) {
    SetPath(report, key, Unavailable(e.what()));
    return;
  }
  const int runs = o.quick ? 4 : 20;
  const int jobs = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  const double run_sim_s = 10.0;
  {
    std::ofstream f(dir + "/campaign.yaml");
    f << "campaign: bench_paper000_throughput\n"
      << "base: " << nlohmann::json(base).dump() << "\n"
      << "sampling: grid\nseed: 1\n"
      << "repeats: " << runs << "\ntimeout_s: 300\n"
      << "set:\n  timing.duration_s: " << run_sim_s << "\n"
      << "parameters:\n  - path: terrain.friction.mu_slide\n    values: [0.7]\n";
  }
  const auto t0 = std::chrono::steady_clock::now();
  const WorkerOutcome w =
      RunWorkerProcess({self_exe, "campaign", dir + "/campaign.yaml", "--jobs",
                        std::to_string(jobs), "--out", dir + "/out", "--quiet", "--no-html"},
                       {}, /*expect_json=*/false);
  const double wall_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  int finished = 0;
  std::error_code ec;
  for (auto it = std::filesystem::recursive_directory_iterator(dir + "/out", ec);
       !ec && it != std::filesystem::recursive_directory_iterator(); it.increment(ec)) {
    if (it->path().filename() == "report.json") ++finished;
  }
  if (finished == runs && wall_s > 0) {
    SetPath(report, key, finished / wall_s);
    SetPath(report, "campaign.paper000_runs", finished);
    SetPath(report, "campaign.paper000_jobs", jobs);
    SetPath(report, "campaign.paper000_run_sim_s", run_sim_s);
  } else {
    // A campaign whose runs fail their expectations still counts; runs without a report do not.
    SetPath(report, key,
            Unavailable(fmt::format("{} of {} campaign runs left a report.json ({})", finished,
                                    runs, w.problem.empty() ? "no problem reported" : w.problem)));
  }
  std::filesystem::remove_all(dir, ec);
}

// The documented keys (bench_report.h: what --check holds a report to) under `prefix`, minus
// those under `except`: what a worker must fill, or mark unavailable when it fails.
std::vector<std::string> DocumentedKeysUnder(const std::string& prefix,
                                             const std::string& except = "") {
  std::vector<std::string> out;
  for (const auto& keys : {DocumentedMetricKeys(), DocumentedTextKeys()}) {
    for (const auto& k : keys) {
      if (k.rfind(prefix, 0) == 0 && (except.empty() || k.rfind(except, 0) != 0)) {
        out.push_back(k);
      }
    }
  }
  return out;
}

}  // namespace

WorkerOutcome RunWorkerProcess(const std::vector<std::string>& argv,
                               const std::vector<std::pair<std::string, std::string>>& extra_env,
                               bool expect_json, double limit_s) {
  WorkerOutcome out;
  // Everything the child needs is built before fork (no allocation between fork and exec).
  std::vector<std::string> env_strings = firmware::EnvironmentWith(extra_env);
  std::vector<char*> envp, args;
  for (auto& s : env_strings) envp.push_back(s.data());
  envp.push_back(nullptr);
  std::vector<std::string> argv_copy = argv;
  for (auto& s : argv_copy) args.push_back(s.data());
  args.push_back(nullptr);

  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0) {
    out.problem = fmt::format("pipe: {}", std::strerror(errno));
    return out;
  }
  const pid_t pid = ::fork();
  if (pid < 0) {
    out.problem = fmt::format("fork: {}", std::strerror(errno));
    ::close(fds[0]);
    ::close(fds[1]);
    return out;
  }
  if (pid == 0) {
    ::setpgid(0, 0);  // its own group: a worker that overstays goes with what it started
    ::dup2(fds[1], STDOUT_FILENO);
    ::execve(args[0], args.data(), envp.data());
    ::_exit(127);
  }
  ::close(fds[1]);
  // A worker that hangs (a run that never ends) costs its row, not the bench.
  if (limit_s <= 0) limit_s = argv[0].ends_with("uml_run.sh") ? 900.0 : g_worker_limit_s;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(limit_s);
  bool overstayed = false;
  std::string text;
  char buf[4096];
  while (true) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - std::chrono::steady_clock::now());
    pollfd p{fds[0], POLLIN, 0};
    const int ready = ::poll(&p, 1, static_cast<int>(std::max<std::int64_t>(0, left.count())));
    if (ready == 0) {
      overstayed = true;
      ::kill(-pid, SIGKILL);
      ::kill(pid, SIGKILL);
      break;
    }
    if (ready < 0 && errno == EINTR) continue;
    const ssize_t n = ::read(fds[0], buf, sizeof(buf));
    if (n > 0) {
      text.append(buf, static_cast<std::size_t>(n));
    } else if (n == 0 || errno != EINTR) {
      break;
    }
  }
  ::close(fds[0]);
  int status = 0;
  rusage usage{};
  while (::wait4(pid, &status, 0, &usage) < 0 && errno == EINTR) {
  }
  if (overstayed) {
    out.problem = fmt::format(
        "`{}` did not finish within {:g} s of wall time (killed)",
        fmt::join(std::vector<std::string>(argv.begin() + 1, argv.end()), " "), limit_s);
    fmt::print(stderr, "wheelhil bench: {}\n", out.problem);
    return out;
  }
  out.max_rss_mib = static_cast<double>(usage.ru_maxrss) / 1024.0;  // ru_maxrss is in KiB
  // The JSON is the last line that starts with '{' (a UML guest prints boot lines first).
  std::size_t end = text.size();
  while (end > 0) {
    std::size_t begin = text.rfind('\n', end - 1);
    begin = begin == std::string::npos ? 0 : begin + 1;
    if (text.compare(begin, 1, "{") == 0) {
      try {
        out.report = nlohmann::json::parse(text.substr(begin, end - begin));
      } catch (const std::exception& e) {
        out.problem = fmt::format("worker output is not JSON: {}", e.what());
      }
      break;
    }
    if (begin == 0) break;
    end = begin - 1;
  }
  const bool ok = WIFEXITED(status) && WEXITSTATUS(status) == 0;
  if (!ok && out.problem.empty()) {
    // tests/vcan/uml_run.sh says why it cannot boot the guest on a "SKIP: <reason>" line.
    const std::size_t skip = text.rfind("SKIP: ");
    const auto worker = std::find(argv.begin(), argv.end(), "--worker");
    if (skip != std::string::npos && (skip == 0 || text[skip - 1] == '\n')) {
      out.problem = text.substr(skip, text.find('\n', skip) - skip);
    } else {
      out.problem =
          fmt::format("worker {} failed ({})",
                      worker != argv.end() && worker + 1 != argv.end() ? *(worker + 1) : argv[0],
                      WorkerStatus(status));
    }
  } else if (ok && expect_json && out.report.empty() && out.problem.empty()) {
    out.problem = "worker printed no JSON";
  }
  return out;
}

nlohmann::json RunWorker(const std::string& name, const BenchOptions& o) {
  const double case_s = o.quick ? 0.15 : 1.5;
  if (name == "physics") return RunPhysicsWorkload(o.source_dir, case_s);
  if (name == "peers") return RunPeersWorkload(o.source_dir, o.quick ? 1 : 3);
  if (name == "bus-ucan") return RunBusWorkload("ucan", o.quick ? 0.3 : 2.0);
  if (name == "bus-vcan") return RunBusWorkload("vcan", o.quick ? 0.3 : 2.0);
  if (name == "realtime" || name == "realtime-loaded") {
    RealtimeWorkloadOptions r;
    r.source_dir = o.source_dir;
    r.duration_s = o.quick ? 1.0 : 10.0;
    r.sched_fifo = o.sched_fifo;
    r.fifo_priority = o.fifo_priority;
    r.cpu = o.cpu;
    r.pipeline_cpu = o.bus_cpu;
    r.spin_us = o.spin_us;
    r.bare_timer_s = o.quick ? 0.2 : 1.0;
    if (name == "realtime-loaded") {
      r.prefix = "realtime.loaded_";
      r.load_threads = o.load_threads >= 0
                           ? o.load_threads
                           : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
    }
    return RunRealtimeWorkload(r);
  }
  if (name == "lockstep-kernel") {
    // In the user-mode-linux guest (uml_run.sh sets WHEELHIL_VCAN, WHEELHIL_UML) or on a host
    // kernel with vcan0. The userspace-bus runs for comparison in the guest are left out of
    // --quick (they would double its time).
    const char* iface = std::getenv("WHEELHIL_VCAN");
    return LockstepOnKernelBus(o, SelfExePath(), iface && *iface ? iface : "vcan0",
                               /*also_ucan=*/std::getenv("WHEELHIL_UML") != nullptr && !o.quick);
  }
  if (name == "lockstep-vcan") {
    nlohmann::json report = nlohmann::json::object();
    RunLockstepVcan(o, SelfExePath(), "", report);
    return report;
  }
  throw std::invalid_argument(fmt::format("unknown bench worker '{}'", name));
}

nlohmann::json RunBench(const BenchOptions& o, const std::string& self_exe,
                        const UcanEnvironmentFn& ucan_env,
                        const std::string& lockstep_unavailable) {
  g_worker_limit_s = o.quick ? 45.0 : 900.0;
  nlohmann::json report = nlohmann::json::object();
  const MachineFacts m = ReadMachineFacts();
  SetPath(report, "machine.cpu_model", m.cpu_model);
  SetPath(report, "machine.cores", m.cores);
  SetPath(report, "machine.build_type", m.build_type);
  SetPath(report, "machine.kernel", m.kernel);
  SetPath(report, "machine.date_utc", m.date_utc);
  SetPath(report, "machine.quick", o.quick);

  double peak_mib = 0.0;
  auto run = [&](const std::string& name, bool on_ucan,
                 const std::vector<std::string>& failure_keys) -> double {
    std::vector<std::pair<std::string, std::string>> env;
    std::string dir;
    if (on_ucan) {
      try {
        dir = bus::CreateTempUcanRuntimeDir("wheelhil-bench-");
        env = ucan_env(dir);
      } catch (const std::exception& e) {
        for (const auto& k : failure_keys) SetPath(report, k, Unavailable(e.what()));
        return std::nan("");
      }
    }
    WorkerOutcome w = RunWorkerProcess(CommonWorkerArgs(o, self_exe, name), env);
    if (!dir.empty()) {
      std::error_code ec;
      std::filesystem::remove_all(dir, ec);  // the broker removes it; this covers a crash
    }
    if (!w.problem.empty()) {
      for (const auto& k : failure_keys) {
        if (!GetPath(w.report, k)) SetPath(report, k, Unavailable(w.problem));
      }
    }
    report.merge_patch(w.report);
    peak_mib = std::max(peak_mib, w.max_rss_mib);
    return w.max_rss_mib;
  };

  SetPath(report, "rss.physics_mib", run("physics", false, DocumentedKeysUnder("physics.")));
  run("peers", false, DocumentedKeysUnder("peers."));
  SetPath(report, "rss.bus_mib",
          run("bus-ucan", true, {"bus.ucan_frames_per_s", "bus.ucan_fanout4_frames_per_s"}));

  const std::vector<std::string> vcan_keys = {"bus.vcan_frames_per_s",
                                              "bus.vcan_fanout4_frames_per_s"};
  if (std::filesystem::exists("/sys/class/net/vcan0")) {
    run("bus-vcan", false, vcan_keys);
    SetPath(report, "bus.vcan_environment", "host kernel vcan0");
  } else if (o.uml) {
    const std::string script = o.source_dir + "/tests/vcan/uml_run.sh";
    std::vector<std::string> argv = {script, "--timeout", "300", "--"};
    const auto worker = CommonWorkerArgs(o, self_exe, "bus-vcan");
    argv.insert(argv.end(), worker.begin(), worker.end());
    WorkerOutcome w = RunWorkerProcess(argv, {});
    if (!w.problem.empty()) {
      for (const auto& k : vcan_keys) {
        if (!GetPath(w.report, k)) SetPath(report, k, Unavailable("user-mode-linux: " + w.problem));
      }
    }
    report.merge_patch(w.report);
    SetPath(report, "bus.vcan_environment",
            "vcan0 inside the user-mode-linux test kernel (tests/vcan/uml_run.sh): UML traps "
            "every system call, so these are UML's numbers, not a native kernel's");
  } else {
    for (const auto& k : vcan_keys) {
      SetPath(report, k,
              Unavailable("no kernel vcan0 on this machine; `wheelhil bench --uml` measures it "
                          "inside the user-mode-linux test kernel"));
    }
    SetPath(report, "bus.vcan_environment", "none");
  }
  SetRatio(report, "bus.ucan_vs_vcan_ratio", GetPath(report, "bus.ucan_frames_per_s"),
           GetPath(report, "bus.vcan_frames_per_s"), "needs both bus rates");

  SetPath(report, "rss.realtime_mib",
          run("realtime", true, DocumentedKeysUnder("realtime.", "realtime.loaded_")));
  run("realtime-loaded", true, DocumentedKeysUnder("realtime.loaded_"));

  RunLockstep(o, self_exe, lockstep_unavailable, report, peak_mib);
  RunLockstepVcan(o, self_exe, lockstep_unavailable, report);
  RunCampaignThroughput(o, self_exe, lockstep_unavailable, report);
  for (const char* k : {"rss.physics_mib", "rss.bus_mib", "rss.realtime_mib"}) {
    const nlohmann::json* r = GetPath(report, k);
    if (r && r->is_number() && !std::isfinite(r->get<double>())) {
      SetPath(report, k, Unavailable("the worker did not run"));
    }
  }
  SetPath(report, "rss.peak_mib", peak_mib);
  return report;
}

}  // namespace wheelhil::emulator::bench
