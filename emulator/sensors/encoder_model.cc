#include "emulator/sensors/encoder_model.h"

#include <fmt/format.h>

#include <cmath>
#include <numbers>
#include <stdexcept>

namespace wheelhil::emulator {
namespace {
void RequireProbability(double p, const char* field) {
  if (!(p >= 0.0 && p <= 1.0)) {
    throw std::invalid_argument(fmt::format("encoder.{} ({}) must be in [0, 1]", field, p));
  }
}
}  // namespace

EncoderModel::EncoderModel(const EncoderParams& params) : params_(params), rng_(params.seed) {
  if (params.lines_per_rev <= 0) {
    throw std::invalid_argument(
        fmt::format("encoder.lines_per_rev ({}) must be > 0", params.lines_per_rev));
  }
  if (params.counter_bits < 1 || params.counter_bits > 32) {
    throw std::invalid_argument(
        fmt::format("encoder.counter_bits ({}) must be in 1..32", params.counter_bits));
  }
  if (params.direction != 1 && params.direction != -1) {
    throw std::invalid_argument(
        fmt::format("encoder.direction ({}) must be +1 or -1", params.direction));
  }
  RequireProbability(params.missed_count_prob, "missed_count_prob");
  RequireProbability(params.glitch_prob, "glitch_prob");
  if (!(params.eccentricity_rad >= 0.0 && params.eccentricity_rad <= 0.1) ||
      !std::isfinite(params.eccentricity_phase_rad)) {
    throw std::invalid_argument(
        fmt::format("encoder.eccentricity_rad ({}) must be in [0, 0.1] with a finite phase",
                    params.eccentricity_rad));
  }
  if (!(params.disc_phase_counts >= 0.0 && params.disc_phase_counts < 1.0)) {
    throw std::invalid_argument(
        fmt::format("encoder.disc_phase_counts ({}) must be in [0, 1)", params.disc_phase_counts));
  }
  counts_per_rev_ = params.lines_per_rev * (params.quadrature_x4 ? 4 : 1);
  counter_mask_ = (std::uint64_t{1} << params.counter_bits) - 1;
  Reset(0.0, 0);
}

std::int64_t EncoderModel::IdealEdgeIndex(double wheel_angle_rad) const {
  const double read_angle =
      params_.eccentricity_rad > 0.0
          ? wheel_angle_rad + params_.eccentricity_rad *
                                  std::sin(wheel_angle_rad + params_.eccentricity_phase_rad)
          : wheel_angle_rad;
  const double counts =
      params_.direction * read_angle * counts_per_rev_ / (2.0 * std::numbers::pi) +
      params_.disc_phase_counts;
  return static_cast<std::int64_t>(std::floor(counts));
}

void EncoderModel::Reset(double wheel_angle_rad, std::int64_t count) {
  last_edge_index_ = IdealEdgeIndex(wheel_angle_rad);
  count_ = count;
}

std::uint32_t EncoderModel::Sample(double wheel_angle_rad) {
  const std::int64_t edge = IdealEdgeIndex(wheel_angle_rad);
  std::int64_t delta = edge - last_edge_index_;
  last_edge_index_ = edge;
  if (delta != 0 && params_.missed_count_prob > 0.0) {
    const std::int64_t n = delta > 0 ? delta : -delta;
    std::binomial_distribution<std::int64_t> lost(n, params_.missed_count_prob);
    const std::int64_t k = lost(rng_);
    missed_edges_ += k;
    delta += delta > 0 ? -k : k;
  }
  if (params_.glitch_prob > 0.0) {
    std::bernoulli_distribution glitch(params_.glitch_prob);
    if (glitch(rng_)) {
      std::bernoulli_distribution sign(0.5);
      delta += sign(rng_) ? 1 : -1;
      ++glitches_;
    }
  }
  count_ += delta;
  return counter();
}

std::uint32_t EncoderModel::counter() const {
  return static_cast<std::uint32_t>(static_cast<std::uint64_t>(count_) & counter_mask_);
}

}  // namespace wheelhil::emulator
