#include "emulator/campaign/run_report.h"

#include <fmt/format.h>

#include <cmath>
#include <fstream>
#include <sstream>

#include "emulator/scoring/expectations.h"

namespace wheelhil::emulator::campaign {
namespace {

using nlohmann::json;

std::string Text(const json& v) { return v.is_string() ? v.get<std::string>() : v.dump(); }

}  // namespace

std::optional<double> RunReport::Metric(const std::string& name) const {
  const auto it = metrics.find(name);
  if (it == metrics.end()) return std::nullopt;
  return it->second;
}

std::string RunReport::FailedExpectations() const {
  std::string out = failure.empty() ? "" : "run failed: " + failure;
  for (const auto& e : expectations) {
    if (e.passed) continue;
    if (!out.empty()) out += "; ";
    if (e.text.rfind(e.name, 0) == 0) {
      out += "expectation failed: " + e.text;  // the runner's text already names it
    } else {
      out += fmt::format("expectation {} failed: {}", e.name, e.text);
    }
  }
  return out;
}

std::optional<RunReport> ParseRunReport(const std::string& json_text, std::string* error) {
  const json doc = json::parse(json_text, nullptr, /*allow_exceptions=*/false);
  if (doc.is_discarded() || !doc.is_object()) {
    if (error) *error = "report.json is not a JSON object";
    return std::nullopt;
  }
  RunReport r;
  const auto verdict = doc.find("verdict");
  if (verdict == doc.end() || !verdict->is_string()) {
    if (error) *error = "report.json has no string `verdict`";
    return std::nullopt;
  }
  r.verdict = verdict->get<std::string>();
  if (const auto f = doc.find("failure"); f != doc.end() && f->is_string()) {
    r.failure = f->get<std::string>();
  }
  if (const auto m = doc.find("metrics"); m != doc.end()) {
    // A non-finite value is stored as absent (SQLite REAL, campaign statistics).
    for (const auto& [name, v] : scoring::FlattenMetrics(*m)) {
      if (std::isfinite(v)) r.metrics[name] = v;
    }
  }
  if (const auto ex = doc.find("expectations"); ex != doc.end() && ex->is_array()) {
    std::size_t i = 0;
    for (const auto& e : *ex) {
      Expectation x;
      x.name = fmt::format("#{}", i++);
      if (!e.is_object()) continue;
      for (const char* key : {"name", "id", "metric", "expect", "text"}) {
        if (e.contains(key) && e[key].is_string()) {
          x.name = e[key].get<std::string>();
          break;
        }
      }
      bool passed = true;
      for (const char* key : {"passed", "pass", "ok"}) {
        if (e.contains(key) && e[key].is_boolean()) passed = e[key].get<bool>();
      }
      if (e.contains("verdict") && e["verdict"].is_string()) {
        const auto v = e["verdict"].get<std::string>();
        passed = v == "pass" || v == "passed";
      }
      x.passed = passed;
      // Everything but the name and flag, compact: "value=0.31 max=0.1 stream=pose".
      std::string text;
      for (const auto& [k, v] : e.items()) {
        if (k == "name" || k == "passed" || k == "pass" || k == "ok" || k == "verdict") continue;
        if (!text.empty()) text += " ";
        text += k + "=" + Text(v);
      }
      // The runner's own wording when it gives one: "<text> (value <v>)".
      if (e.contains("text") && e["text"].is_string()) {
        text = e["text"].get<std::string>();
        if (e.contains("value")) text += " (value " + Text(e["value"]) + ")";
      }
      x.text = text;
      if (e.contains("metric") && e.contains("value") && e["value"].is_number()) {
        const double v = e["value"].get<double>();
        if (std::isfinite(v)) r.metrics["expect." + x.name] = v;
      }
      r.expectations.push_back(std::move(x));
    }
  }
  return r;
}

std::optional<RunReport> ReadRunReport(const std::filesystem::path& file, std::string* error) {
  std::ifstream in(file);
  if (!in) {
    if (error) *error = fmt::format("{} missing", file.string());
    return std::nullopt;
  }
  std::stringstream text;
  text << in.rdbuf();
  return ParseRunReport(text.str(), error);
}

}  // namespace wheelhil::emulator::campaign
