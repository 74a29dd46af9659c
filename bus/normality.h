#pragma once
/// The skewness/kurtosis normality test of paper 000 (eqs 3-8), the one implementation for the
/// firmware (is the slip-free calibration residual normal before a mean +- z*sigma band is
/// trusted?) and the emulator's scorer (is the residual the firmware reported normal?).
///
/// With Bk the k-th sample central moment (divisor n): G1 = B3/B2^1.5, G2 = B4/B2^2 - 3.
/// Under normality (large n): E[G1] = 0, var G1 = 6(n-2)/((n+1)(n+3)), E[G2] = -6/(n+1),
/// var G2 = 24n(n-2)(n-3)/((n+1)^2 (n+3)(n+5)). U1 = G1/sd1, U2 = (G2 - E[G2])/sd2.
/// Normality is rejected when |U1| >= z or |U2| >= z (paper: z = z_{a/4} = 1.96 for a = 0.1).
///
/// It lives in bus/ although it is statistics, not CAN: the firmware may depend on bus/ only,
/// and bus/ is the one library both the firmware and the emulator link.
/// Pure functions, thread-safe.

#include <cstddef>
#include <cstdint>
#include <span>

namespace wheelhil::bus {

struct NormalityResult {
  std::size_t n = 0;  ///< Number of samples (always set).
  /// The test could be evaluated: n >= the minimum, every sample finite, variance > 0. When not,
  /// only n, and mean and sigma once n reaches the minimum, are set; `accepted` is false.
  bool defined = false;
  double mean = 0.0;      ///< Sample mean (unit of the samples).
  double sigma = 0.0;     ///< sqrt(B2), divisor n (unit of the samples).
  double g1 = 0.0;        ///< Sample skewness B3/B2^1.5.
  double g2 = 0.0;        ///< Sample excess kurtosis B4/B2^2 - 3.
  double sd_g1 = 0.0;     ///< sqrt(var G1) under normality.
  double mean_g2 = 0.0;   ///< E[G2] under normality, -6/(n+1).
  double sd_g2 = 0.0;     ///< sqrt(var G2) under normality.
  double u1 = 0.0;        ///< Standardised skewness.
  double u2 = 0.0;        ///< Standardised kurtosis.
  bool accepted = false;  ///< defined, |u1| < z and |u2| < z.
};

/// The fewest samples the statistics are defined for (var G2 is 0 at n = 3).
inline constexpr std::size_t kNormalityMinSamples = 4;

/// Test over raw samples; `z` is the two-sided critical value. With fewer than
/// max(min_samples, kNormalityMinSamples) samples nothing but n is computed.
NormalityResult SkewnessKurtosisTest(std::span<const double> samples, double z = 1.96,
                                     std::size_t min_samples = kNormalityMinSamples) noexcept;

/// Test over a histogram: every sample of bin i is taken at `bin_centres[i]` (no Sheppard
/// correction, as in the paper), n = sum of `counts`. Spans of different lengths: n = 0,
/// undefined.
NormalityResult SkewnessKurtosisTestHistogram(
    std::span<const double> bin_centres, std::span<const std::uint64_t> counts, double z = 1.96,
    std::size_t min_samples = kNormalityMinSamples) noexcept;

}  // namespace wheelhil::bus
