#pragma once
/// Models an incremental (quadrature) rotary encoder reading a wheel's ground-truth angle.
///
/// The wheel angle (rad, any real value, unwrapped: spin shows as growing angle) is quantised
/// to counts: one count per edge, `lines_per_rev` optical lines per revolution, x4 decoding gives
/// 4 counts per line (x1 gives 1). The decoder accumulates edges into a counter of
/// `counter_bits` bits that wraps modulo 2^bits like the hardware register. Imperfections:
///   - direction: +1 counts up for positive wheel angle, -1 counts down (mounting);
///   - missed counts: each edge is lost independently with probability `missed_count_prob`
///     (the lost edges are gone for good: the count drifts, as on real hardware);
///   - glitches: on each sample, with probability `glitch_prob`, a spurious +-1 count is added
///     (noise on the A/B lines);
///   - eccentricity: a disc mounted off its shaft's centre by e is read at radius rho as the
///     angle + (e / rho) sin(angle + phase): `eccentricity_rad` is e / rho, a once-per-turn
///     error that a full turn cancels and a part turn does not.
/// Randomness comes from a std::mt19937_64 seeded with `seed` and is drawn only when the
/// corresponding probability is > 0: same seed and inputs -> same counts (with libstdc++).
/// Thread-compatible.

#include <cstdint>
#include <random>

namespace wheelhil::emulator {

struct EncoderParams {
  int lines_per_rev = 1024;        ///< Optical lines (A/B cycles) per revolution, > 0.
  bool quadrature_x4 = true;       ///< x4 decoding (4 counts per line) or x1 (1 per line).
  int counter_bits = 32;           ///< Counter register width, 1..32 bits; wraps modulo 2^bits.
  int direction = 1;               ///< +1 or -1.
  double missed_count_prob = 0.0;  ///< Probability that one edge is not counted, [0, 1].
  double glitch_prob = 0.0;        ///< Probability per sample of a spurious +-1 count, [0, 1].
  /// Where the disc's edges sit at wheel angle 0, in counts, [0, 1): the ideal count is
  /// floor(direction * angle * cpr / 2pi + disc_phase_counts). 0 puts an edge exactly at angle 0,
  /// so a wheel that only trembles there flips between two counts.
  double disc_phase_counts = 0.0;
  double eccentricity_rad = 0.0;        ///< Peak angle error of an off-centre disc, [0, 0.1].
  double eccentricity_phase_rad = 0.0;  ///< Wheel angle at which that error is zero and rising.
  std::uint64_t seed = 0;               ///< RNG seed.
};

class EncoderModel {
 public:
  /// Throws std::invalid_argument naming the bad field.
  explicit EncoderModel(const EncoderParams& params);

  /// Re-zeroes the decoder: the counter reads `count` (taken modulo 2^bits) at this wheel angle.
  /// The constructor behaves as Reset(0.0, 0): the counter then reads floor(angle * cpr / 2pi).
  void Reset(double wheel_angle_rad, std::int64_t count = 0);

  /// Samples the encoder at the wheel's true angle; returns the counter register value.
  std::uint32_t Sample(double wheel_angle_rad);

  /// Counts per revolution after decoding (lines * 4 for x4).
  int counts_per_rev() const { return counts_per_rev_; }
  /// The counter register value of the last sample (wrapped to counter_bits).
  std::uint32_t counter() const;
  /// Unwrapped count since Reset, signed (what an ideal infinite counter would hold).
  std::int64_t unwrapped_count() const { return count_; }
  /// Total edges lost to missed counts and spurious glitch counts added so far.
  std::int64_t missed_edges() const { return missed_edges_; }
  std::int64_t glitches() const { return glitches_; }

 private:
  std::int64_t IdealEdgeIndex(double wheel_angle_rad) const;

  EncoderParams params_;
  int counts_per_rev_;
  std::uint64_t counter_mask_;
  std::int64_t last_edge_index_ = 0;  ///< Ideal (quantised) position at the last sample.
  std::int64_t count_ = 0;            ///< Accumulated decoder count, unwrapped.
  std::int64_t missed_edges_ = 0;
  std::int64_t glitches_ = 0;
  std::mt19937_64 rng_;
};

}  // namespace wheelhil::emulator
