#pragma once
/// Reads the report.json that `wheelhil run SCENARIO --out DIR` writes (docs/scenarios.md) into
/// the few things a campaign needs: the verdict, flat numeric metrics and the expectations.
/// Metric names are the dotted paths of the numeric leaves of the report's `metrics` object
/// (e.g. {"metrics": {"pose": {"final_error_m": 0.03}}} -> "pose.final_error_m"); each
/// expectation with a numeric `value` is also available as "expect.<name>". Wall-clock fields
/// are ignored, so two runs of the same scenario and seed give equal RunReports.
/// Thread-compatible.

#include <nlohmann/json.hpp>

#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace wheelhil::emulator::campaign {

struct Expectation {
  std::string name;
  bool passed = false;
  std::string text;  ///< human description: name, value, bound as the report gives them
};

struct RunReport {
  std::string verdict;  ///< "pass", "fail", ... as written by the runner
  std::map<std::string, double> metrics;
  std::vector<Expectation> expectations;
  std::string failure;  ///< the report's `failure` (why the run itself failed), may be empty
  bool VerdictPassed() const { return verdict == "pass" || verdict == "passed"; }
  std::optional<double> Metric(const std::string& name) const;
  /// "run failed: <failure>" and "expectation <name> failed: <text>" for each failed
  /// expectation, joined by "; ".
  std::string FailedExpectations() const;
};

/// Parses report.json text. Returns nullopt and sets `error` when it is not a usable report
/// (invalid JSON, no verdict): outside data never throws.
std::optional<RunReport> ParseRunReport(const std::string& json_text, std::string* error);
std::optional<RunReport> ReadRunReport(const std::filesystem::path& file, std::string* error);

}  // namespace wheelhil::emulator::campaign
