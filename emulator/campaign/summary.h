#pragma once
/// End-of-campaign evaluation and reports: pass rate, campaign-wide criteria, the worst runs,
/// for each varied parameter how the metrics move with it (text table), and campaign.html with
/// the same tables plus inline SVG scatter plots (no scripts, no external files).
/// Pure functions of the stored runs: a merged set of shard databases gives the same summary
/// as the unsharded campaign. Thread-compatible.

#include <filesystem>
#include <string>
#include <vector>

#include "emulator/campaign/campaign_spec.h"
#include "emulator/campaign/junit_writer.h"
#include "emulator/campaign/results_store.h"

namespace wheelhil::emulator::campaign {

struct CriterionResult {
  std::string description;
  double achieved = 0;  ///< fraction of runs satisfying it
  double required = 0;
  bool holds = false;
};

struct CampaignSummary {
  std::size_t expected = 0;  ///< runs in the (shard's) run list
  std::size_t stored = 0;    ///< of those, finished and stored
  std::size_t passed = 0;
  double pass_rate = 0;  ///< passed / stored
  std::vector<CriterionResult> criteria;
  bool complete = false;                 ///< stored == expected
  bool campaign_passed = false;          ///< complete and every criterion holds
  std::vector<std::size_t> worst;        ///< indices into the runs, worst first (at most 10)
  std::vector<std::string> key_metrics;  ///< metrics shown in tables and plots
};

/// Evaluates `runs` (the stored records of this run list) against `spec`.
CampaignSummary Summarize(const CampaignSpec& spec, const std::vector<RunRecord>& runs,
                          std::size_t expected);

/// Plain-text summary for the terminal.
std::string FormatSummary(const CampaignSpec& spec, const CampaignSummary& summary,
                          const std::vector<RunRecord>& runs);

/// Writes campaign.html. Throws std::runtime_error.
void WriteCampaignHtml(const std::filesystem::path& file, const CampaignSpec& spec,
                       const CampaignSummary& summary, const std::vector<RunRecord>& runs);

/// One JUnit case per run (failure message = why it failed) plus one per campaign criterion.
JUnitSuite CampaignJUnitSuite(const CampaignSpec& spec, const CampaignSummary& summary,
                              const std::vector<RunRecord>& runs);

}  // namespace wheelhil::emulator::campaign
