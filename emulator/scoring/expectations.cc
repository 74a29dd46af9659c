#include "emulator/scoring/expectations.h"

#include <fmt/format.h>

namespace wheelhil::emulator::scoring {

namespace {

using nlohmann::json;

void Flatten(const json& node, const std::string& prefix,
             std::vector<std::pair<std::string, double>>& out) {
  if (node.is_number()) {
    out.emplace_back(prefix, node.get<double>());
  } else if (node.is_boolean()) {
    out.emplace_back(prefix, node.get<bool>() ? 1.0 : 0.0);
  } else if (node.is_object()) {
    for (const auto& [k, v] : node.items()) Flatten(v, prefix.empty() ? k : prefix + "." + k, out);
  } else if (node.is_array()) {
    for (std::size_t i = 0; i < node.size(); ++i) {
      Flatten(node[i], fmt::format("{}[{}]", prefix, i), out);
    }
  }
}

}  // namespace

std::vector<std::pair<std::string, double>> FlattenMetrics(const json& metrics) {
  std::vector<std::pair<std::string, double>> out;
  if (metrics.is_object()) Flatten(metrics, "", out);
  return out;
}

bool Compare(double value, const std::string& op, double limit) {
  if (op == "<") return value < limit;
  if (op == "<=") return value <= limit;
  if (op == ">") return value > limit;
  if (op == ">=") return value >= limit;
  return false;
}

bool EvaluateExpectations(const std::vector<Expectation>& expectations, const json& metrics,
                          json& out) {
  const auto flat = FlattenMetrics(metrics);
  auto find = [&](const std::string& name) -> std::optional<double> {
    for (const auto& [k, v] : flat) {
      if (k == name) return v;
    }
    return std::nullopt;
  };
  bool all = true;
  out = json::array();
  for (const auto& e : expectations) {
    const auto value = find(e.metric);
    std::optional<double> limit = e.value;
    if (!e.other_metric.empty()) limit = find(e.other_metric);
    const bool ok = value && limit && Compare(*value, e.op, *limit);
    const std::string rhs =
        e.other_metric.empty() ? fmt::format("{}", e.value.value_or(0.0)) : e.other_metric;
    json j{{"metric", e.metric},
           {"op", e.op},
           {"text", fmt::format("{} {} {}", e.metric, e.op, rhs)},
           {"passed", ok}};
    if (value) j["value"] = *value;
    if (limit) j["limit"] = *limit;
    if (!value) j["problem"] = "metric not produced by this run";
    if (value && !limit) j["problem"] = "comparison metric not produced by this run";
    out.push_back(j);
    all = all && ok;
  }
  return all;
}

}  // namespace wheelhil::emulator::scoring
