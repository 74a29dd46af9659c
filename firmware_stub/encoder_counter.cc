#include "firmware_stub/encoder_counter.h"

#include <fmt/format.h>

#include <cmath>
#include <numbers>
#include <stdexcept>

namespace wheelhil::fw {

std::int64_t CounterDelta(std::uint64_t previous, std::uint64_t current, int bits) noexcept {
  if (bits < 1 || bits > 64) return 0;
  // Unsigned subtraction is modular; keep the low `bits` bits and sign-extend from bit bits-1.
  std::uint64_t diff = current - previous;
  if (bits == 64) return static_cast<std::int64_t>(diff);
  const std::uint64_t mask = (std::uint64_t{1} << bits) - 1;
  diff &= mask;
  const std::uint64_t sign = std::uint64_t{1} << (bits - 1);
  if (diff & sign) return static_cast<std::int64_t>(diff | ~mask);
  return static_cast<std::int64_t>(diff);
}

double CountsToMeters(std::int64_t delta_counts, double counts_per_rev, double radius_m) noexcept {
  return 2.0 * std::numbers::pi * radius_m * static_cast<double>(delta_counts) / counts_per_rev;
}

double MetersToCounts(double distance_m, double counts_per_rev, double radius_m) noexcept {
  return distance_m * counts_per_rev / (2.0 * std::numbers::pi * radius_m);
}

EncoderIncrement::EncoderIncrement(double counts_per_rev, double radius_m, int counter_bits)
    : counts_per_rev_(counts_per_rev), radius_m_(radius_m), counter_bits_(counter_bits) {
  if (!std::isfinite(counts_per_rev) || counts_per_rev <= 0.0) {
    throw std::invalid_argument(
        fmt::format("counts_per_rev ({}) must be finite and > 0", counts_per_rev));
  }
  if (!std::isfinite(radius_m) || radius_m <= 0.0) {
    throw std::invalid_argument(fmt::format("radius_m ({}) must be finite and > 0", radius_m));
  }
  if (counter_bits < 1 || counter_bits > 64) {
    throw std::invalid_argument(fmt::format("counter_bits ({}) must be in [1, 64]", counter_bits));
  }
}

std::int64_t EncoderIncrement::UpdateCounts(std::uint64_t raw_count) noexcept {
  if (!primed_) {
    primed_ = true;
    last_ = raw_count;
    return 0;
  }
  const std::int64_t delta = CounterDelta(last_, raw_count, counter_bits_);
  last_ = raw_count;
  return delta;
}

double EncoderIncrement::Update(std::uint64_t raw_count) noexcept {
  return CountsToMeters(UpdateCounts(raw_count), counts_per_rev_, radius_m_);
}

}  // namespace wheelhil::fw
