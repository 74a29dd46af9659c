#pragma once
/// Configuration of the reference estimator firmware (`wheelhil-fw --config FILE.yaml`).
/// Loading throws std::invalid_argument with "file:line:col: field: problem" on bad input.

#include <string>

namespace wheelhil::fw {

enum class EstimatorKind { kPaper000SlipCorrection, kPaper001FollowerOdometry, kPaper002Fusion };

struct FwConfig {
  std::string source_path;  ///< The file it was read from, for messages.
  EstimatorKind estimator = EstimatorKind::kPaper000SlipCorrection;
};

/// Reads and validates a firmware config file.
FwConfig LoadFwConfig(const std::string& path);

/// The YAML spelling of an estimator kind (`paper000`, `paper001`, `paper002`).
const char* EstimatorName(EstimatorKind kind) noexcept;

}  // namespace wheelhil::fw
