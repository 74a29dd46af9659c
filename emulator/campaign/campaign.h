#pragma once
/// Running a campaign and the smoke suite end to end: expand the run list, skip the runs
/// already stored (resume), run the rest on a pool of child `wheelhil run` processes, store each
/// run as it finishes, then summarise (text, campaign.html, JUnit XML). See docs/campaigns.md
/// and docs/ci.md. Single-threaded (the parallelism is in child processes).

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "emulator/campaign/campaign_spec.h"
#include "emulator/campaign/results_store.h"
#include "emulator/campaign/run_report.h"
#include "emulator/campaign/summary.h"

namespace wheelhil::emulator::campaign {

struct CampaignOptions {
  std::filesystem::path out_dir;  ///< run dirs + campaign.html; default ./campaign-<name>
  std::filesystem::path db;       ///< default <out_dir>/results.sqlite
  int jobs = 1;
  Shard shard;
  std::string runner_exe;  ///< default: this executable (/proc/self/exe)
  std::vector<std::string> runner_args;
  std::filesystem::path junit;  ///< empty: no JUnit file
  bool progress = true;
  bool html = true;
  /// Loads a scenario file and throws std::invalid_argument ("file:line:col: field: problem")
  /// when it is not valid. Given, the base scenario and the first expanded run are checked
  /// before any run starts; unset, each run finds its own errors.
  std::function<void(const std::filesystem::path&)> check_scenario;
};

struct CampaignOutcome {
  std::vector<RunRecord> runs;  ///< stored runs of this (shard's) run list, by index
  CampaignSummary summary;
  std::size_t ran_now = 0;  ///< runs executed by this call
  std::size_t skipped = 0;  ///< runs already stored (resume)
  std::string text;         ///< FormatSummary
};

/// Fills passed/failure of a finished run from its report and the campaign's per-run criteria.
void EvaluateRun(const CampaignSpec& spec, RunRecord& record, const RunReport* report);

/// Runs (or resumes) the campaign. Throws std::invalid_argument (bad parameter paths, named
/// with campaign file:line) before any run starts, std::runtime_error on store errors.
CampaignOutcome RunCampaign(const CampaignSpec& spec, const CampaignOptions& options);

struct SmokeOptions {
  std::vector<std::filesystem::path> scenarios;
  std::filesystem::path out_dir = "smoke";
  int jobs = 2;
  std::string runner_exe;        ///< default: this executable
  std::string firmware_command;  ///< non-empty: written into each scenario's firmware.command
  std::filesystem::path junit;
  std::uint64_t seed = 1;
  double timeout_s = 60;
  bool progress = true;
};

struct SmokeOutcome {
  std::vector<RunRecord> runs;  ///< in scenario order
  bool passed = false;          ///< every run passed
};

/// The smoke scenarios: every *.yaml in `dir` (sorted), or the entries of a list file (one path
/// a line, relative to the list file, '#' comments). Throws std::invalid_argument when none.
std::vector<std::filesystem::path> FindSmokeScenarios(const std::filesystem::path& dir_or_list);

/// Runs every smoke scenario once (seed `seed`), writes JUnit (one case per scenario, the
/// failed expectations in the failure message).
SmokeOutcome RunSmoke(const SmokeOptions& options);

}  // namespace wheelhil::emulator::campaign
