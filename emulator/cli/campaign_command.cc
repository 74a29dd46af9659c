#include "emulator/cli/campaign_command.h"

#include <fmt/format.h>
#include <unistd.h>

#include <filesystem>
#include <iostream>
#include <stdexcept>

#include "bus/install_paths.h"
#include "emulator/campaign/campaign.h"
#include "emulator/campaign/run_pool.h"
#include "emulator/cli/finite_number.h"
#include "emulator/scenario/scenario.h"

namespace wheelhil::emulator {
namespace {

namespace fs = std::filesystem;
namespace cmp = campaign;

// scenarios/smoke next to the current directory, else in the source tree next to the build
// directory that holds this executable (build-x/bin/wheelhil -> ../../scenarios/smoke), else
// the installed examples (<bindir>/../share/wheelhil/scenarios/smoke).
std::string DefaultSmokeDir() {
  if (fs::is_directory("scenarios/smoke")) return "scenarios/smoke";
  const std::string root = bus::FindShippedDataRoot(bus::RunningExecutableDir());
  std::error_code ec;
  if (!root.empty() && fs::is_directory(fs::path(root) / "scenarios" / "smoke", ec)) {
    return (fs::path(root) / "scenarios" / "smoke").string();
  }
  return "scenarios/smoke";
}

}  // namespace

CampaignCommand::CampaignCommand(CLI::App& app) {
  campaign_ = app.add_subcommand("campaign",
                                 "Run or resume a fault-injection campaign (docs/campaigns.md)");
  campaign_->add_option("FILE", file_, "Campaign file (YAML)");
  campaign_->add_option("-j,--jobs", jobs_, "Parallel runs (child processes)")
      ->check(CLI::Range(1, 1024));
  campaign_->add_option("--db", db_, "SQLite results store (default <out>/results.sqlite)");
  campaign_->add_option("--shard", shard_, "Run only slice K of N (0-based K), e.g. 3/8");
  campaign_->add_option("--junit", junit_, "Write JUnit XML (one case per run + criteria)");
  campaign_->add_option("--out", out_, "Output folder (default ./campaign-<name>)");
  campaign_->add_option("--runner", runner_,
                        "Program run as `EXE run SCENARIO --out DIR --seed N` (default: this "
                        "wheelhil)");
  campaign_->add_flag("-q,--quiet", quiet_, "No progress output");
  campaign_->add_flag("--no-html", no_html_, "Do not write campaign.html");
  merge_ = campaign_->add_subcommand("merge", "Merge shard result databases into one");
  merge_->add_option("-o,--out", merge_out_, "Merged database (created or extended)")->required();
  merge_->add_option("INPUTS", merge_inputs_, "Shard databases")->required();

  smoke_ = app.add_subcommand(
      "smoke",
      "Short CI suite: every platform and paper scenario, a few seconds each (docs/ci.md)");
  smoke_->add_option("--junit", smoke_junit_, "Write JUnit XML (one case per scenario)");
  smoke_->add_option("--firmware", smoke_firmware_,
                     "Firmware command under test (replaces each scenario's firmware.command)");
  smoke_->add_option("--scenarios", smoke_scenarios_,
                     "Folder of smoke scenarios or a list file (default scenarios/smoke)");
  smoke_->add_option("--out", smoke_out_, "Output folder for the run artefacts");
  smoke_->add_option("-j,--jobs", smoke_jobs_, "Parallel runs")->check(CLI::Range(1, 1024));
  smoke_->add_option("--timeout", smoke_timeout_s_, "Wall-clock limit per run, s")
      ->check(FiniteNumber())
      ->check(CLI::Range(0.1, 86400.0));
  smoke_->add_option("--runner", smoke_runner_, "Program used instead of this wheelhil's `run`");
}

std::optional<int> CampaignCommand::Run() {
  if (merge_->parsed()) return RunMerge();
  if (campaign_->parsed()) return RunCampaign();
  if (smoke_->parsed()) return RunSmoke();
  return std::nullopt;
}

int CampaignCommand::RunCampaign() {
  if (file_.empty()) {
    std::cerr << "wheelhil campaign: FILE is required (or use `wheelhil campaign merge`)\n";
    return 2;
  }
  try {
    const auto spec = cmp::LoadCampaignFile(file_);
    cmp::CampaignOptions o;
    o.out_dir = out_;
    o.db = db_;
    o.jobs = jobs_;
    o.shard = cmp::Shard::Parse(shard_);
    o.runner_exe = runner_.empty() ? "" : fs::absolute(runner_).string();
    o.junit = junit_;
    o.progress = !quiet_;
    o.html = !no_html_;
    // Checked with wheelhil's own loader only when wheelhil's `run` is the runner: another
    // runner may read other keys.
    if (runner_.empty()) {
      o.check_scenario = [](const fs::path& file) {
        (void)scenario::LoadScenarioFile(file.string());
      };
    }
    const auto outcome = cmp::RunCampaign(spec, o);
    std::cout << outcome.text << std::flush;
    if (o.shard.n > 1) return outcome.summary.complete ? 0 : 1;
    return outcome.summary.campaign_passed ? 0 : 1;
  } catch (const std::invalid_argument& e) {
    std::cerr << "wheelhil campaign: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "wheelhil campaign: " << e.what() << "\n";
    return 1;
  }
}

int CampaignCommand::RunMerge() {
  try {
    std::vector<fs::path> inputs(merge_inputs_.begin(), merge_inputs_.end());
    const auto n = cmp::MergeStores(merge_out_, inputs);
    std::cout << fmt::format("merged {} databases into {}: {} runs\n", inputs.size(), merge_out_,
                             n);
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "wheelhil campaign merge: " << e.what() << "\n";
    return 2;
  }
}

int CampaignCommand::RunSmoke() {
  try {
    cmp::SmokeOptions o;
    o.scenarios =
        cmp::FindSmokeScenarios(smoke_scenarios_.empty() ? DefaultSmokeDir() : smoke_scenarios_);
    o.out_dir = smoke_out_;
    o.jobs = smoke_jobs_;
    o.runner_exe = smoke_runner_.empty() ? "" : fs::absolute(smoke_runner_).string();
    o.firmware_command = smoke_firmware_;
    o.junit = smoke_junit_;
    o.timeout_s = smoke_timeout_s_;
    const auto outcome = cmp::RunSmoke(o);
    std::size_t passed = 0;
    for (const auto& r : outcome.runs) {
      passed += r.passed;
      std::cout << fmt::format("{:<40} {:>5.1f} s  {}{}\n", r.key, r.wall_s,
                               r.passed ? "pass" : "FAIL", r.passed ? "" : ": " + r.failure);
    }
    std::cout << fmt::format("smoke: {}/{} passed\n", passed, outcome.runs.size());
    return outcome.passed ? 0 : 1;
  } catch (const std::invalid_argument& e) {
    std::cerr << "wheelhil smoke: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "wheelhil smoke: " << e.what() << "\n";
    return 1;
  }
}

}  // namespace wheelhil::emulator
