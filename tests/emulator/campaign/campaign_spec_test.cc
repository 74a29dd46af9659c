#include "emulator/campaign/campaign_spec.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <filesystem>
#include <set>

#include "emulator/campaign/scenario_writer.h"
#include "tests/bus/yaml_fields_test_util.h"
#include "tests/emulator/campaign/campaign_test_util.h"

namespace wheelhil::emulator::campaign {
namespace {

using ::testing::HasSubstr;
using testing::kBaseScenario;
using testing::TempDir;
using ::testing::ThrowsMessage;

class CampaignSpecTest : public ::testing::Test {
 protected:
  CampaignSpecTest() { dir_.Write("base.yaml", kBaseScenario); }
  CampaignSpec Parse(const std::string& text) {
    return ParseCampaign(text, (dir_.path() / "camp.yaml").string());
  }
  TempDir dir_;
};

TEST(ShippedCampaigns, EveryCampaignLoadsAndExpands) {
  int loaded = 0;
  for (const auto& e : std::filesystem::directory_iterator(std::string(WHEELHIL_SOURCE_DIR) +
                                                           "/scenarios/campaigns")) {
    if (e.path().extension() != ".yaml") continue;
    SCOPED_TRACE(e.path().string());
    CampaignSpec spec;
    ASSERT_NO_THROW(spec = LoadCampaignFile(e.path()));
    EXPECT_FALSE(ExpandRuns(spec).empty());
    EXPECT_TRUE(std::filesystem::is_regular_file(spec.base_scenario)) << spec.base_scenario;
    ++loaded;
  }
  EXPECT_GE(loaded, 4);  // paper 000, 001, 002 and the bus-fault campaign
}

TEST_F(CampaignSpecTest, GridIsTheProductOfListsAndRangesTimesRepeats) {
  const auto spec = Parse(R"(campaign: grid
base: base.yaml
sampling: grid
repeats: 2
seed: 42
parameters:
  - path: terrain.friction
    values: [0.2, 0.5, 0.9]
  - path: faults[0].probability
    range: {from: 0.0, to: 0.3, steps: 4}
)");
  const auto runs = ExpandRuns(spec);
  ASSERT_EQ(runs.size(), 3u * 4u * 2u);
  std::set<std::string> keys;
  std::set<std::uint64_t> seeds;
  std::set<std::pair<double, double>> points;
  for (const auto& r : runs) {
    keys.insert(r.key);
    seeds.insert(r.seed);
    points.emplace(r.values[0].get<double>(), r.values[1].get<double>());
    EXPECT_EQ(r.index, &r - runs.data());
    EXPECT_EQ(r.point, r.index / 2);
    EXPECT_EQ(r.repeat, r.index % 2);
  }
  EXPECT_EQ(keys.size(), runs.size());
  EXPECT_EQ(seeds.size(), runs.size()) << "every repeat gets its own seed";
  EXPECT_EQ(points.size(), 12u);
  // Range values: exact end points, evenly spaced, first parameter slowest.
  EXPECT_DOUBLE_EQ(runs[0].values[1].get<double>(), 0.0);
  EXPECT_DOUBLE_EQ(runs[2].values[1].get<double>(), 0.1);
  EXPECT_DOUBLE_EQ(runs[4].values[1].get<double>(), 0.2);
  EXPECT_DOUBLE_EQ(runs[6].values[1].get<double>(), 0.3);
  EXPECT_DOUBLE_EQ(runs[7].values[0].get<double>(), 0.2);
  EXPECT_DOUBLE_EQ(runs[8].values[0].get<double>(), 0.5);
}

TEST_F(CampaignSpecTest, ExpansionIsDeterministicAndSeedDependent) {
  const std::string text = R"(base: base.yaml
sampling: random
runs: 50
seed: 7
repeats: 3
parameters:
  - path: terrain.friction
    uniform: {min: 0.1, max: 1.0}
  - path: sensors.gyro_bias_rad_s
    normal: {mean: 0.0, stddev: 0.01}
  - path: faults[0].kind
    values: [frame_loss, delay]
)";
  const auto a = ExpandRuns(Parse(text));
  const auto b = ExpandRuns(Parse(text));
  ASSERT_EQ(a.size(), 150u);
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].key, b[i].key);
    EXPECT_EQ(a[i].seed, b[i].seed);
    EXPECT_EQ(a[i].values, b[i].values);
    const double f = a[i].values[0].get<double>();
    EXPECT_GE(f, 0.1);
    EXPECT_LT(f, 1.0);
    EXPECT_TRUE(std::isfinite(a[i].values[1].get<double>()));
    EXPECT_LT(a[i].seed, 1ULL << 31);
  }
  // Golden values pin the arithmetic across platforms and refactors.
  EXPECT_EQ(a[0].key.substr(0, 9), "p00000-r0");
  std::string other = text;
  other.replace(other.find("seed: 7"), 7, "seed: 8");
  const auto c = ExpandRuns(Parse(other));
  int same = 0;
  for (std::size_t i = 0; i < a.size(); ++i) same += a[i].values[0] == c[i].values[0];
  EXPECT_EQ(same, 0) << "another seed samples other points";
  // Both list entries are drawn, in roughly equal numbers.
  int delay = 0;
  for (std::size_t i = 0; i < a.size(); i += 3) delay += a[i].values[2] == "delay";
  EXPECT_GT(delay, 10);
  EXPECT_LT(delay, 40);
  // Sample mean/stddev of the normal parameter near 0 / 0.01 (50 points: loose bounds).
  double sum = 0, sq = 0;
  for (std::size_t i = 0; i < a.size(); i += 3) {
    const double v = a[i].values[1].get<double>();
    sum += v;
    sq += v * v;
  }
  const double mean = sum / 50, sd = std::sqrt(sq / 50 - mean * mean);
  EXPECT_NEAR(mean, 0.0, 0.005);
  EXPECT_NEAR(sd, 0.01, 0.004);
}

