#pragma once
/// Scoring of a run as pure functions over time-stamped samples: the pose metrics of the papers
/// (paper 000 eq 13 final position error, heading error, APE RMSE after time alignment, path
/// length and total turned angle of the truth), slip detection against the physics' ground-truth
/// slip intervals (precision, recall, latency) and velocity RMSE. Planar poses in the world
/// frame W (x, y in m, heading theta in rad, CCW), times in s. No state; thread-safe.

#include <cstddef>
#include <optional>
#include <utility>
#include <vector>

namespace wheelhil::emulator::scoring {

struct PoseSample {
  double t_s = 0;
  double x_m = 0;
  double y_m = 0;
  double theta_rad = 0;  ///< Unwrapped or wrapped; differences are wrapped to (-pi, pi].
};

struct VelocitySample {
  double t_s = 0;
  double vx_m_s = 0;  ///< Body frame B, forward.
  double vy_m_s = 0;  ///< Body frame B, left.
  double omega_rad_s = 0;
};

struct PoseMetrics {
  double final_position_error_m = 0;   ///< Paper 000 eq 13: |p_est(end) - p_truth(end)|.
  double final_heading_error_rad = 0;  ///< |wrap(theta_est - theta_truth)| at the end.
  double ape_rmse_m = 0;    ///< RMS of position errors, estimate samples vs truth at their times.
  double distance_m = 0;    ///< Path length of the truth.
  double rotation_rad = 0;  ///< Sum of |heading increments| of the truth.
  std::size_t samples = 0;
};

/// Wraps an angle to (-pi, pi].
double WrapAngle(double a_rad);

/// Truth linearly interpolated at t (headings unwrapped between neighbours); clamps outside.
/// `truth` must be sorted by time and non-empty.
PoseSample InterpolatePose(const std::vector<PoseSample>& truth, double t_s);

/// |p_est(end) - p_truth(end)| (paper 000 eq 13): the last estimate sample against the truth
/// interpolated at its time; 0 when either is empty.
double FinalPositionError(const std::vector<PoseSample>& truth,
                          const std::vector<PoseSample>& estimate);

/// Pose metrics of an estimate stream against the truth (both sorted by time). The estimate's
/// samples are aligned to the truth by time (truth interpolated at each estimate time); the
/// final errors use the last estimate sample. Empty estimate: all-zero metrics with samples 0.
PoseMetrics ComputePoseMetrics(const std::vector<PoseSample>& truth,
                               const std::vector<PoseSample>& estimate);

/// Statistics of a set of errors, as evo prints them.
struct ErrorStats {
  std::size_t n = 0;
  double rmse = 0, mean = 0, median = 0, std = 0, min = 0, max = 0;
};
ErrorStats ComputeErrorStats(std::vector<double> errors);

/// evo's association (evo/core/sync.py associate_trajectories): each estimate sample paired
/// with the truth sample nearest in time, kept when |dt| <= max_diff_s. Both sorted by time.
std::vector<std::pair<PoseSample, PoseSample>> AssociateNearest(
    const std::vector<PoseSample>& truth, const std::vector<PoseSample>& estimate,
    double max_diff_s = 0.01);

/// APE of the translation part (m) over associated (truth, estimate) pairs, no alignment.
ErrorStats AbsolutePositionError(const std::vector<std::pair<PoseSample, PoseSample>>& pairs);

/// RPE over consecutive segments of at least `delta_m` of the truth's path (evo's
/// filter_pairs_by_path without all_pairs, measured on the truth): per segment (i, j) the
/// error E = (T_i^-1 T_j)^-1 (E_i^-1 E_j) of the planar poses; its translation (m per segment)
/// and its rotation angle (rad).
struct RelativePoseError {
  ErrorStats translation_m, rotation_rad;
};
RelativePoseError ComputeRelativePoseError(
    const std::vector<std::pair<PoseSample, PoseSample>>& pairs, double delta_m = 1.0);

/// Path length (sum of |dp|) and total turned angle (sum of |wrap(dtheta)|).
double PathLength(const std::vector<PoseSample>& truth);
double TotalRotation(const std::vector<PoseSample>& truth);

/// RMS of the velocity-vector error (vx, vy) of an estimate stream against the truth (truth
/// interpolated at each estimate time). 0 for an empty estimate.
double VelocityRmse(const std::vector<VelocitySample>& truth,
                    const std::vector<VelocitySample>& estimate);

/// A half-open time interval [start, end).
struct Interval {
  double start_s = 0;
  double end_s = 0;
};

/// Detection decision for one estimator cycle covering (t_s - period, t_s].
struct DetectionSample {
  double t_s = 0;
  bool detected = false;
};

struct SlipMetrics {
  std::size_t true_positive = 0, false_positive = 0, false_negative = 0, true_negative = 0;
  double precision = 0;  ///< TP / (TP + FP); 1 when nothing was detected.
  double recall = 0;     ///< TP / (TP + FN); 1 when nothing slipped.
  /// Mean over detected truth intervals of (first detection cycle end - interval start).
  std::optional<double> mean_latency_s;
  std::optional<double> max_latency_s;
  std::size_t intervals = 0;           ///< Ground-truth slip intervals.
  std::size_t intervals_detected = 0;  ///< ... with a detection within their span + 1 period.
};

/// Scores per-cycle detections against ground-truth slip intervals: a cycle (t - period, t] is
/// positive in truth when it overlaps any interval by at least `min_overlap_s`.
SlipMetrics ComputeSlipMetrics(const std::vector<Interval>& truth,
                               const std::vector<DetectionSample>& detections, double period_s,
                               double min_overlap_s = 0.0);

/// Turns per-step flags into intervals; intervals closer than merge_gap_s are merged and
/// intervals shorter than min_length_s dropped. `t_s` sorted, same size as `flags`; each flag
/// covers [t_s[i], t_s[i] + step_s).
std::vector<Interval> FlagsToIntervals(const std::vector<double>& t_s,
                                       const std::vector<bool>& flags, double step_s,
                                       double merge_gap_s = 0.0, double min_length_s = 0.0);


}  // namespace wheelhil::emulator::scoring
