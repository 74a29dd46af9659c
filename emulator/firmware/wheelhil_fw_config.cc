#include "emulator/firmware/wheelhil_fw_config.h"

#include <filesystem>
#include <stdexcept>

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include "bus/yaml_fields.h"

namespace wheelhil::emulator::firmware {

namespace {

namespace fs = std::filesystem;

void Merge(YAML::Node base, const YAML::Node& over) {
  for (const auto& kv : over) {
    const std::string key = kv.first.as<std::string>();
    if (kv.second.IsMap() && base[key] && base[key].IsMap()) {
      Merge(base[key], kv.second);
    } else {
      base[key] = kv.second;
    }
  }
}

}  // namespace

std::string DerivedWheelhilFwConfig(const std::string& config_path,
                                    const std::string& overrides_yaml) {
  const bus::yaml::FieldReader reader(config_path);
  YAML::Node cfg = reader.Parse(reader.ReadFile());
  if (!overrides_yaml.empty()) {
    const bus::yaml::FieldReader overrides("firmware.config_overrides");
    Merge(cfg, overrides.Parse(overrides_yaml));
  }
  if (cfg["dbc_dir"] && cfg["dbc_dir"].IsScalar()) {
    const fs::path p(cfg["dbc_dir"].Scalar());
    if (p.is_relative()) {
      cfg["dbc_dir"] = (fs::path(config_path).parent_path() / p).lexically_normal().string();
    }
  }
  YAML::Emitter e;
  e << cfg;
  return std::string("# Derived by wheelhil run from ") + config_path + "\n" + e.c_str() + "\n";
}

}  // namespace wheelhil::emulator::firmware
