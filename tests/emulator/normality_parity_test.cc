// The shared normality test (bus/normality.h) with the scorer's minimum of 8 samples gives,
// bit for bit, what the scorer's own NormalityTest (emulator/scenario/metrics.h) reports, so the
// scorer can switch to it without changing report.json. Delete this test with NormalityTest.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "bus/normality.h"
#include "emulator/scenario/metrics.h"

namespace wheelhil::emulator::scenario {
namespace {

std::uint64_t Bits(double v) { return std::bit_cast<std::uint64_t>(v); }

void ExpectSameAsScorer(const std::vector<double>& x) {
  const NormalityResult old = NormalityTest(x);
  const bus::NormalityResult now = bus::SkewnessKurtosisTest(x, 1.96, 8);
  EXPECT_EQ(now.n, old.n);
  EXPECT_EQ(Bits(now.mean), Bits(old.mean)) << now.mean << " " << old.mean;
  EXPECT_EQ(Bits(now.sigma), Bits(old.sigma)) << now.sigma << " " << old.sigma;
  EXPECT_EQ(Bits(now.g1), Bits(old.g1)) << now.g1 << " " << old.g1;
  EXPECT_EQ(Bits(now.g2), Bits(old.g2)) << now.g2 << " " << old.g2;
  EXPECT_EQ(Bits(now.u1), Bits(old.u1)) << now.u1 << " " << old.u1;
  EXPECT_EQ(Bits(now.u2), Bits(old.u2)) << now.u2 << " " << old.u2;
  EXPECT_EQ(now.accepted, old.accepted);
}

TEST(NormalityParity, SharedTestIsBitIdenticalToTheScorersOwn) {
  std::mt19937_64 rng(2024);
  std::normal_distribution<double> gauss(0.0, 1.0);
  std::exponential_distribution<double> expo(3.0);
  std::uniform_real_distribution<double> uni(-1.0, 1.0);
  for (std::size_t n : {0, 1, 3, 4, 7, 8, 9, 20, 100, 1000, 5000}) {
    for (double offset : {0.0, 1e-3, 1e6}) {
      std::vector<double> g, e, u;
      for (std::size_t i = 0; i < n; ++i) {
        g.push_back(offset + 1e-3 * gauss(rng));
        e.push_back(offset + expo(rng));
        u.push_back(offset + uni(rng));
      }
      SCOPED_TRACE(::testing::Message() << "n " << n << " offset " << offset);
      ExpectSameAsScorer(g);
      ExpectSameAsScorer(e);
      ExpectSameAsScorer(u);
    }
  }
  // Quantised residuals, as decoded from the firmware's frames.
  std::vector<double> q;
  for (int i = 0; i < 400; ++i) q.push_back(std::round(gauss(rng) * 50.0) * 1e-4);
  ExpectSameAsScorer(q);
}

TEST(NormalityParity, EdgeCasesMatchToo) {
  ExpectSameAsScorer(std::vector<double>(12, 0.25));  // zero variance
  ExpectSameAsScorer({1, 2, 3, 4, 5, 6, 7, std::numeric_limits<double>::quiet_NaN(), 9});
  ExpectSameAsScorer({1, 2, 3, 4, 5, 6, 7, std::numeric_limits<double>::infinity(), 9});
  ExpectSameAsScorer({1e200, -1e200, 1e200, -1e200, 1e200, -1e200, 1e200, -1e200});
}

}  // namespace
}  // namespace wheelhil::emulator::scenario
