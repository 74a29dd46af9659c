// Tests for emulator/sensors: encoder, gyro and accelerometer models.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <vector>

#include "emulator/sensors/accelerometer_model.h"
#include "emulator/sensors/encoder_model.h"
#include "emulator/sensors/gyro_model.h"
#include "emulator/sensors/sample_schedule.h"

namespace wheelhil::emulator {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;
constexpr double kPi = std::numbers::pi;

// Angle at the middle of count interval k, so floating-point rounding cannot move the edge.
double MidCount(double k, int cpr) { return (k + 0.5) * 2.0 * kPi / cpr; }

TEST(EncoderModel, QuantisesToFloorOfCounts) {
  EncoderModel enc({.lines_per_rev = 100, .quadrature_x4 = true});
  ASSERT_EQ(enc.counts_per_rev(), 400);
  EXPECT_EQ(enc.Sample(MidCount(0, 400)), 0u);
  EXPECT_EQ(enc.Sample(MidCount(1, 400)), 1u);
  EXPECT_EQ(enc.Sample(MidCount(399, 400)), 399u);
  // One full turn plus 3 counts: 403 (counter keeps counting across revolutions).
  EXPECT_EQ(enc.Sample(2.0 * kPi + MidCount(3, 400)), 403u);
  // A move smaller than one count does not change the reading.
  EXPECT_EQ(enc.Sample(2.0 * kPi + MidCount(3, 400) + 0.4 * 2.0 * kPi / 400), 403u);
  EXPECT_EQ(enc.unwrapped_count(), 403);
}

TEST(EncoderModel, EccentricDiscErrsOncePerTurnAndCancelsOverAFullTurn) {
  EncoderParams p;
  p.lines_per_rev = 1024;  // 4096 counts per turn
  p.eccentricity_rad = 0.01;
  p.eccentricity_phase_rad = 0.0;
  EncoderModel enc(p);
  enc.Reset(0.0);
  // A quarter turn reads 0.01 rad long: 4096 * 0.01 / 2pi = 6.5 counts over the true 1024.
  enc.Sample(std::numbers::pi / 2);
  EXPECT_EQ(enc.unwrapped_count(), 1030);
  enc.Sample(std::numbers::pi + 1e-9);  // half a turn: the error is back to zero
  EXPECT_EQ(enc.unwrapped_count(), 2048);
  enc.Sample(1.5 * std::numbers::pi);  // three quarters: as much short
  EXPECT_EQ(enc.unwrapped_count(), 3072 - 7);
  enc.Sample(2 * std::numbers::pi + 1e-9);
  EXPECT_EQ(enc.unwrapped_count(), 4096);
  p.eccentricity_rad = 0.2;
  EXPECT_THROW(EncoderModel{p}, std::invalid_argument);
}

TEST(EncoderModel, X1DecodingAndDirection) {
  EncoderModel x1({.lines_per_rev = 100, .quadrature_x4 = false});
  EXPECT_EQ(x1.counts_per_rev(), 100);
  EXPECT_EQ(x1.Sample(MidCount(42, 100)), 42u);
  EncoderModel reversed({.lines_per_rev = 100, .direction = -1});
  // Forward wheel rotation counts down: -5 counts wrap to 2^32 - 5 in a 32-bit register.
  reversed.Sample(MidCount(4, 400));  // floor(-4.5) = -5
  EXPECT_EQ(reversed.unwrapped_count(), -5);
  EXPECT_EQ(reversed.counter(), 0xFFFFFFFBu);
}

TEST(EncoderModel, CounterWrapsAtItsWidth) {
  EncoderModel enc({.lines_per_rev = 1024, .quadrature_x4 = true, .counter_bits = 16});
  // 17 revolutions = 69632 counts; a 16-bit register holds 69632 - 65536 = 4096.
  EXPECT_EQ(enc.Sample(17 * 2.0 * kPi + MidCount(0, 4096)), 4096u);
  EXPECT_EQ(enc.unwrapped_count(), 69632);
  // Going back below zero wraps the other way: -1 -> 0xFFFF.
  EXPECT_EQ(enc.Sample(MidCount(-1, 4096)), 0xFFFFu);
  // Small steps across the wrap point behave like the hardware register.
  EncoderModel small({.lines_per_rev = 1, .quadrature_x4 = true, .counter_bits = 2});
  std::vector<std::uint32_t> seen;
  for (int k = 0; k < 6; ++k) seen.push_back(small.Sample(MidCount(k, 4)));
  EXPECT_THAT(seen, ::testing::ElementsAre(0u, 1u, 2u, 3u, 0u, 1u));
}

TEST(EncoderModel, ResetSetsCountAtAngle) {
  EncoderModel enc({.lines_per_rev = 100});
  enc.Reset(MidCount(10, 400), 1000);
  EXPECT_EQ(enc.Sample(MidCount(15, 400)), 1005u);
}

TEST(EncoderModel, MissedCountsLoseEdgesWithGivenProbability) {
  EncoderModel enc({.lines_per_rev = 1000, .missed_count_prob = 0.01, .seed = 7});
  // 100 revolutions in 1000 steps = 400000 edges; expect ~4000 lost (binomial std ~63).
  for (int k = 1; k <= 1000; ++k) enc.Sample(k * 0.1 * 2.0 * kPi + MidCount(0, 4000));
  EXPECT_NEAR(enc.missed_edges(), 4000, 300);
  EXPECT_EQ(enc.unwrapped_count(), 400000 - enc.missed_edges());
}

TEST(EncoderModel, GlitchesAddSpuriousCounts) {
  EncoderModel enc({.lines_per_rev = 1000, .glitch_prob = 0.1, .seed = 3});
  for (int k = 0; k < 10000; ++k) enc.Sample(MidCount(0, 4000));  // wheel at rest
  EXPECT_NEAR(enc.glitches(), 1000, 120);
  EXPECT_LE(std::abs(enc.unwrapped_count()), enc.glitches());
  EXPECT_NE(enc.glitches(), 0);
}

TEST(EncoderModel, SameSeedSameCounts) {
  const EncoderParams p{
      .lines_per_rev = 500, .missed_count_prob = 0.05, .glitch_prob = 0.05, .seed = 11};
  EncoderModel a(p), b(p),
      c({.lines_per_rev = 500, .missed_count_prob = 0.05, .glitch_prob = 0.05, .seed = 12});
  bool differs = false;
  for (int k = 0; k < 2000; ++k) {
    const double angle = 0.013 * k;
    const auto va = a.Sample(angle);
    EXPECT_EQ(va, b.Sample(angle));
    differs |= va != c.Sample(angle);
  }
  EXPECT_TRUE(differs);
}

// With the disc's edge at angle 0 a wheel trembling by 1e-9 rad around its start flips between
// counts -1 and 0; with the edge half a count away it reads 0 throughout, and the edges sit at
// (k - phase) counts.
TEST(EncoderModel, DiscPhaseMovesTheEdgesOffTheStartAngle) {
  const double tremble = 1e-9;
  EncoderModel on_edge({.lines_per_rev = 100});
  EXPECT_EQ(on_edge.Sample(-tremble), 0xFFFFFFFFu);
  EXPECT_EQ(on_edge.Sample(tremble), 0u);
  EncoderModel mid({.lines_per_rev = 100, .disc_phase_counts = 0.5});
  EXPECT_EQ(mid.Sample(-tremble), 0u);
  EXPECT_EQ(mid.Sample(tremble), 0u);
  const double count_rad = 2.0 * kPi / 400;
  EXPECT_EQ(mid.Sample(0.49 * count_rad), 0u);
  EXPECT_EQ(mid.Sample(0.51 * count_rad), 1u);
  EXPECT_EQ(mid.Sample(-0.51 * count_rad), 0xFFFFFFFFu);
}

TEST(EncoderModel, RejectsBadParameters) {
  EXPECT_THAT([] { EncoderModel({.lines_per_rev = 0}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("lines_per_rev")));
  EXPECT_THAT([] { EncoderModel({.counter_bits = 33}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("counter_bits")));
  EXPECT_THAT([] { EncoderModel({.direction = 2}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("direction")));
  EXPECT_THAT([] { EncoderModel({.missed_count_prob = 1.5}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("missed_count_prob")));
  EXPECT_THAT(
      [] { EncoderModel({.disc_phase_counts = 1.0}); },
      ThrowsMessage<std::invalid_argument>(HasSubstr("disc_phase_counts (1) must be in [0, 1)")));
}

TEST(GyroModel, IdealGyroReadsTrueRateOnItsAxis) {
  GyroModel gyro({.rate_hz = 100.0});
  EXPECT_DOUBLE_EQ(gyro.Sample(Eigen::Vector3d(0.3, -0.2, 1.25)), 1.25);
  GyroModel roll({.rate_hz = 100.0, .axis_B = Eigen::Vector3d(2.0, 0.0, 0.0)});
  EXPECT_DOUBLE_EQ(roll.Sample(Eigen::Vector3d(0.3, -0.2, 1.25)), 0.3);
}

TEST(GyroModel, BiasScaleSaturationQuantisation) {
  GyroModel gyro({.rate_hz = 100.0,
                  .bias_rad_s = 0.01,
                  .scale_factor_error = 0.02,
                  .resolution_rad_s = 0.001,
                  .range_rad_s = 2.0});
  // 1.02 * 1.0 + 0.01 = 1.03 exactly representable in LSBs.
  EXPECT_NEAR(gyro.SampleRate(1.0), 1.030, 1e-12);
  // 1.02 * 0.5004 + 0.01 = 0.520408 -> 0.520 (nearest LSB).
  EXPECT_NEAR(gyro.SampleRate(0.5004), 0.520, 1e-12);
  EXPECT_NEAR(gyro.SampleRate(10.0), 2.0, 1e-12);
  EXPECT_NEAR(gyro.SampleRate(-10.0), -2.0, 1e-12);
}

TEST(GyroModel, WhiteNoiseStdMatchesDensity) {
  // 0.005 rad/s/sqrt(Hz) at 400 Hz -> sigma = 0.1 rad/s per sample.
  GyroModel gyro({.rate_hz = 400.0, .noise_density_rad_s_sqrt_hz = 0.005, .seed = 42});
  ASSERT_DOUBLE_EQ(gyro.noise_std_rad_s(), 0.1);
  const int n = 100000;
  double sum = 0.0, sum2 = 0.0;
  for (int k = 0; k < n; ++k) {
    const double v = gyro.SampleRate(0.5);
    sum += v;
    sum2 += v * v;
  }
  const double mean = sum / n;
  const double std = std::sqrt(sum2 / n - mean * mean);
  EXPECT_NEAR(mean, 0.5, 0.002);      // ~6 standard errors (0.1/sqrt(1e5) = 3.2e-4)
  EXPECT_NEAR(std, 0.1, 0.1 * 0.02);  // within 2 %
}

TEST(GyroModel, BiasRandomWalkGrowsLikeSqrtTime) {
  // sigma_b(t) = 0.01 rad/s/sqrt(s) * sqrt(100 s) = 0.1 rad/s, across 400 independent gyros.
  const int runs = 400;
  double sum2 = 0.0;
  for (int r = 0; r < runs; ++r) {
    GyroModel gyro({.rate_hz = 100.0,
                    .bias_random_walk_rad_s_sqrt_s = 0.01,
                    .seed = static_cast<std::uint64_t>(r)});
    for (int k = 0; k < 10000; ++k) gyro.SampleRate(0.0);
    sum2 += gyro.bias_rad_s() * gyro.bias_rad_s();
  }
  // Sample std of 400 normals is within ~3.5 % (1 sigma); allow 12 %.
  EXPECT_NEAR(std::sqrt(sum2 / runs), 0.1, 0.012);
}

TEST(GyroModel, FirstOrderStepResponse) {
  const double fc = 10.0, rate = 1000.0;
  GyroModel gyro({.rate_hz = rate, .bandwidth_hz = fc});
  EXPECT_DOUBLE_EQ(gyro.SampleRate(0.0), 0.0);
  // After the step, y_n = 1 - exp(-2 pi fc n dt): 63.2 % at one time constant (15.9 ms).
  for (int n = 1; n <= 100; ++n) {
    const double y = gyro.SampleRate(1.0);
    EXPECT_NEAR(y, 1.0 - std::exp(-2.0 * kPi * fc * n / rate), 1e-12) << "n=" << n;
  }
  GyroModel tau({.rate_hz = rate, .bandwidth_hz = fc});
  tau.SampleRate(0.0);
  double y = 0.0;
  for (int n = 1; n <= 16; ++n) y = tau.SampleRate(1.0);  // t = 16 ms ~ tau = 15.92 ms
  EXPECT_NEAR(y, 1.0 - std::exp(-1.0), 0.005);
}

TEST(GyroModel, PureDelayShiftsTheOutputByWholeSamples) {
  GyroModel gyro({.rate_hz = 100.0, .delay_samples = 3});
  std::vector<double> out;
  for (double in : {0.0, 0.0, 1.0, 2.0, 3.0, 4.0, 5.0}) out.push_back(gyro.SampleRate(in));
  EXPECT_THAT(out, ::testing::ElementsAre(0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 2.0));
  EXPECT_THAT([] { GyroModel({.delay_samples = -1}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("delay_samples")));
}

TEST(GyroModel, SameSeedSameSamples) {
  const GyroParams p{.rate_hz = 200.0,
                     .bias_random_walk_rad_s_sqrt_s = 1e-3,
                     .noise_density_rad_s_sqrt_hz = 1e-3,
                     .seed = 99};
  GyroModel a(p), b(p);
  GyroParams q = p;
  q.seed = 100;
  GyroModel c(q);
  bool differs = false;
  for (int k = 0; k < 1000; ++k) {
    const double va = a.SampleRate(0.1 * k);
    EXPECT_EQ(va, b.SampleRate(0.1 * k));
    differs |= va != c.SampleRate(0.1 * k);
  }
  EXPECT_TRUE(differs);
}

TEST(GyroModel, RejectsBadParameters) {
  EXPECT_THAT([] { GyroModel({.rate_hz = 0.0}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("rate_hz")));
  EXPECT_THAT([] { GyroModel({.noise_density_rad_s_sqrt_hz = -1.0}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("noise_density")));
  EXPECT_THAT([] { GyroModel({.axis_B = Eigen::Vector3d::Zero()}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("axis_B")));
}

// A body spinning about z at omega with angular acceleration alpha, centre accelerating by a,
// tilted by pitch theta about y (gravity projected): the analytic specific force at r = (R, 0, 0)
// is f = a + (-omega^2 R, alpha R, 0) - g_B with g_B = 9.81 (sin theta, 0, -cos theta).
TEST(AccelerometerModel, MatchesAnalyticSpecificForceOnSpinningAcceleratingBody) {
  const double R = 0.2, omega = 3.0, alpha = 1.5, theta = 0.1, g = 9.81;
  BodyKinematics k;
  k.a_WBo_B = Eigen::Vector3d(0.5, -0.25, 0.0);
  k.omega_WB_B = Eigen::Vector3d(0.0, 0.0, omega);
  k.alpha_WB_B = Eigen::Vector3d(0.0, 0.0, alpha);
  k.g_B = Eigen::Vector3d(g * std::sin(theta), 0.0, -g * std::cos(theta));
  const double fx = 0.5 - omega * omega * R - g * std::sin(theta);  // 0.5 - 1.8 - 0.979...
  const double fy = -0.25 + alpha * R;                              // 0.05
  const double fz = g * std::cos(theta);

  AccelerometerModel three(
      {.r_BP_B = Eigen::Vector3d(R, 0.0, 0.0),
       .axes_B = {Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ()}});
  const auto& f = three.Sample(k);
  ASSERT_EQ(f.size(), 3u);
  EXPECT_NEAR(f[0], fx, 1e-12);
  EXPECT_NEAR(f[1], fy, 1e-12);
  EXPECT_NEAR(f[2], fz, 1e-12);

  // Paper 002 layout: four single-axis sensors at radius R, tangential directions.
  // At (R,0,0) tangential +y; at (0,R,0) tangential -x; at (-R,0,0) -y; at (0,-R,0) +x.
  const double ax = 0.5, ay = -0.25;
  struct Mount {
    Eigen::Vector3d r, u;
    double expected;
  } mounts[] = {
      {{R, 0, 0}, {0, 1, 0}, ay + alpha * R},
      {{0, R, 0}, {-1, 0, 0}, -(ax - omega * omega * 0.0 - g * std::sin(theta)) + alpha * R},
      {{-R, 0, 0}, {0, -1, 0}, -ay + alpha * R},
      {{0, -R, 0}, {1, 0, 0}, ax - g * std::sin(theta) + alpha * R},
  };
  for (const auto& m : mounts) {
    AccelerometerModel single({.r_BP_B = m.r, .axes_B = {m.u}});
    EXPECT_NEAR(single.Sample(k)[0], m.expected, 1e-12) << m.r.transpose();
  }
}

TEST(AccelerometerModel, LevelAtRestReadsPlusOneG) {
  AccelerometerModel acc({.axes_B = {Eigen::Vector3d::UnitZ()}});
  EXPECT_NEAR(acc.Sample(BodyKinematics{})[0], 9.80665, 1e-12);
}

TEST(AccelerometerModel, BiasScaleMisalignmentSaturationQuantisation) {
  BodyKinematics k;
  k.a_WBo_B = Eigen::Vector3d(2.0, 0.0, 0.0);
  k.g_B = Eigen::Vector3d::Zero();
  // 1 deg misalignment about z turns x towards y: reads 2 cos(1 deg); scale 1.01, bias 0.05.
  const double mis = kPi / 180.0;
  AccelerometerModel acc({.axes_B = {Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY()},
                          .misalignment_rad = Eigen::Vector3d(0.0, 0.0, mis),
                          .bias_m_s2 = {0.05, -0.05},
                          .scale_error = {0.01, 0.0}});
  const auto& f = acc.Sample(k);
  EXPECT_NEAR(f[0], 1.01 * 2.0 * std::cos(mis) + 0.05, 1e-12);
  EXPECT_NEAR(f[1], -2.0 * std::sin(mis) - 0.05, 1e-12);

  AccelerometerModel sat(
      {.axes_B = {Eigen::Vector3d::UnitX()}, .resolution_m_s2 = 0.01, .range_m_s2 = 1.5});
  EXPECT_NEAR(sat.Sample(k)[0], 1.5, 1e-12);
  k.a_WBo_B.x() = 0.1234;
  EXPECT_NEAR(sat.Sample(k)[0], 0.12, 1e-12);
}

TEST(AccelerometerModel, NoiseStatisticsAndSeeding) {
  AccelerometerParams p{.rate_hz = 1000.0,
                        .axes_B = {Eigen::Vector3d::UnitX()},
                        .noise_density_m_s2_sqrt_hz = 0.002,
                        .seed = 5};
  AccelerometerModel a(p), b(p);
  BodyKinematics k;
  const int n = 50000;
  double sum2 = 0.0;
  for (int i = 0; i < n; ++i) {
    const double v = a.Sample(k)[0];
    EXPECT_EQ(v, b.Sample(k)[0]);
    sum2 += v * v;
  }
  // sigma = 0.002 * sqrt(1000) = 0.0632 m/s^2.
  EXPECT_NEAR(std::sqrt(sum2 / n), 0.002 * std::sqrt(1000.0), 0.0632 * 0.03);
}

TEST(AccelerometerModel, RejectsBadParameters) {
  EXPECT_THAT([] { AccelerometerModel({.axes_B = {}}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("axes_B")));
  EXPECT_THAT(
      [] {
        AccelerometerModel({.bias_m_s2 = {1.0, 2.0}});
      },
      ThrowsMessage<std::invalid_argument>(HasSubstr("bias_m_s2")));
}

TEST(SampleSchedule, InstantsAndInterpolationWeightsPerPhysicsStep) {
  // 400 Hz sensor (2.5 ms) on a 1 kHz physics step: samples fall between steps.
  SampleSchedule s(2'500'000);
  EXPECT_TRUE(s.InStep(0, 1'000'000).empty());
  EXPECT_TRUE(s.InStep(1'000'000, 2'000'000).empty());
  const auto in = s.InStep(2'000'000, 3'000'000);
  ASSERT_EQ(in.size(), 1u);
  EXPECT_EQ(in[0].t_ns, 2'500'000);
  EXPECT_DOUBLE_EQ(in[0].alpha, 0.5);
  // A step that divides the period: every sample lands on a step, alpha = 1.
  SampleSchedule fast(1'000'000, 0);
  for (std::int64_t t = 0; t < 10'000'000; t += 500'000) {
    for (const auto& i : fast.InStep(t, t + 500'000)) {
      EXPECT_EQ(i.t_ns, t + 500'000);
      EXPECT_DOUBLE_EQ(i.alpha, 1.0);
    }
  }
  // A long step holds several samples; the phase shifts them.
  SampleSchedule phased(1'000'000, 250'000);
  const auto many = phased.InStep(0, 3'000'000);
  ASSERT_EQ(many.size(), 3u);
  EXPECT_EQ(many[0].t_ns, 250'000);
  EXPECT_EQ(many[2].t_ns, 2'250'000);
  EXPECT_EQ(phased.FirstAfter(250'000), 1'250'000);
  EXPECT_EQ(phased.FirstAfter(-1'000'000), -750'000);
  EXPECT_THAT([] { SampleSchedule(0); }, ThrowsMessage<std::invalid_argument>(HasSubstr("period")));
  EXPECT_THAT([] { SampleSchedule(10, 10); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("phase")));
}

}  // namespace
}  // namespace wheelhil::emulator
