#pragma once
/// The one metric flattener and the one expectation evaluator, shared by `wheelhil run` (the
/// scenario's `expect:` list) and `wheelhil campaign` (its per-run criteria over report.json).
/// A metric's name is the dotted path of a numeric or boolean leaf of a report's `metrics`
/// object ({"pose": {"final_position_error_m": 0.03}} -> "pose.final_position_error_m"; array
/// elements as "name[i]"); booleans are 1 / 0. No state; thread-safe.

#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

namespace wheelhil::emulator::scoring {

/// Every leaf of `metrics`, in the object's (sorted) key order. Non-finite numbers are kept
/// (a NaN metric fails every comparison rather than looking absent).
std::vector<std::pair<std::string, double>> FlattenMetrics(const nlohmann::json& metrics);

/// `metric OP value`, or `metric OP other_metric`.
struct Expectation {
  std::string metric;  ///< e.g. "pose.final_position_error_m".
  std::string op;      ///< "<", "<=", ">", ">=".
  std::optional<double> value;
  std::string other_metric;  ///< When set, compare against this metric instead of value.
  std::string where;         ///< file:line:column, for messages.
};

/// `value OP limit` for op "<", "<=", ">", ">="; false for any other op or a NaN.
bool Compare(double value, const std::string& op, double limit);

/// Evaluates the expectations against the flattened metrics; fills `out` (a JSON array, one
/// object per expectation: metric, op, text, passed, value, limit, problem) and returns true
/// when all hold. A missing metric fails its expectation and says so in `problem`.
bool EvaluateExpectations(const std::vector<Expectation>& expectations,
                          const nlohmann::json& metrics, nlohmann::json& out);

}  // namespace wheelhil::emulator::scoring
