#include "firmware_stub/fw_config.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <stdexcept>

#include "tests/bus/yaml_fields_test_util.h"

namespace wheelhil::fw {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

std::string WriteTemp(const std::string& name, const std::string& text) {
  const auto path = std::filesystem::path(::testing::TempDir()) / name;
  std::ofstream(path) << text;
  return path.string();
}

TEST(FwConfig, ReadsEstimator) {
  const auto path = WriteTemp("fw_ok.yaml", R"(estimator: paper001
sync: {period_s: 0.01}
paper001:
  mount_radius_m: 0.2
  follower_radius_m: 0.024
  counts_per_rev: 4096
  followers:
    - {node_id: 1, angle_deg: 90}
    - {node_id: 2, angle_deg: 210}
    - {node_id: 3, angle_deg: 330}
)");
  EXPECT_EQ(LoadFwConfig(path).estimator, EstimatorKind::kPaper001FollowerOdometry);
}

TEST(FwConfig, UnknownEstimatorNamesFileLineAndField) {
  const auto path = WriteTemp("fw_bad.yaml", "# comment\nestimator: paper999\n");
  EXPECT_THAT([&] { LoadFwConfig(path); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("fw_bad.yaml:2:12: estimator")));
}

TEST(FwConfig, DamagedShippedConfigsGiveOnlyLocatedInputErrors) {
  for (const auto& e : std::filesystem::directory_iterator(std::string(WHEELHIL_SOURCE_DIR) +
                                                           "/scenarios/firmware")) {
    if (e.path().extension() != ".yaml") continue;
    SCOPED_TRACE(e.path().string());
    const std::string path = e.path().string();
    yaml_mutation::ExpectOnlyLocatedInputErrors(
        yaml_mutation::ReadText(path), path,
        [&](const std::string& text) { (void)ParseFwConfig(text, path); });
  }
}

TEST(FwConfig, MissingFileIsNamed) {
  EXPECT_THAT([] { LoadFwConfig("/nonexistent/fw.yaml"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("/nonexistent/fw.yaml")));
}

}  // namespace
}  // namespace wheelhil::fw
