#include "firmware_stub/normality_test.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

namespace wheelhil::fw {
namespace {

// Paper 000's calibration histogram (5 runs, 1000 samples of the residual).
constexpr std::array<double, 10> kCentres = {-4.5, -3.5, -2.5, -1.5, -0.5, 0.5, 1.5, 2.5, 3.5, 4.5};
constexpr std::array<std::uint64_t, 10> kCounts = {9, 21, 92, 163, 232, 218, 151, 74, 30, 10};

TEST(SkewnessKurtosisTest, PaperHistogramGivesThePublishedStatistics) {
  const auto r = SkewnessKurtosisTestHistogram(kCentres, kCounts);
  ASSERT_TRUE(r.has_value());
  EXPECT_EQ(r->n, 1000u);
  EXPECT_NEAR(r->mean, -0.034, 1e-12);  // Paper: -0.034.
  EXPECT_NEAR(r->sigma, 1.69, 0.005);   // Paper: 1.69 (1.69259 with divisor n).
  EXPECT_NEAR(r->u1, 1.19, 0.01);       // Paper: 1.19 (1.19034).
  EXPECT_NEAR(r->u2, -0.78, 0.01);      // Paper: -0.78 (-0.78095).
  EXPECT_TRUE(r->accepted);
  EXPECT_NEAR(r->mean_g2, -6.0 / 1001.0, 1e-15);
}

TEST(SkewnessKurtosisTest, HistogramAndExpandedSamplesAgree) {
  std::vector<double> samples;
  for (std::size_t i = 0; i < kCentres.size(); ++i) {
    samples.insert(samples.end(), kCounts[i], kCentres[i]);
  }
  const auto h = SkewnessKurtosisTestHistogram(kCentres, kCounts);
  const auto s = SkewnessKurtosisTest(samples);
  ASSERT_TRUE(h && s);
  EXPECT_NEAR(h->u1, s->u1, 1e-9);
  EXPECT_NEAR(h->u2, s->u2, 1e-9);
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
  const auto rg = SkewnessKurtosisTest(g);
  const auto re = SkewnessKurtosisTest(e);
  const auto ru = SkewnessKurtosisTest(u);
  ASSERT_TRUE(rg && re && ru);
  EXPECT_TRUE(rg->accepted) << rg->u1 << " " << rg->u2;
  EXPECT_FALSE(re->accepted);
  EXPECT_GT(re->u1, 10.0);  // Skewness 2.
  EXPECT_FALSE(ru->accepted);
  EXPECT_LT(ru->u2, -10.0);  // Excess kurtosis -1.2.
}

TEST(SkewnessKurtosisTest, UndefinedCasesReturnNothing) {
  EXPECT_FALSE(SkewnessKurtosisTest(std::vector<double>{1.0, 2.0, 3.0}));
  EXPECT_FALSE(SkewnessKurtosisTest(std::vector<double>(10, 1.0)));
  EXPECT_FALSE(SkewnessKurtosisTest(std::vector<double>{1.0, 2.0, NAN, 3.0, 4.0}));
  const std::array<std::uint64_t, 2> counts = {1, 2};
  EXPECT_FALSE(SkewnessKurtosisTestHistogram(kCentres, counts));
}

}  // namespace
}  // namespace wheelhil::fw
