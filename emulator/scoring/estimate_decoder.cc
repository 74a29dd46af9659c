#include "emulator/scoring/estimate_decoder.h"

#include <initializer_list>

#include "bus/dbc_codec.h"

namespace wheelhil::emulator::scoring {

EstimateDecoder::EstimateDecoder(std::shared_ptr<const bus::DbcDatabase> firmware_dbc)
    : dbc_(std::move(firmware_dbc)) {}

void EstimateDecoder::OnFrame(const bus::CanFrame& f) {
  if (f.extended) return;
  const bus::DbcMessage* msg = dbc_->FindMessage(f.id, false);
  if (msg == nullptr) return;
  Plan& plan = PlanFor(*msg);
  if (plan.kind == Plan::Kind::kIgnored) return;
  auto get = [&](std::size_t field) {
    double value = 0.0;
    for (const bus::DbcSignal* sig : plan.fields[field]) {
      if (bus::DecodeSignalIfPresent(*msg, *sig, f, &value)) return value;
    }
    return 0.0;
  };
  const int cycle = static_cast<int>(get(0));
  const auto it = sync_time_by_cycle_.find(cycle);
  if (it == sync_time_by_cycle_.end()) return;
  const double t = it->second;
  switch (plan.kind) {
    case Plan::Kind::kPose: {
      const PoseSample ps{t, get(1), get(2), get(3)};
      if (plan.pose == nullptr) plan.pose = &pose_[plan.stream];
      plan.pose->push_back(ps);
      rows_.push_back({t, cycle, plan.stream, ps.x_m, ps.y_m, ps.theta_rad});
      break;
    }
    case Plan::Kind::kVelocity: {
      const VelocitySample vs{t, get(1), get(2), get(3)};
      if (plan.vel == nullptr) plan.vel = &vel_[plan.stream];
      plan.vel->push_back(vs);
      rows_.push_back({t, cycle, plan.stream, vs.vx_m_s, vs.vy_m_s, vs.omega_rad_s});
      break;
    }
    case Plan::Kind::kSlip:
      detections_.push_back({t, get(1) != 0});
      if (get(2) != 0) {
        residual_.t_s.push_back(t);
        residual_.residual_rad.push_back(get(3));
        residual_.band_lower_rad.push_back(get(4));
        residual_.band_upper_rad.push_back(get(5));
      }
      break;
    default:
      break;
  }
}

EstimateDecoder::Plan& EstimateDecoder::PlanFor(const bus::DbcMessage& msg) {
  const auto found = plans_.find(&msg);
  if (found != plans_.end()) return found->second;
  Plan plan;
  auto field = [&](const std::string& name) {
    std::vector<const bus::DbcSignal*> sigs;
    for (const auto& sg : msg.signals) {
      if (sg.name == name) sigs.push_back(&sg);
    }
    plan.fields.push_back(std::move(sigs));
  };
  auto estimate = [&](Plan::Kind kind, const char* stream, const std::string& prefix,
                      std::initializer_list<const char*> names) {
    plan.kind = kind;
    plan.stream = stream;
    for (const char* n : names) field(prefix + n);
  };
  // The cycle: the first signal named <prefix>_Cycle; a message without one is not an estimate.
  std::string cycle;
  for (const auto& sg : msg.signals) {
    if (sg.name.size() > 6 && sg.name.ends_with("_Cycle")) {
      cycle = sg.name;
      break;
    }
  }
  if (!cycle.empty()) {
    field(cycle);
    if (msg.name == "FW_Pose") {
      estimate(Plan::Kind::kPose, "pose", "Pose", {"_X", "_Y", "_Theta"});
    } else if (msg.name == "FW_PoseRaw") {
      estimate(Plan::Kind::kPose, "pose_raw", "PoseRaw", {"_X", "_Y", "_Theta"});
    } else if (msg.name == "FW_Velocity") {
      estimate(Plan::Kind::kVelocity, "fused", "Vel", {"_Vx", "_Vy", "_Omega"});
    } else if (msg.name == "FW_VelocityOdom") {
      estimate(Plan::Kind::kVelocity, "odometry", "VelOdom", {"_Vx", "_Vy", "_Omega"});
    } else if (msg.name == "FW_VelocityAccel") {
      estimate(Plan::Kind::kVelocity, "accel", "VelAccel", {"_Vx", "_Vy", "_Omega"});
    } else if (msg.name == "FW_SlipStatus") {
      estimate(Plan::Kind::kSlip, "", "Slip_",
               {"OutOfBand", "Calibrated", "Residual", "BandLower", "BandUpper"});
    }
  }
  return plans_.emplace(&msg, std::move(plan)).first->second;
}

}  // namespace wheelhil::emulator::scoring
