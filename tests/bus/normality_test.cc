// Paper 000's skewness/kurtosis normality test (bus/normality.h): the paper's own histogram gives
// its published statistics; raw samples and histograms agree; the undefined cases and the
// minimum sample count.
#include "bus/normality.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

namespace wheelhil::bus {
namespace {

// Paper 000's calibration histogram (5 runs, 1000 samples of the residual).
constexpr std::array<double, 10> kCentres = {-4.5, -3.5, -2.5, -1.5, -0.5, 0.5, 1.5, 2.5, 3.5, 4.5};
constexpr std::array<std::uint64_t, 10> kCounts = {9, 21, 92, 163, 232, 218, 151, 74, 30, 10};

TEST(SkewnessKurtosisTest, PaperHistogramGivesThePublishedStatistics) {
  const NormalityResult r = SkewnessKurtosisTestHistogram(kCentres, kCounts);
  ASSERT_TRUE(r.defined);
  EXPECT_EQ(r.n, 1000u);
  EXPECT_NEAR(r.mean, -0.034, 1e-12);  // Paper: -0.034.
  EXPECT_NEAR(r.sigma, 1.69, 0.005);   // Paper: 1.69 (1.69259 with divisor n).
  EXPECT_NEAR(r.u1, 1.19, 0.01);       // Paper: 1.19 (1.19034).
  EXPECT_NEAR(r.u2, -0.78, 0.01);      // Paper: -0.78 (-0.78095).
  EXPECT_TRUE(r.accepted);
  EXPECT_NEAR(r.mean_g2, -6.0 / 1001.0, 1e-15);
}

TEST(SkewnessKurtosisTest, HistogramAndExpandedSamplesAgree) {
  std::vector<double> samples;
  for (std::size_t i = 0; i < kCentres.size(); ++i) {
    samples.insert(samples.end(), kCounts[i], kCentres[i]);
  }
  const NormalityResult h = SkewnessKurtosisTestHistogram(kCentres, kCounts);
  const NormalityResult s = SkewnessKurtosisTest(samples);
  ASSERT_TRUE(h.defined && s.defined);
  EXPECT_EQ(h.n, s.n);
  EXPECT_NEAR(h.u1, s.u1, 1e-9);
  EXPECT_NEAR(h.u2, s.u2, 1e-9);
}

TEST(SkewnessKurtosisTest, AcceptsGaussianRejectsExponentialAndUniform) {
  std::mt19937_64 rng(42);
  std::normal_distribution<double> gauss(3.0, 0.5);
  std::exponential_distribution<double> expo(1.0);
  std::uniform_real_distribution<double> uni(-1.0, 1.0);
  std::vector<double> g(2000), e(2000), u(2000);
  for (auto& v : g) v = gauss(rng);
  for (auto& v : e) v = expo(rng);
  for (auto& v : u) v = uni(rng);
  const NormalityResult rg = SkewnessKurtosisTest(g);
  const NormalityResult re = SkewnessKurtosisTest(e);
  const NormalityResult ru = SkewnessKurtosisTest(u);
  ASSERT_TRUE(rg.defined && re.defined && ru.defined);
  EXPECT_TRUE(rg.accepted) << rg.u1 << " " << rg.u2;
  EXPECT_FALSE(re.accepted);
  EXPECT_GT(re.u1, 10.0);  // Skewness 2.
  EXPECT_FALSE(ru.accepted);
  EXPECT_LT(ru.u2, -10.0);  // Excess kurtosis -1.2.
}

TEST(SkewnessKurtosisTest, UndefinedCasesAreNeverAccepted) {
  const NormalityResult three = SkewnessKurtosisTest(std::vector<double>{1.0, 2.0, 3.0});
  EXPECT_FALSE(three.defined);
  EXPECT_EQ(three.n, 3u);
  EXPECT_EQ(three.mean, 0.0);  // below the minimum nothing but n is computed
  const NormalityResult flat = SkewnessKurtosisTest(std::vector<double>(10, 1.0));
  EXPECT_FALSE(flat.defined);
  EXPECT_EQ(flat.mean, 1.0);  // zero variance: mean and sigma still reported
  EXPECT_EQ(flat.sigma, 0.0);
  const NormalityResult nan = SkewnessKurtosisTest(std::vector<double>{1.0, 2.0, NAN, 3.0, 4.0});
  EXPECT_FALSE(nan.defined);
  EXPECT_FALSE(nan.accepted);
  const std::array<std::uint64_t, 2> counts = {1, 2};
  EXPECT_FALSE(SkewnessKurtosisTestHistogram(kCentres, counts).defined);
}

TEST(SkewnessKurtosisTest, MinimumSampleCountIsAtLeastFour) {
  const std::vector<double> seven = {0.1, -0.4, 0.3, 0.2, -0.1, 0.5, -0.3};
  EXPECT_TRUE(SkewnessKurtosisTest(seven).defined);  // the firmware's rule: n >= 4
  const NormalityResult scorer = SkewnessKurtosisTest(seven, 1.96, 8);  // the scorer's: n >= 8
  EXPECT_FALSE(scorer.defined);
  EXPECT_EQ(scorer.n, 7u);
  EXPECT_FALSE(SkewnessKurtosisTest(std::vector<double>{1.0, 2.0, 3.0}, 1.96, 0).defined);
}

}  // namespace
}  // namespace wheelhil::bus
