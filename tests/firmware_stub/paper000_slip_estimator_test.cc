#include "firmware_stub/paper000_slip_estimator.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <numbers>
#include <random>
#include <stdexcept>

#include "firmware_stub/encoder_counter.h"

namespace wheelhil::fw {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

constexpr double kB = 0.5;           // Track width [m].
constexpr double kDt = 0.25;         // Paper: 4 Hz.
constexpr double kV = 0.25;          // Paper: 0.25 m/s.
constexpr int kSteps = 160;          // 10 m.
constexpr double kMean = -0.034e-3;  // Paper's calibration statistics, taken as mrad.
constexpr double kSigma = 1.69e-3;

SlipEstimatorConfig PaperConfig(HeadingRule rule = HeadingRule::kMidpoint) {
  SlipEstimatorConfig c;
  c.track_width_m = kB;
  c.residual_mean_rad = kMean;
  c.residual_sigma_rad = kSigma;
  c.heading_rule = rule;
  return c;
}

double Dist(const Pose2& a, double x, double y) { return std::hypot(a.x_m - x, a.y_m - y); }

TEST(SlipCorrectingOdometry, BandFromThePaperStatistics) {
  SlipCorrectingOdometry est(PaperConfig());
  EXPECT_NEAR(est.band_low_rad(), -3.35e-3, 0.005e-3);  // Paper: about [-3.35, 3.28].
  EXPECT_NEAR(est.band_high_rad(), 3.28e-3, 0.005e-3);
}

TEST(SlipCorrectingOdometry, NoSlipStraightGivesTheExactPose) {
  SlipCorrectingOdometry est(PaperConfig());
  for (int k = 0; k < kSteps; ++k) {
    ASSERT_TRUE(est.Step(kV * kDt, kV * kDt, 0.0));
    EXPECT_FALSE(est.last().out_of_band);
  }
  EXPECT_NEAR(est.pose_encoder().x_m, 10.0, 1e-12);
  EXPECT_NEAR(est.pose_encoder().y_m, 0.0, 1e-12);
  EXPECT_NEAR(est.pose_corrected().x_m, 10.0, 1e-12);
  EXPECT_EQ(est.pose_corrected().theta_rad, 0.0);
  EXPECT_EQ(est.slips_left() + est.slips_right() + est.slips_unattributed(), 0u);
}

TEST(SlipCorrectingOdometry, NoSlipArcGivesTheKinematicPose) {
  const double w = 0.1;  // rad/s: radius 2.5 m.
  const double dL = (kV - w * kB / 2) * kDt;
  const double dR = (kV + w * kB / 2) * kDt;
  const double T = kSteps * kDt;
  const double x_true = kV / w * std::sin(w * T);
  const double y_true = kV / w * (1.0 - std::cos(w * T));

  SlipCorrectingOdometry exact(PaperConfig(HeadingRule::kExactArc));
  SlipCorrectingOdometry mid(PaperConfig(HeadingRule::kMidpoint));
  for (int k = 0; k < kSteps; ++k) {
    ASSERT_TRUE(exact.Step(dL, dR, w * kDt));
    ASSERT_TRUE(mid.Step(dL, dR, w * kDt));
    EXPECT_FALSE(exact.last().out_of_band);
  }
  EXPECT_NEAR(exact.pose_corrected().x_m, x_true, 1e-9);
  EXPECT_NEAR(exact.pose_corrected().y_m, y_true, 1e-9);
  EXPECT_NEAR(exact.pose_corrected().theta_rad, w * T, 1e-12);
  EXPECT_NEAR(exact.pose_encoder().x_m, x_true, 1e-9);
  // Paper's midpoint rule: every step is the exact chord stretched by 1/sinc(dth/2), so for a
  // constant twist the end point is the true one scaled by that factor about the start.
  const double h = w * kDt / 2;
  const double stretch = h / std::sin(h);
  EXPECT_NEAR(mid.pose_corrected().x_m, stretch * x_true, 1e-9);
  EXPECT_NEAR(mid.pose_corrected().y_m, stretch * y_true, 1e-9);
  EXPECT_NEAR(mid.pose_corrected().theta_rad, w * T, 1e-12);
  EXPECT_GT(Dist(mid.pose_corrected(), x_true, y_true), 1e-4);  // 0.12 mm: visible.
}

// A single spin of `slip_m` on one wheel halfway down the 10 m line.
struct SlipCase {
  bool right;
  double direction;  // +1 forward, -1 backward.
};

class SingleWheelSlip : public ::testing::TestWithParam<SlipCase> {};

TEST_P(SingleWheelSlip, IsFlaggedOnThatWheelAndCorrectedToTheGyroPose) {
  const auto [right, dir] = GetParam();
  const double slip_m = 0.03 * dir;  // Spin over-reports travel in the direction of motion.
  SlipCorrectingOdometry est(PaperConfig());
  for (int k = 0; k < kSteps; ++k) {
    double dL = dir * kV * kDt;
    double dR = dir * kV * kDt;
    if (k == 80) (right ? dR : dL) += slip_m;
    ASSERT_TRUE(est.Step(dL, dR, 0.0));
    const auto& r = est.last();
    if (k == 80) {
      EXPECT_TRUE(r.out_of_band);
      EXPECT_EQ(r.slip_right, right);
      EXPECT_EQ(r.slip_left, !right);
      EXPECT_NEAR(r.residual_rad, (right ? 1 : -1) * slip_m / kB, 1e-12);
      EXPECT_NEAR(r.dL_corrected_m, dir * kV * kDt, 1e-12);
      EXPECT_NEAR(r.dR_corrected_m, dir * kV * kDt, 1e-12);
    } else {
      EXPECT_FALSE(r.out_of_band) << k;
    }
  }
  EXPECT_EQ(est.slips_right(), right ? 1u : 0u);
  EXPECT_EQ(est.slips_left(), right ? 0u : 1u);
  EXPECT_NEAR(est.pose_corrected().x_m, dir * 10.0, 1e-12);
  EXPECT_NEAR(est.pose_corrected().y_m, 0.0, 1e-12);
  EXPECT_NEAR(est.pose_corrected().theta_rad, 0.0, 1e-15);
  // The encoder-only pose turned by slip/B and drifted sideways.
  EXPECT_NEAR(std::abs(est.pose_encoder().theta_rad), 0.03 / kB, 1e-12);
  EXPECT_GT(std::abs(est.pose_encoder().y_m), 0.2);
}

INSTANTIATE_TEST_SUITE_P(Wheels, SingleWheelSlip,
                         ::testing::Values(SlipCase{true, 1.0}, SlipCase{false, 1.0},
                                           SlipCase{true, -1.0}, SlipCase{false, -1.0}));

TEST(SlipCorrectingOdometry, SlipOnAnArcIsCorrectedToTheGyroConsistentPose) {
  const double w = 0.1;
  const double dL = (kV - w * kB / 2) * kDt;
  const double dR = (kV + w * kB / 2) * kDt;
  SlipCorrectingOdometry slipping(PaperConfig(HeadingRule::kExactArc));
  SlipCorrectingOdometry clean(PaperConfig(HeadingRule::kExactArc));
  for (int k = 0; k < kSteps; ++k) {
    const double extra_l = (k % 20 == 5) ? 0.02 : 0.0;
    const double extra_r = (k % 20 == 15) ? 0.02 : 0.0;
    ASSERT_TRUE(slipping.Step(dL + extra_l, dR + extra_r, w * kDt));
    ASSERT_TRUE(clean.Step(dL, dR, w * kDt));
    EXPECT_EQ(slipping.last().slip_left, extra_l > 0) << k;
    EXPECT_EQ(slipping.last().slip_right, extra_r > 0) << k;
  }
  EXPECT_EQ(slipping.slips_left(), 8u);
  EXPECT_EQ(slipping.slips_right(), 8u);
  EXPECT_NEAR(slipping.pose_corrected().x_m, clean.pose_corrected().x_m, 1e-9);
  EXPECT_NEAR(slipping.pose_corrected().y_m, clean.pose_corrected().y_m, 1e-9);
  EXPECT_NEAR(slipping.pose_corrected().theta_rad, clean.pose_corrected().theta_rad, 1e-12);
}

TEST(SlipCorrectingOdometry, TurningOnTheSpotBlamesTheWheelThatReportsMore) {
  SlipCorrectingOdometry est(PaperConfig());
  // Spin CCW at 0.4 rad/s: dR = +0.05, dL = -0.05; the right wheel spins 2 cm extra.
  const double d = 0.4 * kDt * kB / 2;
  ASSERT_TRUE(est.Step(-d, d + 0.02, 0.4 * kDt));
  EXPECT_TRUE(est.last().slip_right);
  EXPECT_FALSE(est.last().slip_left);
  EXPECT_NEAR(est.last().dR_corrected_m, d, 1e-12);
  EXPECT_NEAR(est.last().ds_m, 0.0, 1e-12);
  // Encoders under-report turning (r < 0 while dR > 0, dL < 0): a skid, neither rule holds.
  ASSERT_TRUE(est.Step(-d, d - 0.02, 0.4 * kDt));
  EXPECT_TRUE(est.last().slip_unattributed);
  EXPECT_NEAR(est.last().dtheta_rad, 0.4 * kDt, 1e-15);
}

TEST(SlipCorrectingOdometry, CalibrationWindowEstimatesTheBandAndTestsNormality) {
  SlipEstimatorConfig c;
  c.track_width_m = kB;
  c.calibration_samples = 1000;
  SlipCorrectingOdometry est(c);
  std::mt19937_64 rng(7);
  std::normal_distribution<double> gyro_noise(-kMean, kSigma);  // r = -noise: mean kMean.
  for (int k = 0; k < 1000; ++k) {
    EXPECT_FALSE(est.calibrated());
    // A large "residual" during calibration is not flagged: the band is not known yet.
    ASSERT_TRUE(est.Step(kV * kDt, kV * kDt, gyro_noise(rng)));
    EXPECT_FALSE(est.last().out_of_band);
  }
  ASSERT_TRUE(est.calibrated());
  EXPECT_NEAR(est.residual_mean_rad(), kMean, 3 * kSigma / std::sqrt(1000.0));
  EXPECT_NEAR(est.residual_sigma_rad(), kSigma, 0.1 * kSigma);
  ASSERT_TRUE(est.calibration_normality().has_value());
  EXPECT_TRUE(est.calibration_normality()->accepted);
  EXPECT_NEAR(est.calibration_normality()->sigma, est.residual_sigma_rad(), 1e-15);
  ASSERT_TRUE(est.Step(kV * kDt, kV * kDt + 0.02, 0.0));
  EXPECT_TRUE(est.last().slip_right);
}

TEST(SlipCorrectingOdometry, RejectsNonFiniteInputAndBadConfig) {
  SlipCorrectingOdometry est(PaperConfig());
  EXPECT_FALSE(est.Step(NAN, 0.0, 0.0));
  EXPECT_FALSE(est.Step(0.0, INFINITY, 0.0));
  EXPECT_EQ(est.rejected_samples(), 2u);
  EXPECT_EQ(est.samples(), 0u);

  SlipEstimatorConfig c = PaperConfig();
  c.track_width_m = 0.0;
  EXPECT_THAT([&] { SlipCorrectingOdometry{c}; },
              ThrowsMessage<std::invalid_argument>(HasSubstr("track_width_m (0)")));
  c = PaperConfig();
  c.residual_sigma_rad = 0.0;
  EXPECT_THAT([&] { SlipCorrectingOdometry{c}; },
              ThrowsMessage<std::invalid_argument>(HasSubstr("residual_sigma_rad")));
  c.calibration_samples = 1;
  EXPECT_THAT([&] { SlipCorrectingOdometry{c}; },
              ThrowsMessage<std::invalid_argument>(HasSubstr("calibration_samples (1)")));
}

// Like the paper's Table 2: ten 10 m runs at 0.25 m/s, 4 Hz, frequent single-wheel spins,
// a gyro with the paper's residual sigma, 2000-count encoders on 16-bit counters.
TEST(SlipCorrectingOdometry, Table2LikeRunsCorrectedErrorIsMuchSmaller) {
  constexpr double kCpr = 2000.0;
  constexpr double kWheelR = 0.05;
  double sum_ratio = 0.0;
  for (int run = 1; run <= 10; ++run) {
    std::mt19937_64 rng(1000 + run);
    std::normal_distribution<double> gyro_noise(0.0, kSigma);
    std::bernoulli_distribution slips(0.12);
    std::bernoulli_distribution right_wheel(0.5);
    std::uniform_real_distribution<double> slip_m(0.005, 0.025);

    EncoderIncrement left(kCpr, kWheelR, 16);
    EncoderIncrement right(kCpr, kWheelR, 16);
    double wheel_l_m = 0.0;  // What each encoder has seen in total (ground travel + spin).
    double wheel_r_m = 0.0;
    auto raw = [&](double m) {
      return static_cast<std::uint64_t>(std::floor(MetersToCounts(m, kCpr, kWheelR)) + 60000.0);
    };
    (void)left.Update(raw(0.0));
    (void)right.Update(raw(0.0));

    SlipCorrectingOdometry est(PaperConfig());
    int events = 0;
    for (int k = 0; k < kSteps; ++k) {
      wheel_l_m += kV * kDt;
      wheel_r_m += kV * kDt;
      if (slips(rng)) {
        ++events;
        (right_wheel(rng) ? wheel_r_m : wheel_l_m) += slip_m(rng);
      }
      const double dL = left.Update(raw(wheel_l_m));
      const double dR = right.Update(raw(wheel_r_m));
      ASSERT_TRUE(est.Step(dL, dR, gyro_noise(rng)));
    }
    const double uncorrected_mm = 1000.0 * Dist(est.pose_encoder(), 10.0, 0.0);
    const double corrected_mm = 1000.0 * Dist(est.pose_corrected(), 10.0, 0.0);
    std::printf(
        "run %2d: %2d spins, flagged L %2llu R %2llu ?%llu, uncorrected %7.2f mm, "
        "corrected %6.2f mm, ratio %5.2f\n",
        run, events, static_cast<unsigned long long>(est.slips_left()),
        static_cast<unsigned long long>(est.slips_right()),
        static_cast<unsigned long long>(est.slips_unattributed()), uncorrected_mm, corrected_mm,
        uncorrected_mm / corrected_mm);
    EXPECT_LT(corrected_mm * 3.0, uncorrected_mm) << "run " << run;
    EXPECT_LT(corrected_mm, 150.0) << "run " << run;
    sum_ratio += uncorrected_mm / corrected_mm;
  }
  EXPECT_GT(sum_ratio / 10.0, 5.0);  // Paper: ratios 5.2 .. 12.6.
}

}  // namespace
}  // namespace wheelhil::fw
