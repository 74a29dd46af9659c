// Metric components (emulator/scoring/metric_components.h) and the estimate decoder
// (estimate_decoder.h): the firmware's FW_* frames become time-stamped estimates, each component
// adds its block only when selected, paper components against hand-computed values.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <string>

#include "bus/dbc.h"
#include "bus/dbc_codec.h"
#include "emulator/scoring/estimate_decoder.h"
#include "emulator/scoring/metric_components.h"
#include "emulator/scoring/truth_recorder.h"

namespace wheelhil::emulator::scoring {
namespace {

using nlohmann::json;

std::shared_ptr<const bus::DbcDatabase> FwDbc() {
  return std::make_shared<const bus::DbcDatabase>(
      bus::DbcDatabase::LoadFile(std::string(WHEELHIL_SOURCE_DIR) + "/bus/dbc/wheelhil_fw.dbc"));
}

// The reference firmware's binding, as the shipped scenarios name it.
OutputBinding ReferenceBinding() {
  const std::string dir = std::string(WHEELHIL_SOURCE_DIR) + "/scenarios";
  const bus::yaml::FieldReader r(dir + "/scenario.yaml");
  return OutputBinding::Resolve(
      ReadOutputs(r, YAML::Node("outputs/wheelhil_fw.yaml"), "firmware.outputs", dir),
      std::string(WHEELHIL_SOURCE_DIR) + "/bus/dbc");
}

bus::CanFrame Pose(const bus::DbcDatabase& db, const char* msg, const char* prefix, int cycle,
                   double x) {
  const bus::DbcMessage* m = db.FindMessage(msg);
  bus::SignalValues v;
  v[std::string(prefix) + "_Cycle"] = cycle;
  v[std::string(prefix) + "_X"] = x;
  v[std::string(prefix) + "_Y"] = 0.0;
  v[std::string(prefix) + "_Theta"] = 0.0;
  return bus::EncodeMessage(*m, v);
}

// A body moving at 1 m/s along x for 1 s, recorded at 10 Hz; the truth rows are the SYNCs.
TruthRecorder StraightTruth() {
  TruthRecorderOptions o;
  o.drive_wheels = {0};
  o.every_ns = 100'000'000;
  TruthRecorder truth(o);
  physics::BodyTruth b;
  std::vector<physics::WheelTruth> wheels(1);
  truth.StartMotion(0, b);
  for (int i = 0; i <= 10; ++i) {
    b.p_WB.x() = 0.1 * i;
    b.v_WB_W.x() = 1.0;
    truth.Record(i * 100'000'000LL, b, wheels, false);
  }
  return truth;
}

TEST(EstimateDecoder, StampsEstimatesWithTheirSyncAndIgnoresUnknownCycles) {
  const auto db = FwDbc();
  EstimateDecoder d(ReferenceBinding());
  d.OnSync(0.0);
  d.OnSync(0.25);
  d.OnFrame(Pose(*db, "FW_Pose", "Pose", 1, 0.5), 1.0);
  d.OnFrame(Pose(*db, "FW_Pose", "Pose", 7, 9.0), 1.0);  // no SYNC 7: ignored
  ASSERT_EQ(d.pose_streams().count("pose"), 1u);
  const auto& pose = d.pose_streams().at("pose");
  ASSERT_EQ(pose.size(), 1u);
  EXPECT_DOUBLE_EQ(pose[0].t_s, 0.25);
  EXPECT_NEAR(pose[0].x_m, 0.5, 5e-4);  // the signal's resolution
  ASSERT_EQ(d.rows().size(), 1u);
  EXPECT_EQ(d.rows()[0].stream, "pose");
}

TEST(MetricComponents, OnlySelectedComponentsAddBlocks) {
  const auto db = FwDbc();
  const TruthRecorder truth = StraightTruth();
  EstimateDecoder d(ReferenceBinding());
  d.OnSync(1.0);
  d.OnFrame(Pose(*db, "FW_Pose", "Pose", 0, 1.0 + 0.01), 1.0);     // corrected: 10 mm off
  d.OnFrame(Pose(*db, "FW_PoseRaw", "PoseRaw", 0, 1.0 + 0.1), 1.0);  // uncorrected: 100 mm off
  const RecordedRun run{truth, d, 0.25, {"left"}, SlipIntervals(truth), std::nullopt, false, {}};

  json generic = json::object();
  std::vector<json> events;
  ScoreRun(run, DefaultMetricComponents(), generic, events);
  EXPECT_TRUE(generic.contains("pose"));
  EXPECT_TRUE(generic.contains("pose_raw"));
  EXPECT_TRUE(generic.contains("truth"));
  EXPECT_FALSE(generic.contains("correction"));  // paper 000's: not selected

  json paper = json::object();
  ScoreRun(run, {"pose", "correction_ratio"}, paper, events);
  ASSERT_TRUE(paper.contains("correction"));
  EXPECT_NEAR(paper["correction"]["uncorrected_over_corrected"].get<double>(), 10.0, 0.1);
  EXPECT_TRUE(paper["correction"]["corrected_below_uncorrected"].get<bool>());
  EXPECT_FALSE(paper.contains("truth"));
  EXPECT_NEAR(paper["pose"]["final_position_error_m"].get<double>(), 0.01, 5e-4);
  EXPECT_NEAR(paper["pose"]["distance_m"].get<double>(), 1.0, 1e-12);
}

TEST(MetricComponents, UnknownComponentIsRefusedWithTheKnownOnes) {
  EXPECT_THAT([] { (void)MakeMetricComponent("ratio"); },
              ::testing::ThrowsMessage<std::invalid_argument>(
                  ::testing::HasSubstr("known: pose, correction_ratio, velocity")));
}

TEST(TruthRecorder, RowsAreRelativeToTheMotionStartAndSlipStepsBecomeIntervals) {
  TruthRecorderOptions o;
  o.drive_wheels = {0};
  o.slip_threshold_m_s = 0.05;
  o.every_ns = 1'000'000;
  o.step_ns = 1'000'000;
  TruthRecorder truth(o);
  physics::BodyTruth b;
  b.p_WB = {2.0, 1.0, 0.1};
  b.yaw_rad = 0.5;
  b.q_WB = Eigen::Quaterniond(Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitZ()));
  std::vector<physics::WheelTruth> wheels(1);
  truth.StartMotion(5'000'000, b);
  // 1 m ahead along the start heading.
  physics::BodyTruth b1 = b;
  b1.p_WB += Eigen::Vector3d(std::cos(0.5), std::sin(0.5), 0.0);
  truth.Record(6'000'000, b1, wheels, false);
  ASSERT_EQ(truth.rows().size(), 1u);
  EXPECT_NEAR(truth.rows()[0].x_m, 1.0, 1e-12);
  EXPECT_NEAR(truth.rows()[0].y_m, 0.0, 1e-12);
  EXPECT_NEAR(truth.rows()[0].t_s, 0.001, 1e-12);
  // Steps 1..30 ms: the wheel slips over [10, 20) ms.
  for (int i = 1; i <= 30; ++i) {
    wheels[0].slip_speed_m_s = (i > 10 && i <= 20) ? 0.1 : 0.0;
    truth.RecordMotionStep(5'000'000 + i * 1'000'000LL, wheels);
  }
  const auto iv = SlipIntervals(truth);
  ASSERT_EQ(iv.size(), 1u);
  EXPECT_NEAR(iv[0].start_s, 0.010, 1e-9);
  EXPECT_NEAR(iv[0].end_s, 0.020, 1e-9);
}

}  // namespace
}  // namespace wheelhil::emulator::scoring
