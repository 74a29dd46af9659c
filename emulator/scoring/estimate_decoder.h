#pragma once
/// Reads the firmware's estimate frames as its DBC file (bus/dbc/wheelhil_fw.dbc) describes
/// them: FW_Pose / FW_PoseRaw (pose streams "pose", "pose_raw"), FW_Velocity / FW_VelocityOdom /
/// FW_VelocityAccel (velocity streams "fused", "odometry", "accel") and FW_SlipStatus (slip
/// detections and the paper 000 residual against its band). Every estimate frame carries the
/// cycle counter (mod 256) of the SYNC that opened its cycle; the estimate is time-stamped with
/// that SYNC's instant (s since the motion start). Frames of other messages, and estimates of
/// a cycle whose SYNC is unknown, are ignored. Thread-compatible.

#include <map>
#include <memory>
#include <string>
#include <vector>

#include "bus/can_frame.h"
#include "bus/dbc.h"
#include "emulator/scoring/artefacts.h"
#include "emulator/scoring/metrics.h"

namespace wheelhil::emulator::scoring {

/// Paper 000's residual r (rad) against its band, per cycle with a calibrated band.
struct ResidualTrace {
  std::vector<double> t_s, residual_rad, band_lower_rad, band_upper_rad;
};

class EstimateDecoder {
 public:
  explicit EstimateDecoder(std::shared_ptr<const bus::DbcDatabase> firmware_dbc);

  /// SYNC number `cycle` (mod 256) went out at t_s (s since the motion start).
  void OnSync(int cycle, double t_s) { sync_time_by_cycle_[cycle] = t_s; }
  /// One frame the firmware sent.
  void OnFrame(const bus::CanFrame& f);

  const std::vector<EstimateRow>& rows() const { return rows_; }
  const std::map<std::string, std::vector<PoseSample>>& pose_streams() const { return pose_; }
  const std::map<std::string, std::vector<VelocitySample>>& velocity_streams() const {
    return vel_;
  }
  const std::vector<DetectionSample>& detections() const { return detections_; }
  const ResidualTrace& residual() const { return residual_; }

 private:
  // What OnFrame reads from one message, worked out at its first frame: the signals of each
  // field (the first present one of that name wins, as DecodeMessage's map would give it).
  struct Plan {
    enum class Kind { kPose, kVelocity, kSlip, kIgnored };
    Kind kind = Kind::kIgnored;
    std::string stream;
    // The cycle, then the kind's values in order.
    std::vector<std::vector<const bus::DbcSignal*>> fields;
    std::vector<PoseSample>* pose = nullptr;
    std::vector<VelocitySample>* vel = nullptr;
  };
  Plan& PlanFor(const bus::DbcMessage& msg);

  std::shared_ptr<const bus::DbcDatabase> dbc_;
  std::map<const bus::DbcMessage*, Plan> plans_;
  std::map<int, double> sync_time_by_cycle_;
  std::vector<EstimateRow> rows_;
  std::map<std::string, std::vector<PoseSample>> pose_;
  std::map<std::string, std::vector<VelocitySample>> vel_;
  std::vector<DetectionSample> detections_;
  ResidualTrace residual_;
};

}  // namespace wheelhil::emulator::scoring