TEST_F(CampaignSpecTest, LatinHypercubeUsesEveryStratumOncePerDimension) {
  const auto spec = Parse(R"(base: base.yaml
sampling: lhs
runs: 40
seed: 3
parameters:
  - path: terrain.friction
    uniform: {min: 0.0, max: 2.0}
  - path: faults[0].probability
    range: {from: 0.0, to: 0.4, steps: 2}
  - path: sensors.gyro_bias_rad_s
    normal: {mean: 1.0, stddev: 0.5}
)");
  const auto runs = ExpandRuns(spec);
  ASSERT_EQ(runs.size(), 40u);
  std::multiset<int> s0, s1, s2;
  for (const auto& r : runs) {
    s0.insert(static_cast<int>(std::floor(r.values[0].get<double>() / 2.0 * 40)));
    s1.insert(static_cast<int>(std::floor(r.values[1].get<double>() / 0.4 * 40)));
    const double z = (r.values[2].get<double>() - 1.0) / 0.5;
    const double u = 0.5 * std::erfc(-z / std::sqrt(2.0));
    s2.insert(static_cast<int>(std::floor(u * 40)));
  }
  for (int k = 0; k < 40; ++k) {
    EXPECT_EQ(s0.count(k), 1u) << "friction stratum " << k;
    EXPECT_EQ(s1.count(k), 1u) << "probability stratum " << k;
    EXPECT_EQ(s2.count(k), 1u) << "normal stratum " << k;
  }
}

TEST_F(CampaignSpecTest, InverseNormalCdfMatchesErf) {
  for (double p : {1e-9, 1e-4, 0.02, 0.1, 0.5, 0.7, 0.975, 0.999999}) {
    const double x = InverseNormalCdf(p);
    EXPECT_NEAR(0.5 * std::erfc(-x / std::sqrt(2.0)), p, 1e-12 + 1e-9 * p) << p;
  }
  EXPECT_NEAR(InverseNormalCdf(0.975), 1.959963984540054, 1e-9);
}

TEST_F(CampaignSpecTest, CriteriaAreParsed) {
  const auto spec = Parse(R"(base: base.yaml
parameters:
  - path: terrain.friction
    values: [0.5]
pass:
  verdict: false
  run:
    - {metric: pose.final_position_error_m, max: 0.1}
  campaign:
    - {pass_rate: 0.9}
    - {metric: pose.final_position_error_m, max: 0.05, fraction: 0.95}
)");
  EXPECT_FALSE(spec.require_verdict_pass);
  ASSERT_EQ(spec.run_criteria.size(), 1u);
  EXPECT_TRUE(spec.run_criteria[0].Holds(0.1));
  EXPECT_FALSE(spec.run_criteria[0].Holds(0.1000001));
  EXPECT_FALSE(spec.run_criteria[0].Holds(std::nullopt));
  ASSERT_EQ(spec.campaign_criteria.size(), 2u);
  EXPECT_FALSE(spec.campaign_criteria[0].bound.has_value());
  EXPECT_DOUBLE_EQ(spec.campaign_criteria[1].fraction, 0.95);
  EXPECT_EQ(spec.rank_metric, "pose.final_position_error_m");
  EXPECT_EQ(spec.campaign_criteria[1].Describe(),
            ">= 95 % of runs with pose.final_position_error_m <= 0.05");
}

