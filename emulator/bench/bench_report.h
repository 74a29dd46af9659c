#pragma once
/// The report of `wheelhil bench`: one JSON object whose dotted key paths name what they
/// measure (`physics.diff2.flat_rtf`, `bus.ucan_frames_per_s`, `realtime.p99_us`, ...), the
/// machine facts, statistics helpers, and the check that a report carries every documented key
/// with a finite number or an explicit "unavailable: <reason>" string. The key list here is the
/// one docs/performance.md documents (a test keeps them in step). Thread-compatible.

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

namespace wheelhil::emulator::bench {

/// CPU model, cores and build type, and when/where the bench ran.
struct MachineFacts {
  std::string cpu_model;   ///< "model name" of /proc/cpuinfo ("unknown" when absent).
  int cores = 0;           ///< Online CPUs (sysconf(_SC_NPROCESSORS_ONLN)).
  std::string build_type;  ///< CMAKE_BUILD_TYPE of this binary (WHEELHIL_BUILD_TYPE).
  std::string kernel;      ///< uname -sr.
  std::string date_utc;    ///< ISO 8601, when the facts were read.
};
MachineFacts ReadMachineFacts();
/// The first "model name" (x86) / "Model" / "Hardware" / "cpu model" line of a /proc/cpuinfo
/// text; "unknown" when none.
std::string CpuModelFromCpuinfo(std::string_view cpuinfo);
/// Build type compiled into this binary.
std::string CompiledBuildType();

/// Nearest-rank percentile (p in [0, 100]) of `values`; NaN for an empty input. Sorts a copy.
double Percentile(std::vector<double> values, double p);
/// Median of `values`; NaN for an empty input.
double Median(std::vector<double> values);

/// A value that could not be measured: the string "unavailable: <reason>".
std::string Unavailable(std::string_view reason);
bool IsUnavailable(const nlohmann::json& value);

/// Sets report[a][b][c] for path "a.b.c" (creating objects on the way).
void SetPath(nlohmann::json& report, std::string_view dotted_path, nlohmann::json value);
/// The value at "a.b.c", or nullptr when absent.
const nlohmann::json* GetPath(const nlohmann::json& report, std::string_view dotted_path);

/// Physics platforms measured (files scenarios/platforms/<name>.yaml).
const std::vector<std::string>& BenchPlatforms();
/// Paper scenarios of the lockstep rows.
const std::vector<std::string>& BenchScenarios();
/// Those also measured on the firmware's virtual clock (virtual_time.<paper>.rtf).
const std::vector<std::string>& VirtualTimeBenchScenarios();
/// The hand-over figures of each virtual-time row (virtual_time.<row>.<key>), from the run's
/// report.json wall block (docs/performance.md).
const std::vector<const char*>& HandoverAccountKeys();
/// Every documented numeric key (finite number or "unavailable: ...").
std::vector<std::string> DocumentedMetricKeys();
/// Every documented text key (machine facts, notes).
std::vector<std::string> DocumentedTextKeys();
/// Problems of a report: "<key>: missing", "<key>: not a finite number or an unavailable
/// reason", ... Empty when the report is complete.
std::vector<std::string> CheckReport(const nlohmann::json& report);

/// The human-readable table: one "key  value" line per documented key, grouped by section.
std::string FormatTable(const nlohmann::json& report);

}  // namespace wheelhil::emulator::bench
