#pragma once
/// Sensor faults as modifiers applied to a sensor's output sample at its sample instant t
/// (integer ns), between the sensor model and the device that encodes it.
/// Each fault is active over its window [t0, t1) (t1 = kForever: from t0 on):
///   kBiasStep     + value (sample units: m/s^2, rad/s, counts);
///   kDriftRamp    + value * (t - t0) [s] (value in units per second);
///   kNoiseScale   noise x k (k = value >= 1): adds white noise of std nominal_noise_std *
///                 sqrt(k^2 - 1), so the total is k times the sensor's own noise;
///   kStuck        the output holds the value of the first sample in the window;
///   kDropout      no sample (Apply returns nullopt: the device sends nothing for it);
///   kSaturation   clamps to [-value, +value] (value > 0);
///   kMissedCounts counts only (ApplyCounts): each count increment in the window is lost with
///                 probability value in [0, 1]; the lost counts stay lost after the window (the
///                 counter drifts, as on hardware). Ignored by Apply (double samples).
/// Order: missed counts, bias, drift, noise, saturation, stuck, dropout. Randomness from one
/// std::mt19937_64 seeded with `seed`, drawn only while a random fault is active: same seed and
/// inputs -> same outputs. Start/end of each fault go to the FaultEventLog (category "sensor").
/// Thread-compatible.

#include <cstdint>
#include <memory>
#include <optional>
#include <random>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "emulator/faults/fault_event.h"

namespace wheelhil::emulator {

enum class SensorFaultKind : std::uint8_t {
  kBiasStep,
  kDriftRamp,
  kNoiseScale,
  kStuck,
  kDropout,
  kSaturation,
  kMissedCounts,
};

/// "bias_step", "drift_ramp", "noise_scale", "stuck", "dropout", "saturation", "missed_counts".
std::optional<SensorFaultKind> ParseSensorFaultKind(std::string_view name) noexcept;
std::string_view SensorFaultKindName(SensorFaultKind kind) noexcept;

struct SensorFault {
  SensorFaultKind kind = SensorFaultKind::kBiasStep;
  FaultWindow window;
  double value = 0.0;  ///< Bias, drift per s, noise factor k, saturation limit, loss probability.
};

class SensorFaultInjector {
 public:
  /// `sensor` names the target in the event log; nominal_noise_std is the sensor's own noise
  /// per sample (for kNoiseScale). Throws std::invalid_argument ("sensor_faults[i].field:
  /// problem") on a bad window or value.
  SensorFaultInjector(std::string sensor, std::vector<SensorFault> faults, double nominal_noise_std,
                      std::uint64_t seed, FaultEventLog* log = nullptr);

  /// The faulted sample at t_ns (nullopt: dropped). t_ns must not go backwards.
  std::optional<double> Apply(double sample, std::int64_t t_ns);
  /// The faulted counter register value (counter_bits wide, wraps) at t_ns.
  std::optional<std::uint32_t> ApplyCounts(std::uint32_t counts, std::int64_t t_ns,
                                           int counter_bits = 32);

  /// Counts lost to kMissedCounts so far.
  std::int64_t missed_counts() const { return missed_total_; }

 private:
  struct State {
    SensorFault fault;
    faults_internal::WindowPhase phase;
    bool holding = false;
    double held = 0.0;
  };
  void Track(std::int64_t t_ns);
  /// Everything except missed counts, on a double.
  std::optional<double> Modify(double x, std::int64_t t_ns, bool counts);

  std::string sensor_;
  std::vector<State> faults_;
  double nominal_noise_std_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
  bool have_last_counts_ = false;
  std::uint32_t last_counts_ = 0;
  std::int64_t missed_total_ = 0;
  FaultEventLog* log_ = nullptr;
};

/// The sensor faults of a multi-channel device at one sample instant: channel c's injector
/// (null: none) on samples[c]. Every injector is applied, also after a drop, so that each
/// channel's stream advances the same way whatever the others do. False when a sample was
/// dropped (the device then sends no frame for that instant).
bool ApplyToChannels(std::span<const std::unique_ptr<SensorFaultInjector>> faults,
                     std::span<double> samples, std::int64_t t_ns);

}  // namespace wheelhil::emulator
