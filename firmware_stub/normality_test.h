#pragma once
/// The skewness/kurtosis normality test of paper 000 (eqs 3-8), used to check that the
/// encoder-minus-gyro heading residual of a slip-free calibration run is normally distributed
/// before a mean +- z*sigma band is trusted. Pure functions, thread-safe.
///
/// With Bk the k-th sample central moment (divisor n): G1 = B3/B2^1.5, G2 = B4/B2^2 - 3.
/// Under normality (large n): E[G1] = 0, var G1 = 6(n-2)/((n+1)(n+3)), E[G2] = -6/(n+1),
/// var G2 = 24n(n-2)(n-3)/((n+1)^2 (n+3)(n+5)). U1 = G1/sd1, U2 = (G2 - E[G2])/sd2.
/// Normality is rejected when |U1| >= z or |U2| >= z (paper: z = z_{a/4} = 1.96 for a = 0.1).

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>

namespace wheelhil::fw {

struct NormalityResult {
  std::size_t n = 0;      ///< Number of samples.
  double mean = 0.0;      ///< Sample mean (unit of the samples).
  double sigma = 0.0;     ///< sqrt(B2), divisor n (unit of the samples).
  double g1 = 0.0;        ///< Sample skewness B3/B2^1.5.
  double g2 = 0.0;        ///< Sample excess kurtosis B4/B2^2 - 3.
  double sd_g1 = 0.0;     ///< sqrt(var G1) under normality.
  double mean_g2 = 0.0;   ///< E[G2] under normality, -6/(n+1).
  double sd_g2 = 0.0;     ///< sqrt(var G2) under normality.
  double u1 = 0.0;        ///< Standardised skewness.
  double u2 = 0.0;        ///< Standardised kurtosis.
  bool accepted = false;  ///< |u1| < z and |u2| < z.
};

/// Test over raw samples. Returns nullopt when the test is undefined: n < 4, a non-finite
/// sample, or zero variance. `z` is the two-sided critical value (default 1.96).
std::optional<NormalityResult> SkewnessKurtosisTest(std::span<const double> samples,
                                                    double z = 1.96) noexcept;

/// Test over a histogram: every sample of bin i is taken at `bin_centres[i]` (no Sheppard
/// correction, as in the paper), n = sum of `counts`. Returns nullopt when the spans differ in
/// length or for the cases above.
std::optional<NormalityResult> SkewnessKurtosisTestHistogram(std::span<const double> bin_centres,
                                                             std::span<const std::uint64_t> counts,
                                                             double z = 1.96) noexcept;

}  // namespace wheelhil::fw
