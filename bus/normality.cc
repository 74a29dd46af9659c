#include "bus/normality.h"

#include <algorithm>
#include <cmath>

namespace wheelhil::bus {
namespace {

// Two passes over (value, weight) pairs: the mean first, then the central moments about it, so
// a large common offset does not cancel catastrophically. The operations and their order are
// those of the emulator's former scorer (B4 as ((d^2 d) d), G1 with pow): with unit weights the
// results are bit for bit what it reported.
template <typename ValueAt, typename WeightAt>
NormalityResult Evaluate(std::size_t bins, ValueAt value, WeightAt weight, double z,
                         std::size_t min_samples) {
  NormalityResult r;
  double n = 0.0;
  double sum = 0.0;
  bool finite = true;
  for (std::size_t i = 0; i < bins; ++i) {
    finite = finite && std::isfinite(value(i));
    n += weight(i);
    sum += weight(i) * value(i);
  }
  r.n = static_cast<std::size_t>(n);
  if (r.n < std::max(min_samples, kNormalityMinSamples)) return r;
  const double mean = sum / n;
  double b2 = 0.0;
  double b3 = 0.0;
  double b4 = 0.0;
  for (std::size_t i = 0; i < bins; ++i) {
    const double d = value(i) - mean;
    const double d2 = d * d;
    b2 += weight(i) * d2;
    b3 += weight(i) * d2 * d;
    b4 += weight(i) * d2 * d * d;
  }
  b2 /= n;
  b3 /= n;
  b4 /= n;
  r.mean = mean;
  r.sigma = std::sqrt(b2);
  if (!finite || !(b2 > 0.0)) return r;

  r.g1 = b3 / std::pow(b2, 1.5);
  r.g2 = b4 / (b2 * b2) - 3.0;
  r.sd_g1 = std::sqrt(6.0 * (n - 2) / ((n + 1) * (n + 3)));
  r.mean_g2 = -6.0 / (n + 1);
  r.sd_g2 = std::sqrt(24.0 * n * (n - 2) * (n - 3) / ((n + 1) * (n + 1) * (n + 3) * (n + 5)));
  r.u1 = r.g1 / r.sd_g1;
  r.u2 = (r.g2 - r.mean_g2) / r.sd_g2;
  r.defined = true;
  r.accepted = std::abs(r.u1) < z && std::abs(r.u2) < z;
  return r;
}

}  // namespace

NormalityResult SkewnessKurtosisTest(std::span<const double> samples, double z,
                                     std::size_t min_samples) noexcept {
  return Evaluate(
      samples.size(), [&](std::size_t i) { return samples[i]; }, [](std::size_t) { return 1.0; }, z,
      min_samples);
}

NormalityResult SkewnessKurtosisTestHistogram(std::span<const double> bin_centres,
                                              std::span<const std::uint64_t> counts, double z,
                                              std::size_t min_samples) noexcept {
  if (bin_centres.size() != counts.size()) return NormalityResult{};
  return Evaluate(
      bin_centres.size(), [&](std::size_t i) { return bin_centres[i]; },
      [&](std::size_t i) { return static_cast<double>(counts[i]); }, z, min_samples);
}

}  // namespace wheelhil::bus
