#pragma once
/// A run's metrics as named components. Each component reads what the run recorded (ground
/// truth, the firmware's decoded estimates) and adds its block to report.json's `metrics` (and
/// its events to events.jsonl) when it applies; a scenario selects the components by name
/// (`scoring.metrics`), by default the generic ones. Generic components: "pose" (one block per
/// pose stream: paper 000 eq 13 final error, APE RMSE after interpolation, evo-style APE and RPE
/// per metre, ...), "velocity" (RMSE per velocity stream), "truth" (slip intervals of the ground
/// truth, distance, rotation), "contact" (ground-truth contact loss per wheel), "frames" (bus
/// checks of each stream's frames: count, DLC, cycle time, counter, checksum). Paper-specific ones:
/// "correction_ratio" (paper 000 Table 2: uncorrected over corrected final error), "slip_detection"
/// (paper 000: precision, recall and latency of the firmware's slip flags against the truth),
/// "residual_normality" (paper 000: skewness/kurtosis test of the firmware's calibrated residual).
/// Closed loop: "closed_loop" (where the firmware took the robot against the scenario's goal; per
/// drive fault, how the firmware reacted: time to detect = first drive other than the faulted one
/// leaving Operation enabled, truth distance after the fault start, time until the robot stands
/// still for good). Components always run in this canonical order, so the metrics and events do not
/// depend on how a scenario lists them. Thread-compatible.

#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "emulator/scoring/estimate_decoder.h"
#include "emulator/scoring/metrics.h"
#include "emulator/scoring/truth_recorder.h"

namespace wheelhil::emulator::scoring {

/// What the components read.
struct RecordedRun {
  const TruthRecorder& truth;
  const EstimateDecoder& estimates;
  double sync_period_s = 0;
  std::vector<std::string> wheel_names;  ///< Vehicle wheel order.
  /// Ground-truth slip intervals (from truth.slipping(); merged over 20 ms gaps).
  std::vector<Interval> slip_intervals;
  /// Closed loop: where the firmware's path ends (start frame; theta only with goal_has_heading).
  std::optional<PoseSample> goal;
  bool goal_has_heading = false;
  /// The run's events so far (fault_start, drive_state, ...), t_s since the motion start.
  std::vector<nlohmann::json> run_events;
};

class MetricComponent {
 public:
  virtual ~MetricComponent() = default;
  virtual std::string_view name() const = 0;
  /// Adds the component's block(s) to `metrics` and its events to `events` (unsorted).
  virtual void Compute(const RecordedRun& run, nlohmann::json& metrics,
                       std::vector<nlohmann::json>& events) const = 0;
};

/// Every component name, in the canonical order.
const std::vector<std::string>& MetricComponentNames();
/// What a scenario gets without `scoring.metrics`: the generic components.
std::vector<std::string> DefaultMetricComponents();
/// Throws std::invalid_argument naming the known components for an unknown name.
std::unique_ptr<MetricComponent> MakeMetricComponent(std::string_view name);

/// The run's slip intervals from its per-step flags (merged over gaps < 20 ms).
std::vector<Interval> SlipIntervals(const TruthRecorder& truth);

/// Runs the selected components in the canonical order on
/// `metrics`, then sorts `events` by time (stable: events of one instant keep their order).
void ScoreRun(const RecordedRun& run, const std::vector<std::string>& selected,
              nlohmann::json& metrics, std::vector<nlohmann::json>& events);

}  // namespace wheelhil::emulator::scoring
