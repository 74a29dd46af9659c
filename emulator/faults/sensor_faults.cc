#include "emulator/faults/sensor_faults.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <fmt/format.h>

namespace wheelhil::emulator {

std::optional<SensorFaultKind> ParseSensorFaultKind(std::string_view name) noexcept {
  for (auto k : {SensorFaultKind::kBiasStep, SensorFaultKind::kDriftRamp,
                 SensorFaultKind::kNoiseScale, SensorFaultKind::kStuck, SensorFaultKind::kDropout,
                 SensorFaultKind::kSaturation, SensorFaultKind::kMissedCounts}) {
    if (SensorFaultKindName(k) == name) return k;
  }
  return std::nullopt;
}

std::string_view SensorFaultKindName(SensorFaultKind kind) noexcept {
  switch (kind) {
    case SensorFaultKind::kBiasStep:
      return "bias_step";
    case SensorFaultKind::kDriftRamp:
      return "drift_ramp";
    case SensorFaultKind::kNoiseScale:
      return "noise_scale";
    case SensorFaultKind::kStuck:
      return "stuck";
    case SensorFaultKind::kDropout:
      return "dropout";
    case SensorFaultKind::kSaturation:
      return "saturation";
    case SensorFaultKind::kMissedCounts:
      return "missed_counts";
  }
  return "?";
}

SensorFaultInjector::SensorFaultInjector(std::string sensor, std::vector<SensorFault> faults,
                                         double nominal_noise_std, std::uint64_t seed,
                                         FaultEventLog* log)
    : sensor_(std::move(sensor)), nominal_noise_std_(nominal_noise_std), rng_(seed) {
  log_ = log;
  if (!(nominal_noise_std >= 0.0) || !std::isfinite(nominal_noise_std)) {
    throw std::invalid_argument(fmt::format("{}: nominal_noise_std ({}) must be finite and >= 0",
                                            sensor_, nominal_noise_std));
  }
  for (std::size_t i = 0; i < faults.size(); ++i) {
    const SensorFault& f = faults[i];
    const std::string field = fmt::format("{}: sensor_faults[{}]", sensor_, i);
    if (!f.window.IsValid()) {
      throw std::invalid_argument(fmt::format("{}.window: [{}, {}) ns must have 0 <= t0 < t1",
                                              field, f.window.t0_ns, f.window.t1_ns));
    }
    if (!std::isfinite(f.value)) {
      throw std::invalid_argument(fmt::format("{}.value ({}) must be finite", field, f.value));
    }
    if (f.kind == SensorFaultKind::kNoiseScale && !(f.value >= 1.0)) {
      throw std::invalid_argument(
          fmt::format("{}.value: noise factor k ({}) must be >= 1", field, f.value));
    }
    if (f.kind == SensorFaultKind::kSaturation && !(f.value > 0.0)) {
      throw std::invalid_argument(
          fmt::format("{}.value: saturation limit ({}) must be > 0", field, f.value));
    }
    if (f.kind == SensorFaultKind::kMissedCounts && !(f.value >= 0.0 && f.value <= 1.0)) {
      throw std::invalid_argument(
          fmt::format("{}.value: loss probability ({}) must be in [0, 1]", field, f.value));
    }
    faults_.push_back({f, {}, false, 0.0});
  }
}

void SensorFaultInjector::Track(std::int64_t t_ns) {
  for (State& s : faults_) {
    if (s.phase.Pending(t_ns, s.fault.window)) {
      s.phase.Advance(t_ns, s.fault.window, log_, "sensor", SensorFaultKindName(s.fault.kind),
                      sensor_, fmt::format("value={}", s.fault.value));
    }
    if (!s.fault.window.Contains(t_ns)) s.holding = false;
  }
}

std::optional<double> SensorFaultInjector::Modify(double x, std::int64_t t_ns, bool counts) {
  bool drop = false;
  for (State& s : faults_) {
    if (!s.fault.window.Contains(t_ns)) continue;
    const double v = s.fault.value;
    switch (s.fault.kind) {
      case SensorFaultKind::kBiasStep:
        x += v;
        break;
      case SensorFaultKind::kDriftRamp:
        x += v * static_cast<double>(t_ns - s.fault.window.t0_ns) * 1e-9;
        break;
      case SensorFaultKind::kNoiseScale:
        x += nominal_noise_std_ * std::sqrt(v * v - 1.0) * normal_(rng_);
        break;
      case SensorFaultKind::kSaturation:
        x = std::clamp(x, -v, v);
        break;
      case SensorFaultKind::kDropout:
        drop = true;
        break;
      case SensorFaultKind::kStuck:
      case SensorFaultKind::kMissedCounts:
        break;
    }
  }
  if (counts) x = std::round(x);
  // Stuck after the additive faults: the output freezes where it was.
  for (State& s : faults_) {
    if (s.fault.kind != SensorFaultKind::kStuck || !s.fault.window.Contains(t_ns)) continue;
    if (!s.holding) {
      s.holding = true;
      s.held = x;
    }
    x = s.held;
  }
  if (drop) return std::nullopt;
  return x;
}

std::optional<double> SensorFaultInjector::Apply(double sample, std::int64_t t_ns) {
  Track(t_ns);
  return Modify(sample, t_ns, false);
}

std::optional<std::uint32_t> SensorFaultInjector::ApplyCounts(std::uint32_t counts,
                                                              std::int64_t t_ns, int counter_bits) {
  Track(t_ns);
  counter_bits = std::clamp(counter_bits, 1, 32);
  const std::uint64_t mask = (1ULL << counter_bits) - 1;
  const std::uint64_t half = 1ULL << (counter_bits - 1);
  // Missed counts: the lost part of each increment since the last sample.
  if (have_last_counts_) {
    const std::uint64_t raw_delta = (static_cast<std::uint64_t>(counts) - last_counts_) & mask;
    std::int64_t delta = static_cast<std::int64_t>(raw_delta);
    if (raw_delta >= half) delta -= static_cast<std::int64_t>(mask + 1);
    for (const State& s : faults_) {
      if (s.fault.kind != SensorFaultKind::kMissedCounts || !s.fault.window.Contains(t_ns) ||
          delta == 0 || s.fault.value <= 0.0) {
        continue;
      }
      std::binomial_distribution<std::int64_t> lost(delta < 0 ? -delta : delta, s.fault.value);
      const std::int64_t n = lost(rng_);
      missed_total_ += delta < 0 ? -n : n;
    }
  }
  have_last_counts_ = true;
  last_counts_ = counts;
  const std::uint64_t base =
      (static_cast<std::uint64_t>(counts) - static_cast<std::uint64_t>(missed_total_)) & mask;
  // Signed view of the register so bias/saturation act around zero.
  double x = static_cast<double>(base);
  if (base >= half) x -= static_cast<double>(mask + 1);
  const std::optional<double> y = Modify(x, t_ns, true);
  if (!y) return std::nullopt;
  const auto v = static_cast<std::int64_t>(*y);
  return static_cast<std::uint32_t>(static_cast<std::uint64_t>(v) & mask);
}

bool ApplyToChannels(std::span<const std::unique_ptr<SensorFaultInjector>> faults,
                     std::span<double> samples, std::int64_t t_ns) {
  bool kept = true;
  for (std::size_t c = 0; c < faults.size() && c < samples.size(); ++c) {
    if (!faults[c]) continue;
    const auto v = faults[c]->Apply(samples[c], t_ns);
    if (v) {
      samples[c] = *v;
    } else {
      kept = false;
    }
  }
  return kept;
}

}  // namespace wheelhil::emulator
