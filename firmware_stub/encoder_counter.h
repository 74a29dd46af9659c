#pragma once
/// Incremental-encoder helpers shared by the estimators: the signed step between two raw readings
/// of an N-bit hardware counter that wraps, and the counts -> metres conversion of a wheel.
/// Pure functions, thread-safe.

#include <cstdint>

namespace wheelhil::fw {

/// Signed change from `previous` to `current` of a free-running `bits`-wide up/down counter
/// (1 <= bits <= 64). Only the low `bits` bits of each reading are used. The result is the
/// shortest signed step modulo 2^bits, in [-2^(bits-1), 2^(bits-1)), so a counter that wrapped
/// (0xFFFFFFFF -> 0x00000002 with bits = 32 gives +3) is unwrapped correctly as long as the true
/// motion between two readings stays below half the counter range. `bits` outside [1, 64] gives 0.
std::int64_t CounterDelta(std::uint64_t previous, std::uint64_t current, int bits) noexcept;

/// Distance rolled by a wheel (or follower) of `radius_m` whose encoder gives `counts_per_rev`
/// counts per revolution, for a step of `delta_counts`: 2*pi*radius_m*delta_counts/counts_per_rev.
double CountsToMeters(std::int64_t delta_counts, double counts_per_rev, double radius_m) noexcept;

/// The inverse of CountsToMeters, unrounded (for test and emulator use).
double MetersToCounts(double distance_m, double counts_per_rev, double radius_m) noexcept;

/// Turns successive raw readings of one wheel's wrapping counter into metres rolled since the
/// previous reading. The first reading after construction or Reset() only primes it (returns 0).
/// Thread-compatible.
class EncoderIncrement {
 public:
  /// Throws std::invalid_argument ("counts_per_rev (0) must be finite and > 0") on bad values;
  /// counter_bits must be in [1, 64].
  EncoderIncrement(double counts_per_rev, double radius_m, int counter_bits);

  /// Metres rolled since the previous reading (signed, wrap handled), 0 on the first call.
  double Update(std::uint64_t raw_count) noexcept;
  /// Counts since the previous reading (signed, wrap handled), 0 on the first call.
  std::int64_t UpdateCounts(std::uint64_t raw_count) noexcept;
  void Reset() noexcept { primed_ = false; }

  double counts_per_rev() const { return counts_per_rev_; }
  double radius_m() const { return radius_m_; }
  int counter_bits() const { return counter_bits_; }

 private:
  double counts_per_rev_;
  double radius_m_;
  int counter_bits_;
  bool primed_ = false;
  std::uint64_t last_ = 0;
};

}  // namespace wheelhil::fw
