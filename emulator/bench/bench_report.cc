#include "emulator/bench/bench_report.h"

#include <sys/utsname.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <ctime>
#include <fstream>
#include <iterator>
#include <limits>
#include <sstream>

#include <fmt/format.h>

#ifndef WHEELHIL_BUILD_TYPE
#define WHEELHIL_BUILD_TYPE "unknown"
#endif

namespace wheelhil::emulator::bench {

std::string CpuModelFromCpuinfo(std::string_view cpuinfo) {
  for (const char* field : {"model name", "Model", "Hardware", "cpu model"}) {
    std::size_t pos = 0;
    while (pos < cpuinfo.size()) {
      std::size_t end = cpuinfo.find('\n', pos);
      if (end == std::string_view::npos) end = cpuinfo.size();
      const std::string_view line = cpuinfo.substr(pos, end - pos);
      pos = end + 1;
      const std::size_t colon = line.find(':');
      if (colon == std::string_view::npos) continue;
      std::string_view key = line.substr(0, colon);
      while (!key.empty() && (key.back() == ' ' || key.back() == '\t')) key.remove_suffix(1);
      if (key != field) continue;
      std::string_view value = line.substr(colon + 1);
      while (!value.empty() && (value.front() == ' ' || value.front() == '\t')) {
        value.remove_prefix(1);
      }
      while (!value.empty() && (value.back() == ' ' || value.back() == '\r'))
        value.remove_suffix(1);
      if (!value.empty()) return std::string(value);
    }
  }
  return "unknown";
}

std::string CompiledBuildType() {
  const std::string t = WHEELHIL_BUILD_TYPE;
  return t.empty() ? "unspecified" : t;
}

MachineFacts ReadMachineFacts() {
  MachineFacts facts;
  std::ifstream in("/proc/cpuinfo");
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  facts.cpu_model = CpuModelFromCpuinfo(text);
  facts.cores = static_cast<int>(::sysconf(_SC_NPROCESSORS_ONLN));
  facts.build_type = CompiledBuildType();
  utsname u{};
  if (::uname(&u) == 0) facts.kernel = fmt::format("{} {}", u.sysname, u.release);
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  ::gmtime_r(&now, &tm);
  char buf[32];
  std::strftime(buf, sizeof(buf), "%Y-%m-%dT%H:%M:%SZ", &tm);
  facts.date_utc = buf;
  return facts;
}

double Percentile(std::vector<double> values, double p) {
  if (values.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::sort(values.begin(), values.end());
  const double clamped = std::clamp(p, 0.0, 100.0);
  // Nearest rank: the smallest value with at least p % of the values at or below it.
  std::size_t rank = static_cast<std::size_t>(std::ceil(clamped / 100.0 * values.size()));
  if (rank == 0) rank = 1;
  return values[rank - 1];
}

double Median(std::vector<double> values) { return Percentile(std::move(values), 50.0); }

std::string Unavailable(std::string_view reason) { return fmt::format("unavailable: {}", reason); }

bool IsUnavailable(const nlohmann::json& value) {
  if (!value.is_string()) return false;
  const std::string& s = value.get_ref<const std::string&>();
  constexpr std::string_view kPrefix = "unavailable: ";
  return s.size() > kPrefix.size() && s.compare(0, kPrefix.size(), kPrefix) == 0;
}

void SetPath(nlohmann::json& report, std::string_view dotted_path, nlohmann::json value) {
  nlohmann::json* node = &report;
  std::size_t pos = 0;
  while (true) {
    const std::size_t dot = dotted_path.find('.', pos);
    const std::string key(dotted_path.substr(pos, dot == std::string_view::npos ? dot : dot - pos));
    if (!node->is_object()) *node = nlohmann::json::object();
    if (dot == std::string_view::npos) {
      (*node)[key] = std::move(value);
      return;
    }
    node = &(*node)[key];
    pos = dot + 1;
  }
}

const nlohmann::json* GetPath(const nlohmann::json& report, std::string_view dotted_path) {
  const nlohmann::json* node = &report;
  std::size_t pos = 0;
  while (true) {
    const std::size_t dot = dotted_path.find('.', pos);
    const std::string key(dotted_path.substr(pos, dot == std::string_view::npos ? dot : dot - pos));
    if (!node->is_object()) return nullptr;
    const auto it = node->find(key);
    if (it == node->end()) return nullptr;
    node = &*it;
    if (dot == std::string_view::npos) return node;
    pos = dot + 1;
  }
}

const std::vector<std::string>& BenchPlatforms() {
  static const std::vector<std::string> k = {"diff2", "mecanum4_omni3", "ortho3"};
  return k;
}

const std::vector<std::string>& BenchScenarios() {
  static const std::vector<std::string> k = {"paper000", "paper001", "paper002"};
  return k;
}

const std::vector<const char*>& HandoverAccountKeys() {
  static const std::vector<const char*> k = {"handovers_per_sim_s", "handover_us_each"};
  return k;
}

const std::vector<std::string>& VirtualTimeBenchScenarios() {
  static const std::vector<std::string> k = {"paper000", "paper002"};
  return k;
}

std::vector<std::string> DocumentedMetricKeys() {
  std::vector<std::string> keys;
  for (const auto& p : BenchPlatforms()) {
    keys.push_back(fmt::format("physics.{}.flat_rtf", p));
    keys.push_back(fmt::format("physics.{}.mesh_rtf", p));
  }
  for (int n : {1, 4, 16}) keys.push_back(fmt::format("physics.platforms_{}.rtf", n));
  for (const char* k : {"peers.mecanum_wheelhil_steps_per_s", "peers.mecanum_mujoco_steps_per_s",
                        "peers.mecanum_wheelhil_vs_mujoco"}) {
    keys.emplace_back(k);
  }
  for (const auto& s : BenchScenarios()) {
    keys.push_back(fmt::format("lockstep.{}.rtf", s));
    keys.push_back(fmt::format("lockstep.{}.vcan_rtf", s));
  }
  std::vector<std::string> virtual_rows = VirtualTimeBenchScenarios();
  virtual_rows.insert(virtual_rows.end(), {"customer_c", "customer_python"});
  for (const auto& s : VirtualTimeBenchScenarios()) {
    keys.push_back(fmt::format("virtual_time.{}.vs_physics_alone", s));
  }
  for (const auto& s : virtual_rows) {
    keys.push_back(fmt::format("virtual_time.{}.rtf", s));
    for (const char* account : HandoverAccountKeys()) {
      keys.push_back(fmt::format("virtual_time.{}.{}", s, account));
    }
  }
  for (const char* k : {"bus.ucan_frames_per_s",
                        "bus.ucan_fanout4_frames_per_s",
                        "bus.vcan_frames_per_s",
                        "bus.vcan_fanout4_frames_per_s",
                        "bus.ucan_vs_vcan_ratio",
                        "realtime.p50_us",
                        "realtime.p99_us",
                        "realtime.max_us",
                        "realtime.missed_deadlines",
                        "realtime.frames",
                        "realtime.duration_s",
                        "realtime.arrival_p99_us",
                        "realtime.spin_us",
                        "realtime.bare_timer_p99_us",
                        "realtime.bare_timer_max_us",
                        "realtime.bare_spin_p99_us",
                        "realtime.bare_spin_max_us",
                        "realtime.loaded_p50_us",
                        "realtime.loaded_p99_us",
                        "realtime.loaded_max_us",
                        "realtime.loaded_missed_deadlines",
                        "rss.physics_mib",
                        "rss.bus_mib",
                        "rss.realtime_mib",
                        "rss.lockstep_mib",
                        "campaign.paper000_runs_per_s",
                        "rss.peak_mib",
                        "machine.cores"}) {
    keys.emplace_back(k);
  }
  return keys;
}

std::vector<std::string> DocumentedTextKeys() {
  return {"machine.cpu_model",        "machine.build_type",  "machine.kernel",
          "machine.date_utc",         "realtime.scheduling", "bus.vcan_environment",
          "lockstep.vcan_environment"};
}

std::vector<std::string> CheckReport(const nlohmann::json& report) {
  std::vector<std::string> problems;
  for (const auto& key : DocumentedMetricKeys()) {
    const nlohmann::json* v = GetPath(report, key);
    if (!v) {
      problems.push_back(key + ": missing");
    } else if (v->is_number()) {
      if (!std::isfinite(v->get<double>())) problems.push_back(key + ": not finite");
    } else if (!IsUnavailable(*v)) {
      problems.push_back(key + ": neither a finite number nor \"unavailable: <reason>\"");
    }
  }
  for (const auto& key : DocumentedTextKeys()) {
    const nlohmann::json* v = GetPath(report, key);
    if (!v) {
      problems.push_back(key + ": missing");
    } else if (!v->is_string() || v->get_ref<const std::string&>().empty()) {
      problems.push_back(key + ": not a non-empty string");
    }
  }
  return problems;
}

namespace {
std::string FormatValue(const nlohmann::json* v) {
  if (!v) return "(missing)";
  if (v->is_number_integer()) return fmt::format("{}", v->get<std::int64_t>());
  if (v->is_number()) {
    const double d = v->get<double>();
    if (std::fabs(d) >= 1000.0) return fmt::format("{:.0f}", d);
    if (std::fabs(d) >= 10.0) return fmt::format("{:.1f}", d);
    return fmt::format("{:.3g}", d);
  }
  if (v->is_string()) return v->get<std::string>();
  return v->dump();
}
}  // namespace

std::string FormatTable(const nlohmann::json& report) {
  std::string out;
  std::vector<std::string> keys = DocumentedTextKeys();
  const std::vector<std::string> metrics = DocumentedMetricKeys();
  keys.insert(keys.end(), metrics.begin(), metrics.end());
  std::stable_sort(keys.begin(), keys.end(), [](const std::string& a, const std::string& b) {
    return a.substr(0, a.find('.')) < b.substr(0, b.find('.'));
  });
  std::string section;
  for (const auto& key : keys) {
    const std::string s = key.substr(0, key.find('.'));
    if (s != section) {
      out += fmt::format("{}{}\n", section.empty() ? "" : "\n", s);
      section = s;
    }
    out += fmt::format("  {:<36} {}\n", key, FormatValue(GetPath(report, key)));
  }
  return out;
}

}  // namespace wheelhil::emulator::bench
