#include "firmware_stub/normality_test.h"

#include <cmath>

namespace wheelhil::fw {
namespace {

// Two passes over (value, weight) pairs: the mean first, then the central moments about it, so
// a large common offset does not cancel catastrophically.
template <typename ValueAt, typename WeightAt>
std::optional<NormalityResult> Evaluate(std::size_t bins, ValueAt value, WeightAt weight,
                                        double z) {
  double n = 0.0;
  double sum = 0.0;
  for (std::size_t i = 0; i < bins; ++i) {
    if (!std::isfinite(value(i))) return std::nullopt;
    n += weight(i);
    sum += weight(i) * value(i);
  }
  if (n < 4.0) return std::nullopt;
  const double mean = sum / n;
  double b2 = 0.0;
  double b3 = 0.0;
  double b4 = 0.0;
  for (std::size_t i = 0; i < bins; ++i) {
    const double d = value(i) - mean;
    const double d2 = d * d;
    b2 += weight(i) * d2;
    b3 += weight(i) * d2 * d;
    b4 += weight(i) * d2 * d2;
  }
  b2 /= n;
  b3 /= n;
  b4 /= n;
  if (!(b2 > 0.0)) return std::nullopt;

  NormalityResult r;
  r.n = static_cast<std::size_t>(n);
  r.mean = mean;
  r.sigma = std::sqrt(b2);
  r.g1 = b3 / (b2 * r.sigma);
  r.g2 = b4 / (b2 * b2) - 3.0;
  r.sd_g1 = std::sqrt(6.0 * (n - 2.0) / ((n + 1.0) * (n + 3.0)));
  r.mean_g2 = -6.0 / (n + 1.0);
  r.sd_g2 =
      std::sqrt(24.0 * n * (n - 2.0) * (n - 3.0) / ((n + 1.0) * (n + 1.0) * (n + 3.0) * (n + 5.0)));
  r.u1 = r.g1 / r.sd_g1;
  r.u2 = (r.g2 - r.mean_g2) / r.sd_g2;
  r.accepted = std::abs(r.u1) < z && std::abs(r.u2) < z;
  return r;
}

}  // namespace

std::optional<NormalityResult> SkewnessKurtosisTest(std::span<const double> samples,
                                                    double z) noexcept {
  return Evaluate(
      samples.size(), [&](std::size_t i) { return samples[i]; }, [](std::size_t) { return 1.0; },
      z);
}

std::optional<NormalityResult> SkewnessKurtosisTestHistogram(std::span<const double> bin_centres,
                                                             std::span<const std::uint64_t> counts,
                                                             double z) noexcept {
  if (bin_centres.size() != counts.size()) return std::nullopt;
  return Evaluate(
      bin_centres.size(), [&](std::size_t i) { return bin_centres[i]; },
      [&](std::size_t i) { return static_cast<double>(counts[i]); }, z);
}

}  // namespace wheelhil::fw
