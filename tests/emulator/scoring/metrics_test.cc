// Metrics (emulator/scoring/metrics.h) against analytic cases, and expectation evaluation.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "emulator/scoring/metrics.h"
#include "emulator/scoring/expectations.h"

namespace wheelhil::emulator::scoring {
namespace {

std::vector<PoseSample> Straight(double v, double t_end, double dt) {
  std::vector<PoseSample> p;
  for (double t = 0; t <= t_end + 1e-9; t += dt) p.push_back({t, v * t, 0, 0});
  return p;
}

TEST(Metrics, WrapAngle) {
  EXPECT_NEAR(WrapAngle(3 * std::numbers::pi), std::numbers::pi, 1e-12);
  EXPECT_NEAR(WrapAngle(-std::numbers::pi / 2 - 2 * std::numbers::pi), -std::numbers::pi / 2,
              1e-12);
}

TEST(Metrics, FinalPositionErrorIsEq13) {
  const auto truth = Straight(0.25, 40, 0.01);
  std::vector<PoseSample> est = Straight(0.25, 40, 0.25);
  est.back().x_m += 0.03;
  est.back().y_m -= 0.04;
  est.back().theta_rad = 0.1;
  const PoseMetrics m = ComputePoseMetrics(truth, est);
  EXPECT_NEAR(m.final_position_error_m, 0.05, 1e-9);
  EXPECT_NEAR(m.final_heading_error_rad, 0.1, 1e-12);
  EXPECT_NEAR(m.distance_m, 10.0, 1e-9);
  EXPECT_NEAR(m.rotation_rad, 0.0, 1e-12);
  // One of 161 samples off by 0.05 m.
  EXPECT_NEAR(m.ape_rmse_m, std::sqrt(0.05 * 0.05 / 161.0), 1e-9);
}

TEST(Metrics, ApeAlignsByTime) {
  // Truth at 100 Hz, estimate at odd instants on the same line: zero error after interpolation.
  const auto truth = Straight(1.0, 5, 0.01);
  std::vector<PoseSample> est;
  for (double t = 0.003; t < 5; t += 0.137) est.push_back({t, t, 0, 0});
  EXPECT_NEAR(ComputePoseMetrics(truth, est).ape_rmse_m, 0.0, 1e-9);
  // A constant 0.1 m lateral offset gives an RMSE of 0.1 m.
  for (auto& p : est) p.y_m = 0.1;
  EXPECT_NEAR(ComputePoseMetrics(truth, est).ape_rmse_m, 0.1, 1e-9);
}

TEST(Metrics, RotationOfACircle) {
  std::vector<PoseSample> truth;
  const double r = 2.0;
  for (int i = 0; i <= 1000; ++i) {
    const double a = 2 * std::numbers::pi * i / 1000;
    truth.push_back({i * 0.01, r * std::sin(a), r * (1 - std::cos(a)), a});
  }
  EXPECT_NEAR(TotalRotation(truth), 2 * std::numbers::pi, 1e-9);
  EXPECT_NEAR(PathLength(truth), 2 * std::numbers::pi * r, 1e-3);
}

TEST(Metrics, VelocityRmse) {
  std::vector<VelocitySample> truth, est;
  for (int i = 0; i <= 100; ++i) truth.push_back({i * 0.01, 0.1, 0, 0});
  for (int i = 0; i < 10; ++i) est.push_back({i * 0.1, 0.1 + (i % 2 ? 0.02 : -0.02), 0, 0});
  EXPECT_NEAR(VelocityRmse(truth, est), 0.02, 1e-12);
}

TEST(Metrics, FlagsToIntervalsMergesAndDrops) {
  std::vector<double> t;
  std::vector<bool> f;
  for (int i = 0; i < 100; ++i) {
    t.push_back(i * 0.01);
    f.push_back((i >= 10 && i < 20) || (i >= 22 && i < 30) || i == 50);
  }
  const auto iv = FlagsToIntervals(t, f, 0.01, 0.02, 0.02);
  ASSERT_EQ(iv.size(), 1u);  // 10..20 and 22..30 merged; the single step at 50 dropped.
  EXPECT_NEAR(iv[0].start_s, 0.10, 1e-12);
  EXPECT_NEAR(iv[0].end_s, 0.30, 1e-12);
}

TEST(Metrics, SlipPrecisionRecallLatency) {
  // Truth: slip in [1.1, 1.3) and [3.0, 3.2). Cycles of 0.25 s ending at 0.25, 0.5, ...
  const std::vector<Interval> truth{{1.1, 1.3}, {3.0, 3.2}};
  std::vector<DetectionSample> d;
  for (int k = 1; k <= 20; ++k) {
    const double t = 0.25 * k;
    // Detected: the cycle ending at 1.25 (TP), 1.5 (TP: overlaps 1.25..1.3), 2.0 (FP).
    // Missed: the cycle ending at 3.25 (FN).
    d.push_back({t, t == 1.25 || t == 1.5 || t == 2.0});
  }
  const SlipMetrics m = ComputeSlipMetrics(truth, d, 0.25);
  EXPECT_EQ(m.true_positive, 2u);
  EXPECT_EQ(m.false_positive, 1u);
  EXPECT_EQ(m.false_negative, 1u);
  EXPECT_NEAR(m.precision, 2.0 / 3.0, 1e-12);
  EXPECT_NEAR(m.recall, 2.0 / 3.0, 1e-12);
  ASSERT_TRUE(m.mean_latency_s.has_value());
  EXPECT_NEAR(*m.mean_latency_s, 0.15, 1e-12);  // 1.25 - 1.1
  EXPECT_EQ(m.intervals_detected, 1u);
}

TEST(Expectations, CompareAgainstValuesAndMetrics) {
  const nlohmann::json metrics = {{"pose", {{"err", 0.05}}}, {"pose_raw", {{"err", 0.4}}}};
  std::vector<Expectation> ex{{"pose.err", "<", std::nullopt, "pose_raw.err", ""},
                              {"pose.err", "<=", 0.01, "", ""},
                              {"pose.missing", ">", 0.0, "", ""}};
  nlohmann::json out;
  EXPECT_FALSE(EvaluateExpectations(ex, metrics, out));
  ASSERT_EQ(out.size(), 3u);
  EXPECT_TRUE(out[0]["passed"].get<bool>());
  EXPECT_FALSE(out[1]["passed"].get<bool>());
  EXPECT_FALSE(out[2]["passed"].get<bool>());
  EXPECT_TRUE(out[2].contains("problem"));
  ex.resize(1);
  EXPECT_TRUE(EvaluateExpectations(ex, metrics, out));
}

}  // namespace
}  // namespace wheelhil::emulator::scoring
