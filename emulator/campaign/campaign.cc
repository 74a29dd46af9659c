#include "emulator/campaign/campaign.h"

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <stdexcept>

#include "bus/yaml_fields.h"
#include "emulator/campaign/junit_writer.h"
#include "emulator/campaign/run_pool.h"
#include "emulator/campaign/scenario_writer.h"

namespace wheelhil::emulator::campaign {
namespace {

namespace fs = std::filesystem;

void AppendFailure(std::string& failure, const std::string& what) {
  if (what.empty()) return;
  if (!failure.empty()) failure += "; ";
  failure += what;
}

}  // namespace

void EvaluateRun(const CampaignSpec& spec, RunRecord& r, const RunReport* report) {
  if (!report) {
    r.passed = false;
    return;  // failure already says why (runner error / timeout)
  }
  bool passed = true;
  std::string failure;
  if (spec.require_verdict_pass && !report->VerdictPassed()) {
    passed = false;
    std::string why = report->FailedExpectations();
    AppendFailure(failure, why.empty() ? "verdict " + report->verdict : why);
  }
  for (const auto& c : spec.run_criteria) {
    const auto v = report->Metric(c.metric);
    if (!c.Holds(v)) {
      passed = false;
      AppendFailure(failure,
                    v ? fmt::format("criterion {} failed: {} = {:.6g}", c.Describe(), c.metric, *v)
                      : fmt::format("criterion {} failed: metric {} missing from report",
                                    c.Describe(), c.metric));
    }
  }
  r.passed = passed;
  r.failure = failure;
}

namespace {

// A mistake in the base scenario or in what the parameters write into it would otherwise
// fail every run, one child process at a time. A first run that fails is left in out_dir for
// the error's line to be read.
void CheckBeforeStart(const CampaignSpec& spec, const std::vector<RunSpec>& all,
                      const fs::path& out_dir,
                      const std::function<void(const fs::path&)>& check_scenario) {
  try {
    check_scenario(spec.base_scenario);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(fmt::format("{}: base: {}", spec.file, e.what()));
  }
  if (all.empty()) return;
  const fs::path first = out_dir / "first-run-check.yaml";
  WriteRunScenario(spec, all.front(), first);
  try {
    check_scenario(first);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(
        fmt::format("{}: the first run (parameters {}) is not a valid scenario: {}", spec.file,
                    all.front().ParamsJson(spec).dump(), e.what()));
  }
  fs::remove(first);
}

}  // namespace

CampaignOutcome RunCampaign(const CampaignSpec& spec, const CampaignOptions& options) {
  CheckParameterPaths(spec);
  const fs::path out_dir =
      fs::absolute(options.out_dir.empty() ? fs::path("campaign-" + spec.name) : options.out_dir);
  const fs::path db = options.db.empty() ? out_dir / "results.sqlite" : options.db;
  fs::create_directories(out_dir);
  const auto all = ExpandRuns(spec);
  const auto mine = SelectShard(all, options.shard);
  // Finished results are read without writing anything: they may be on a read-only file
  // system (an archive, a colleague's share), where opening them for writing fails. With
  // nothing to run, there is nothing to check either.
  std::unique_ptr<ResultsStore> store;
  std::error_code ec;
  if (fs::is_regular_file(db, ec)) {
    auto finished = std::make_unique<ResultsStore>(db, spec.name, spec.fingerprint,
                                                   ResultsStore::Access::kReadOnly);
    const auto keys = finished->StoredKeys();
    if (std::all_of(mine.begin(), mine.end(),
                    [&](const RunSpec& r) { return keys.count(r.key) != 0; })) {
      store = std::move(finished);
    }
  }
  if (!store) {
    if (options.check_scenario) CheckBeforeStart(spec, all, out_dir, options.check_scenario);
    store = std::make_unique<ResultsStore>(db, spec.name, spec.fingerprint);
  }
  const auto stored = store->StoredKeys();
  CampaignOutcome outcome;
  std::vector<PoolJob> jobs;
  for (const auto& run : mine) {
    if (stored.count(run.key)) {
      ++outcome.skipped;
      continue;
    }
    PoolJob job;
    job.record.key = run.key;
    job.record.index = run.index;
    job.record.point = run.point;
    job.record.repeat = run.repeat;
    job.record.seed = run.seed;
    job.record.params = run.ParamsJson(spec);
    job.record.run_dir = (out_dir / "runs" / run.key).string();
    job.timeout_s = spec.timeout_s;
    job.prepare = [&spec, run](const fs::path& run_dir) {
      const fs::path file = run_dir / "scenario.yaml";
      WriteRunScenario(spec, run, file);
      return file;
    };
    jobs.push_back(std::move(job));
  }
  if (options.progress && outcome.skipped) {
    std::cerr << fmt::format("campaign {}: {} of {} runs already stored in {}, {} to run\n",
                             spec.name, outcome.skipped, mine.size(), db.string(), jobs.size());
  }
  PoolOptions pool;
  pool.runner_exe = options.runner_exe.empty() ? ThisExecutable() : options.runner_exe;
  pool.extra_args = options.runner_args;
  pool.jobs = options.jobs;
  pool.label = spec.name;
  pool.progress = options.progress;
  const auto done = RunPool(
      std::move(jobs), pool,
      [&spec](RunRecord& r, const RunReport* report) { EvaluateRun(spec, r, report); },
      [&store](const RunRecord& r) { store->Put(r); });
  outcome.ran_now = done.size();

  // Summary over the stored runs of this run list (other keys in the file are ignored).
  std::map<std::string, bool> wanted;
  for (const auto& r : mine) wanted[r.key] = true;
  for (auto& r : store->All()) {
    if (wanted.count(r.key)) outcome.runs.push_back(std::move(r));
  }
  outcome.summary = Summarize(spec, outcome.runs, mine.size());
  outcome.text = FormatSummary(spec, outcome.summary, outcome.runs);
  if (options.shard.n > 1) {
    outcome.text += fmt::format(
        "(shard {}/{}: criteria judge this shard only; merge the shard databases with "
        "`wheelhil campaign merge` for the campaign verdict)\n",
        options.shard.k, options.shard.n);
  }
  if (options.html) {
    WriteCampaignHtml(out_dir / "campaign.html", spec, outcome.summary, outcome.runs);
  }
  if (!options.junit.empty()) {
    WriteJUnit(options.junit, {CampaignJUnitSuite(spec, outcome.summary, outcome.runs)},
               "wheelhil campaign " + spec.name);
  }
  return outcome;
}

std::vector<fs::path> FindSmokeScenarios(const fs::path& dir_or_list) {
  std::vector<fs::path> out;
  std::error_code ec;
  if (fs::is_directory(dir_or_list, ec)) {
    for (const auto& e : fs::directory_iterator(dir_or_list)) {
      if (e.is_regular_file() && e.path().extension() == ".yaml") out.push_back(e.path());
    }
    std::sort(out.begin(), out.end());
  } else if (fs::is_regular_file(dir_or_list, ec)) {
    std::ifstream in(dir_or_list);
    std::string line;
    int n = 0;
    while (std::getline(in, line)) {
      ++n;
      if (const auto hash = line.find('#'); hash != std::string::npos) line.resize(hash);
      line.erase(0, line.find_first_not_of(" \t"));
      line.erase(line.find_last_not_of(" \t\r") + 1);
      if (line.empty()) continue;
      fs::path p = line;
      if (p.is_relative()) p = dir_or_list.parent_path() / p;
      if (!fs::is_regular_file(p, ec)) {
        throw std::invalid_argument(
            fmt::format("{}:{}: scenario: '{}' not found", dir_or_list.string(), n, p.string()));
      }
      out.push_back(p.lexically_normal());
    }
  }
  if (out.empty()) {
    throw std::invalid_argument(
        fmt::format("{}:0: smoke: no scenarios (need a folder of *.yaml or a list file)",
                    dir_or_list.string()));
  }
  return out;
}

SmokeOutcome RunSmoke(const SmokeOptions& options) {
  const fs::path out_dir = fs::absolute(options.out_dir);
  fs::create_directories(out_dir);
  std::vector<PoolJob> jobs;
  std::map<std::string, std::size_t> order;
  for (std::size_t i = 0; i < options.scenarios.size(); ++i) {
    const fs::path scenario = fs::absolute(options.scenarios[i]);
    PoolJob job;
    job.record.key = scenario.stem().string();
    if (order.count(job.record.key)) job.record.key += fmt::format("-{}", i);
    order[job.record.key] = i;
    job.record.index = static_cast<int>(i);
    job.record.seed = options.seed;
    job.record.params = {{"scenario", scenario.string()}};
    job.record.run_dir = (out_dir / job.record.key).string();
    job.timeout_s = options.timeout_s;
    const std::string firmware = options.firmware_command;
    job.prepare = [scenario, firmware](const fs::path& run_dir) -> fs::path {
      if (firmware.empty()) return scenario;
      // The firmware under test replaces the scenario's; relative paths become absolute.
      const bus::yaml::FieldReader reader(scenario.string());
      YAML::Node root = reader.Parse(reader.ReadFile());
      std::function<void(YAML::Node)> absolutize = [&](YAML::Node n) {
        if (n.IsMap()) {
          for (auto kv : n) absolutize(kv.second);
        } else if (n.IsSequence()) {
          for (std::size_t k = 0; k < n.size(); ++k) absolutize(n[k]);
        } else if (n.IsScalar()) {
          const std::string& s = n.Scalar();
          if (s.empty() || s.front() == '/' || s.find_first_of("/.") == std::string::npos) return;
          std::error_code ec;
          const fs::path c = (scenario.parent_path() / s).lexically_normal();
          if (fs::exists(c, ec)) n = c.string();
        }
      };
      absolutize(root);
      root["firmware"]["command"] = firmware;
      const fs::path file = run_dir / "scenario.yaml";
      YAML::Emitter em;
      em << root;
      std::ofstream(file) << "# " << scenario.string() << " with firmware.command from "
                          << "`wheelhil smoke --firmware`\n"
                          << em.c_str() << "\n";
      return file;
    };
    jobs.push_back(std::move(job));
  }
  PoolOptions pool;
  pool.runner_exe = options.runner_exe.empty() ? ThisExecutable() : options.runner_exe;
  pool.jobs = options.jobs;
  pool.label = "smoke";
  pool.progress = options.progress;
  auto done = RunPool(
      std::move(jobs), pool,
      [](RunRecord& r, const RunReport* report) {
        if (!report) return;
        r.passed = report->VerdictPassed();
        if (!r.passed) {
          const std::string why = report->FailedExpectations();
          r.failure = why.empty() ? "verdict " + report->verdict : why;
        }
      },
      [](const RunRecord&) {});
  SmokeOutcome outcome;
  std::sort(done.begin(), done.end(),
            [](const RunRecord& a, const RunRecord& b) { return a.index < b.index; });
  outcome.passed = !done.empty();
  JUnitSuite suite;
  suite.name = "wheelhil.smoke";
  for (const auto& r : done) {
    outcome.passed = outcome.passed && r.passed;
    JUnitCase c;
    c.classname = "wheelhil.smoke";
    c.name = r.key;
    c.time_s = r.wall_s;
    if (r.verdict == "error" || r.verdict == "timeout") {
      c.error = r.failure;
    } else if (!r.passed) {
      c.failure = r.failure;
    }
    c.system_out = "scenario: " + r.params.value("scenario", "") + "\nrun dir: " + r.run_dir;
    suite.cases.push_back(std::move(c));
  }
  if (!options.junit.empty()) WriteJUnit(options.junit, {suite}, "wheelhil smoke");
  outcome.runs = std::move(done);
  return outcome;
}

}  // namespace wheelhil::emulator::campaign
