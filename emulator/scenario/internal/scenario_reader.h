#pragma once
// The scenario loader's shared parts (emulator/scenario/scenario.cc, scenario_sensors.cc,
// scenario_faults.cc): the field reader with paths relative to the scenario file, and the
// section readers each file owns. Not for other modules.

#include <filesystem>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <yaml-cpp/yaml.h>

#include "bus/dbc.h"
#include "bus/yaml_fields.h"
#include "emulator/scenario/scenario.h"

namespace wheelhil::emulator::scenario::internal {

// Scenario fields; relative paths resolve against the scenario file's folder.
class Reader : public bus::yaml::FieldReader {
 public:
  explicit Reader(std::string file)
      : FieldReader(std::move(file)), base_dir_(std::filesystem::path(this->file()).parent_path()) {}

  std::string Path(const std::string& p) const {
    if (p.empty() || std::filesystem::path(p).is_absolute()) return p;
    return (base_dir_ / p).lexically_normal().string();
  }

 private:
  std::filesystem::path base_dir_;
};

inline Friction ReadFriction(const Reader& r, const YAML::Node& n, const std::string& field,
                             Friction def) {
  Friction f;
  f.mu_peak = r.Number(n, "mu_peak", field, 0, 10, def.mu_peak);
  f.mu_slide = r.Number(n, "mu_slide", field, 0, 10, std::min(def.mu_slide, f.mu_peak));
  if (f.mu_slide > f.mu_peak) {
    r.FailKey(n, "mu_slide", field + ".mu_slide", "must not exceed mu_peak");
  }
  return f;
}

/// The DBC file at `path` that parent[key] names; its load error fails at that key.
inline std::shared_ptr<const bus::DbcDatabase> LoadDbcAt(const Reader& r, const YAML::Node& parent,
                                                         const std::string& key,
                                                         const std::string& field,
                                                         const std::string& path) {
  try {
    return std::make_shared<const bus::DbcDatabase>(bus::DbcDatabase::LoadFile(path));
  } catch (const std::exception& e) {
    r.FailKey(parent, key, field, e.what());
  }
}

/// sensors: (scenario_sensors.cc).
SensorsSpec ReadSensors(const Reader& r, const YAML::Node& root, const platforms::Platform& platform);
/// devices: (scenario_devices.cc).
std::vector<DeviceSpec> ReadDevices(const Reader& r, const YAML::Node& n,
                                    const platforms::Platform& platform,
                                    const SensorsSpec& sensors);
/// faults: (scenario_faults.cc).
std::vector<FaultSpec> ReadFaults(const Reader& r, const YAML::Node& n, const SensorsSpec& s,
                                  const std::vector<DeviceSpec>& devices,
                                  const platforms::Platform& platform);

}  // namespace wheelhil::emulator::scenario::internal
