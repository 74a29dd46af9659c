#include "emulator/scoring/truth_recorder.h"

#include <cmath>

namespace wheelhil::emulator::scoring {

void TruthRecorder::StartMotion(std::int64_t t0_ns, const physics::BodyTruth& body) {
  t_motion0_s_ = static_cast<double>(t0_ns) * 1e-9;
  p0_ = body.p_WB;
  yaw0_ = body.yaw_rad;
  rows_.clear();
  wheel_states_.clear();
  pose_.clear();
  vel_.clear();
}

void TruthRecorder::Record(std::int64_t t_ns, const physics::BodyTruth& b,
                           const std::vector<physics::WheelTruth>& wt, bool force) {
  if (!force && t_ns % o_.every_ns != 0) return;
  const double t = static_cast<double>(t_ns) * 1e-9 - t_motion0_s_;
  const double c = std::cos(-yaw0_), sn = std::sin(-yaw0_);
  const Eigen::Vector3d d = b.p_WB - p0_;
  TruthRow r;
  r.t_s = t;
  r.x_m = c * d.x() - sn * d.y();
  r.y_m = sn * d.x() + c * d.y();
  r.z_m = b.p_WB.z();
  r.theta_rad = b.yaw_rad - yaw0_;
  const Eigen::Vector3d v_B = b.q_WB.conjugate() * b.v_WB_W;
  const Eigen::Vector3d w_B = b.q_WB.conjugate() * b.omega_WB_W;
  r.vx_m_s = v_B.x();
  r.vy_m_s = v_B.y();
  r.omega_rad_s = w_B.z();
  for (std::size_t i = 0; i < o_.drive_wheels.size(); ++i) {
    if (Slipping(wt[o_.drive_wheels[i]])) r.slipping_wheels |= 1 << i;
  }
  if (!rows_.empty() && rows_.back().t_s == t) return;
  rows_.push_back(r);
  auto& states = wheel_states_.emplace_back();
  for (const physics::WheelTruth& w : wt) {
    states.push_back({w.omega_rad_s, w.slip_speed_m_s, w.normal_load_n, w.motor_torque_nm,
                      w.in_contact, Slipping(w)});
  }
  pose_.push_back({t, r.x_m, r.y_m, r.theta_rad});
  vel_.push_back({t, r.vx_m_s, r.vy_m_s, r.omega_rad_s});
}

void TruthRecorder::RecordMotionStep(std::int64_t t_end_ns,
                                     const std::vector<physics::WheelTruth>& wt) {
  bool slip = false;
  for (std::size_t w : o_.drive_wheels) slip = slip || Slipping(wt[w]);
  const double t_end_s = static_cast<double>(t_end_ns) * 1e-9;
  step_t_.push_back(t_end_s - o_.step_ns * 1e-9 - t_motion0_s_);
  slipping_.push_back(slip);
  airborne_.resize(wt.size());
  for (std::size_t w = 0; w < wt.size(); ++w) airborne_[w].push_back(!wt[w].in_contact);
}

}  // namespace wheelhil::emulator::scoring
