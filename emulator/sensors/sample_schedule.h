#pragma once
/// When a sensor samples, independent of the physics step. A sensor with period P and phase
/// offset samples at t_k = phase + k P (integer ns of virtual time). The physics produces ground
/// truth at its own step; for each physics step (t_prev, t_now] the runner asks which sample
/// instants fall inside and evaluates the sensor on the ground truth interpolated linearly
/// between the two steps (weight alpha = (t_k - t_prev) / (t_now - t_prev)); when the physics
/// step divides the period (and the phase), every t_k coincides with a step and alpha = 1, so
/// the sample sees that step's ground truth exactly, without interpolation.
/// Value type; thread-compatible.

#include <cstdint>
#include <stdexcept>
#include <vector>

namespace wheelhil::emulator {

class SampleSchedule {
 public:
  /// Throws std::invalid_argument when period_ns <= 0 or phase_ns is not in [0, period_ns).
  SampleSchedule(std::int64_t period_ns, std::int64_t phase_ns = 0)
      : period_ns_(period_ns), phase_ns_(phase_ns) {
    if (period_ns <= 0) throw std::invalid_argument("sensor sample period must be > 0 ns");
    if (phase_ns < 0 || phase_ns >= period_ns) {
      throw std::invalid_argument("sensor sample phase must be in [0, period)");
    }
  }

  /// A sample instant inside a physics step and its interpolation weight towards t_now.
  struct Instant {
    std::int64_t t_ns;
    double alpha;  ///< 0 at t_prev (excluded), 1 at t_now.
  };

  /// Sample instants in (t_prev_ns, t_now_ns], in order. Empty when t_now_ns <= t_prev_ns.
  std::vector<Instant> InStep(std::int64_t t_prev_ns, std::int64_t t_now_ns) const {
    std::vector<Instant> out;
    if (t_now_ns <= t_prev_ns) return out;
    for (std::int64_t t = FirstAfter(t_prev_ns); t <= t_now_ns; t += period_ns_) {
      out.push_back(
          {t, static_cast<double>(t - t_prev_ns) / static_cast<double>(t_now_ns - t_prev_ns)});
    }
    return out;
  }

  /// The first sample instant strictly after t_ns.
  std::int64_t FirstAfter(std::int64_t t_ns) const {
    const std::int64_t rel = t_ns - phase_ns_;
    std::int64_t k = rel >= 0 ? rel / period_ns_ + 1 : -((-rel) / period_ns_);
    if (phase_ns_ + k * period_ns_ <= t_ns) ++k;
    return phase_ns_ + k * period_ns_;
  }

  std::int64_t period_ns() const { return period_ns_; }
  std::int64_t phase_ns() const { return phase_ns_; }

 private:
  std::int64_t period_ns_;
  std::int64_t phase_ns_;
};

}  // namespace wheelhil::emulator
