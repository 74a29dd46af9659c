#include "firmware_stub/fw_config.h"

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <stdexcept>

namespace wheelhil::fw {
namespace {

std::string Where(const std::string& path, const YAML::Node& node) {
  const YAML::Mark m = node.Mark();
  if (m.is_null()) return path;
  return fmt::format("{}:{}:{}", path, m.line + 1, m.column + 1);
}

}  // namespace

const char* EstimatorName(EstimatorKind kind) noexcept {
  switch (kind) {
    case EstimatorKind::kPaper000SlipCorrection:
      return "paper000";
    case EstimatorKind::kPaper001FollowerOdometry:
      return "paper001";
    case EstimatorKind::kPaper002Fusion:
      return "paper002";
  }
  return "?";
}

FwConfig LoadFwConfig(const std::string& path) {
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::BadFile&) {
    throw std::invalid_argument(fmt::format("{}: cannot open firmware config", path));
  } catch (const YAML::Exception& e) {
    throw std::invalid_argument(
        fmt::format("{}:{}:{}: {}", path, e.mark.line + 1, e.mark.column + 1, e.msg));
  }
  if (!root.IsMap()) {
    throw std::invalid_argument(fmt::format("{}: firmware config must be a YAML mapping", path));
  }
  FwConfig cfg;
  cfg.source_path = path;
  const YAML::Node est = root["estimator"];
  if (!est) throw std::invalid_argument(fmt::format("{}: missing field 'estimator'", path));
  const std::string name = est.as<std::string>();
  if (name == "paper000") {
    cfg.estimator = EstimatorKind::kPaper000SlipCorrection;
  } else if (name == "paper001") {
    cfg.estimator = EstimatorKind::kPaper001FollowerOdometry;
  } else if (name == "paper002") {
    cfg.estimator = EstimatorKind::kPaper002Fusion;
  } else {
    throw std::invalid_argument(
        fmt::format("{}: estimator: '{}' is not one of paper000, paper001, paper002",
                    Where(path, est), name));
  }
  return cfg;
}

}  // namespace wheelhil::fw
