#pragma once
/// Reads the firmware's estimates from its own frames as its output binding says
/// (output_binding.h): each frame of a bound message gives one sample of every stream bound to
/// it, its values converted to SI units, time-stamped in s since the motion start (the frame's
/// arrival, the SYNC of its cycle signal, or its timestamp signal). Samples before the motion
/// start, of a cycle whose SYNC is unknown, or of a frame that lacks a bound signal (too short,
/// another multiplexer value) are left out; every frame of a bound message counts in its
/// stream's bus checks. The run hands it the frames of the motion phase. Thread-compatible.

#include <cstdint>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "bus/can_frame.h"
#include "emulator/scoring/artefacts.h"
#include "emulator/scoring/metrics.h"
#include "emulator/scoring/output_binding.h"

namespace wheelhil::emulator::scoring {

/// A slip stream's residual r (rad) against its band, per cycle the firmware calls calibrated.
struct ResidualTrace {
  std::vector<double> t_s, residual_rad, band_lower_rad, band_upper_rad;
};

/// The bus checks of one stream's frames (CANoe-style).
struct FrameChecks {
  std::uint64_t frames = 0;
  std::uint64_t dlc_errors = 0;       ///< Length differs from the DBC's.
  std::uint64_t counter_errors = 0;   ///< Counter did not advance by its step.
  std::uint64_t checksum_errors = 0;  ///< Checksum signal differs from the computed one.
  std::uint64_t intervals = 0;        ///< Gaps between consecutive frames.
  double min_interval_s = 0, max_interval_s = 0, sum_interval_s = 0;
  /// Gaps outside expected * (1 +- tolerance), when a cycle time is expected.
  std::uint64_t cycle_violations = 0;
};

class EstimateDecoder {
 public:
  explicit EstimateDecoder(OutputBinding binding);

  /// The next SYNC (the run's first is number 0) went out at t_s (since the motion start).
  void OnSync(double t_s);
  /// One frame the firmware sent, arriving at t_s (since the motion start; negative before).
  void OnFrame(const bus::CanFrame& f, double t_s);

  const OutputBinding& binding() const { return binding_; }
  const std::vector<EstimateRow>& rows() const { return rows_; }
  const std::map<std::string, std::vector<PoseSample>>& pose_streams() const { return pose_; }
  /// Pose streams without a bound heading (their theta is 0).
  const std::set<std::string>& position_only() const { return position_only_; }
  const std::map<std::string, std::vector<VelocitySample>>& velocity_streams() const {
    return vel_;
  }
  const std::map<std::string, std::vector<DetectionSample>>& detections() const {
    return detections_;
  }
  const std::map<std::string, ResidualTrace>& residuals() const { return residuals_; }
  /// Bus checks by stream name (every bound stream, frames seen or not).
  const std::map<std::string, FrameChecks>& frame_checks() const { return checks_; }

 private:
  struct StreamState {
    const ResolvedStream* stream = nullptr;
    FrameChecks* checks = nullptr;
    std::optional<double> last_arrival_s;
    std::optional<std::uint64_t> last_counter;
    std::optional<double> first_stamp_s, first_arrival_s;
  };
  void Check(StreamState& st, const bus::CanFrame& f, double t_s);
  std::optional<double> SampleTime(StreamState& st, const bus::CanFrame& f, double t_s,
                                   int& cycle) const;
  void Record(StreamState& st, const bus::CanFrame& f, double t, int cycle);

  OutputBinding binding_;
  std::map<std::uint64_t, std::vector<StreamState>> by_id_;
  std::vector<double> sync_times_;  // by SYNC number
  std::vector<EstimateRow> rows_;
  std::map<std::string, std::vector<PoseSample>> pose_;
  std::set<std::string> position_only_;
  std::map<std::string, std::vector<VelocitySample>> vel_;
  std::map<std::string, std::vector<DetectionSample>> detections_;
  std::map<std::string, ResidualTrace> residuals_;
  std::map<std::string, FrameChecks> checks_;
};

}  // namespace wheelhil::emulator::scoring
