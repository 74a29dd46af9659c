#pragma once
// Shared by the end-to-end scenario tests: the run options of this build tree (its wheelhil-fw,
// its DBC files, its libwheelhil_ucan.so for the firmware child) and reading an artefact whole.

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <yaml-cpp/yaml.h>
#include <nlohmann/json.hpp>

#include "bus/ucan_runtime_dir.h"
#include "emulator/scenario/runner.h"

namespace wheelhil::emulator::scenario::testing {

inline std::string Slurp(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// A run's report.json without its `wall` object (the only wall-clock fields), for comparing
/// two runs of one scenario and seed.
inline nlohmann::json ReportWithoutWall(const std::filesystem::path& run_dir) {
  nlohmann::json r = nlohmann::json::parse(Slurp(run_dir / "report.json"));
  r.erase("wall");
  return r;
}

/// The emulator produces SYNC (timing.sync_producer: emulator, an emulated CANopen master), the
/// firmware runs on the virtual clock as ever: for tests that need the SYNCs at the emulator's
/// instants. The reference firmware is told so through the scenario's overrides (the run
/// rewrites no config): it follows SYNC with the scenario's period as its cycle deadline.
inline void UseEmulatorSync(Scenario& s) {
  s.timing.firmware_produces_sync = false;
  s.timing.sync_producer_named = true;
  YAML::Node overrides = s.firmware.overrides_yaml.empty() ? YAML::Node(YAML::NodeType::Map)
                                                           : YAML::Load(s.firmware.overrides_yaml);
  overrides["sync"]["produce"] = false;
  overrides["sync"]["period_s"] = s.timing.sync_period_s;
  overrides["sync"]["deadline_s"] = s.timing.sync_period_s;
  YAML::Emitter out;
  out << overrides;
  s.firmware.overrides_yaml = out.c_str();
}

/// Options for a run into `out` with this build's programs and a private userspace bus.
inline RunOptions BuildTreeRunOptions(const std::filesystem::path& out) {
  RunOptions o;
  o.out_dir = out.string();
  o.bin_dir = std::string(WHEELHIL_BINARY_DIR) + "/bin";
  o.dbc_dir = std::string(WHEELHIL_SOURCE_DIR) + "/bus/dbc";
  o.ucan_child_env = [](const std::string& dir) {
    return bus::UcanChildEnvironment(std::string(WHEELHIL_BINARY_DIR) + "/lib/libwheelhil_ucan.so",
                                     dir);
  };
  return o;
}

}  // namespace wheelhil::emulator::scenario::testing