TEST(ShippedCampaigns, DamagedCampaignsGiveOnlyLocatedInputErrors) {
  for (const auto& e : std::filesystem::directory_iterator(std::string(WHEELHIL_SOURCE_DIR) +
                                                           "/scenarios/campaigns")) {
    if (e.path().extension() != ".yaml") continue;
    SCOPED_TRACE(e.path().string());
    const std::string path = e.path().string();
    yaml_mutation::ExpectOnlyLocatedInputErrors(
        yaml_mutation::ReadText(path), path,
        [&](const std::string& text) { (void)ParseCampaign(text, path); });
  }
}

TEST_F(CampaignSpecTest, LoadErrorsNameFileLineAndField) {
  const std::string file = (dir_.path() / "camp.yaml").string();
  EXPECT_THAT(
      [&] { Parse("base: base.yaml\nparameterz: []\n"); },
      ThrowsMessage<std::invalid_argument>(HasSubstr(file + ":2:1: parameterz: unknown key")));
  EXPECT_THAT([&] { Parse("base: nothere.yaml\nparameters: [{path: a, values: [1]}]\n"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr(":1:7: base: scenario")));
  EXPECT_THAT(
      [&] {
        Parse(
            "base: base.yaml\nparameters:\n  - path: terrain.friction\n    uniform: {min: 0, max: "
            "1}\n");
      },
      ThrowsMessage<std::invalid_argument>(
          HasSubstr(":3:5: parameters[0]: a random distribution")));
  EXPECT_THAT(
      [&] { Parse("base: base.yaml\nsampling: lhs\nparameters: [{path: a, values: [1]}]\n"); },
      ThrowsMessage<std::invalid_argument>(HasSubstr("runs")));
  EXPECT_THAT(
      [&] {
        Parse("base: base.yaml\nparameters:\n  - path: a\n    range: {from: 0, to: 1, steps: 0}\n");
      },
      ThrowsMessage<std::invalid_argument>(HasSubstr(":4:36: parameters[0].range.steps")));
}

TEST_F(CampaignSpecTest, ParameterPathMissingFromBaseNamesCampaignLineAndPath) {
  const auto spec = Parse(R"(base: base.yaml
parameters:
  - path: terrain.friction
    values: [0.5]
  - path: faults[2].probability
    values: [0.1]
)");
  EXPECT_THAT([&] { CheckParameterPaths(spec); },
              ThrowsMessage<std::invalid_argument>(HasSubstr(
                  "camp.yaml:5:5: path: faults[2].probability: 'faults[2]' does not exist "
                  "in the base scenario ('faults' has 1 entries)")));
  const auto typo = Parse("base: base.yaml\nparameters:\n  - {path: terrain.frict, values: [1]}\n");
  EXPECT_THAT([&] { CheckParameterPaths(typo); },
              ThrowsMessage<std::invalid_argument>(
                  HasSubstr("camp.yaml:3:5: path: terrain.frict: 'terrain.frict' does not exist")));
}

TEST_F(CampaignSpecTest, SetOverridesMayAddALeafThatParametersThenVary) {
  const auto spec = Parse(R"(base: base.yaml
set:
  sensors.gyro_noise: 0.5
  fake.sleep_s: 0.25
parameters:
  - path: sensors.gyro_noise
    values: [0.125]
)");
  ASSERT_EQ(spec.overrides.size(), 2u);
  EXPECT_NO_THROW(CheckParameterPaths(spec));
  const auto out = dir_.path() / "set.yaml";
  WriteRunScenario(spec, ExpandRuns(spec).at(0), out);
  const YAML::Node n = YAML::LoadFile(out.string());
  EXPECT_DOUBLE_EQ(n["sensors"]["gyro_noise"].as<double>(), 0.125);
  EXPECT_DOUBLE_EQ(n["fake"]["sleep_s"].as<double>(), 0.25);
  const auto bad = Parse(
      "base: base.yaml\nset:\n  nothere.x: 1\nparameters: [{path: terrain.friction, values: "
      "[1]}]\n");
  EXPECT_THAT([&] { CheckParameterPaths(bad); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("camp.yaml:3:3: set: nothere.x")));
}

TEST_F(CampaignSpecTest, SetAtPathWritesMapsAndSequences) {
  YAML::Node root = YAML::Load(kBaseScenario);
  SetAtPath(root, "faults[0].probability", 0.25, "here");
  SetAtPath(root, "terrain.friction", 0.3, "here");
  SetAtPath(root, "faults[0].kind", "delay", "here");
  EXPECT_DOUBLE_EQ(root["faults"][0]["probability"].as<double>(), 0.25);
  EXPECT_DOUBLE_EQ(root["terrain"]["friction"].as<double>(), 0.3);
  EXPECT_EQ(root["faults"][0]["kind"].as<std::string>(), "delay");
  EXPECT_EQ(root["sensors"]["gyro_bias_rad_s"].as<double>(), 0.0) << "others untouched";
  EXPECT_THAT([&] { SetAtPath(root, "terrain", 1.0, "here"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("is not a scalar")));
  EXPECT_THAT([&] { SetAtPath(root, "terrain[0]", 1.0, "here"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("'terrain' is not a list")));
  EXPECT_THAT([&] { SetAtPath(root, "a..b", 1.0, "here"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("empty segment")));
}

TEST_F(CampaignSpecTest, WrittenScenarioHasValuesAndAbsolutePaths) {
  dir_.Write("meshes/floor.obj", "v 0 0 0\n");
  dir_.Write("with_mesh.yaml", std::string(kBaseScenario) + "mesh: meshes/floor.obj\n");
  const auto spec = Parse(R"(base: with_mesh.yaml
parameters:
  - path: faults[0].probability
    values: [0.125]
)");
  const auto runs = ExpandRuns(spec);
  const auto out = dir_.path() / "out" / "scenario.yaml";
  std::filesystem::create_directories(out.parent_path());
  WriteRunScenario(spec, runs.at(0), out);
  const YAML::Node n = YAML::LoadFile(out.string());
  EXPECT_DOUBLE_EQ(n["faults"][0]["probability"].as<double>(), 0.125);
  EXPECT_EQ(n["mesh"].as<std::string>(), (dir_.path() / "meshes/floor.obj").string());
  EXPECT_EQ(n["name"].as<std::string>(), "fake_base");
}

TEST_F(CampaignSpecTest, ListValuesReplaceListsAndFileValuesResolveAgainstTheCampaign) {
  dir_.Write("with_list.yaml",
             std::string(kBaseScenario) + "bias: [0.1, 0.2, 0.3, 0.4]\nfloor: {mesh: none.obj}\n");
  dir_.Write("meshes/rough.obj", "v 0 0 0\n");
  const auto spec = Parse(R"(base: with_list.yaml
set:
  bias[3]: 0.5
parameters:
  - path: bias
    values: [[0, 0, 0, 0], [0.01, -0.01, 0.01, -0.01]]
  - path: floor.mesh
    values: [meshes/rough.obj, not/a/file.obj]
)");
  ASSERT_EQ(spec.parameters[0].values.size(), 2u);
  EXPECT_TRUE(spec.parameters[0].values[1].is_array());
  EXPECT_NO_THROW(CheckParameterPaths(spec));
  const auto runs = ExpandRuns(spec);
  ASSERT_EQ(runs.size(), 4u);
  EXPECT_NE(runs[0].key, runs[2].key);
  const auto out = dir_.path() / "list.yaml";
  WriteRunScenario(spec, runs.at(2), out);  // bias point 1, mesh point 0
  const YAML::Node n = YAML::LoadFile(out.string());
  ASSERT_TRUE(n["bias"].IsSequence());
  ASSERT_EQ(n["bias"].size(), 4u);
  EXPECT_DOUBLE_EQ(n["bias"][1].as<double>(), -0.01);
  EXPECT_DOUBLE_EQ(n["bias"][3].as<double>(), -0.01);
  EXPECT_EQ(n["floor"]["mesh"].as<std::string>(), (dir_.path() / "meshes/rough.obj").string());
  WriteRunScenario(spec, runs.at(1), out);
  EXPECT_EQ(YAML::LoadFile(out.string())["floor"]["mesh"].as<std::string>(), "not/a/file.obj");
  // Shapes must match: a list for a scalar or a scalar for a list is refused.
  YAML::Node root = YAML::Load(kBaseScenario);
  EXPECT_THAT(
      [&] {
        SetAtPath(root, "terrain.friction", nlohmann::json::array({1, 2}), "here");
      },
      ThrowsMessage<std::invalid_argument>(HasSubstr("is not a list")));
  EXPECT_THAT(
      [&] {
        CheckParameterPaths(
            Parse("base: with_list.yaml\nparameters: [{path: bias, values: [1]}]\n"));
      },
      ThrowsMessage<std::invalid_argument>(HasSubstr("'bias' is not a scalar")));
  EXPECT_THAT([&] { Parse("base: base.yaml\nparameters: [{path: x, values: [[]]}]\n"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("must not be empty")));
  EXPECT_THAT([&] { Parse("base: base.yaml\nparameters: [{path: x, values: [[[1]]]}]\n"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("scalars only")));
}

TEST_F(CampaignSpecTest, LinkedPathsGetOneValue) {
  dir_.Write("axes.yaml", std::string(kBaseScenario) + "axes: {x: {d: 0.1}, y: {d: 0.1}}\n");
  const auto spec = Parse(R"(base: axes.yaml
parameters:
  - path: [axes.x.d, axes.y.d]
    values: [0.02, 0.5]
  - path: terrain.friction
    values: [0.4]
)");
  ASSERT_EQ(spec.parameters[0].paths.size(), 2u);
  EXPECT_EQ(spec.parameters[0].path, "axes.x.d + axes.y.d");
  EXPECT_EQ(spec.parameters[1].paths, std::vector<std::string>{"terrain.friction"});
  EXPECT_NO_THROW(CheckParameterPaths(spec));
  const auto runs = ExpandRuns(spec);
  ASSERT_EQ(runs.size(), 2u);
  EXPECT_EQ(runs[1].ParamsJson(spec)["axes.x.d + axes.y.d"], 0.5);
  const auto out = dir_.path() / "linked.yaml";
  WriteRunScenario(spec, runs.at(1), out);
  const YAML::Node n = YAML::LoadFile(out.string());
  EXPECT_DOUBLE_EQ(n["axes"]["x"]["d"].as<double>(), 0.5);
  EXPECT_DOUBLE_EQ(n["axes"]["y"]["d"].as<double>(), 0.5);
  // Every linked path must exist; a path may be varied once only.
  EXPECT_THAT(
      [&] {
        CheckParameterPaths(
            Parse("base: axes.yaml\nparameters: [{path: [axes.x.d, axes.z.d], values: [1]}]\n"));
      },
      ThrowsMessage<std::invalid_argument>(HasSubstr("'axes.z' does not exist")));
  EXPECT_THAT(
      [&] {
        Parse(
            "base: axes.yaml\nparameters: [{path: [axes.x.d], values: [1]}, {path: axes.x.d, "
            "values: [2]}]\n");
      },
      ThrowsMessage<std::invalid_argument>(HasSubstr("varied twice")));
}

TEST_F(CampaignSpecTest, ShardsPartitionTheRunList) {
  const auto spec = Parse(R"(base: base.yaml
parameters:
  - path: terrain.friction
    range: {from: 0.1, to: 1.0, steps: 10}
  - path: faults[0].probability
    values: [0, 0.1, 0.2]
)");
  const auto runs = ExpandRuns(spec);
  std::multiset<std::string> seen;
  for (int k = 0; k < 4; ++k) {
    const auto part = SelectShard(runs, Shard::Parse(std::to_string(k) + "/4"));
    EXPECT_GE(part.size(), 7u);
    EXPECT_LE(part.size(), 8u);
    for (const auto& r : part) seen.insert(r.key);
  }
  EXPECT_EQ(seen.size(), runs.size());
  for (const auto& r : runs) EXPECT_EQ(seen.count(r.key), 1u);
  EXPECT_THROW(Shard::Parse("4/4"), std::invalid_argument);
  EXPECT_THROW(Shard::Parse("1/0"), std::invalid_argument);
  EXPECT_THROW(Shard::Parse("a/b"), std::invalid_argument);
  EXPECT_THROW(Shard::Parse("1"), std::invalid_argument);
  EXPECT_THROW(Shard::Parse("1/2x"), std::invalid_argument);
}

TEST_F(CampaignSpecTest, FingerprintFollowsTheBaseScenario) {
  const std::string text = "base: base.yaml\nparameters: [{path: terrain.friction, values: [1]}]\n";
  const auto a = Parse(text);
  dir_.Write("base.yaml", std::string(kBaseScenario) + "# changed\n");
  const auto b = Parse(text);
  EXPECT_NE(a.fingerprint, b.fingerprint);
  EXPECT_NE(ExpandRuns(a)[0].key, ExpandRuns(b)[0].key);
}

}  // namespace
}  // namespace wheelhil::emulator::campaign
