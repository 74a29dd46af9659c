#include "firmware_stub/fw_app.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "bus/canopen.h"
#include "bus/cia402.h"

namespace wheelhil::fw {
namespace {

constexpr double kPi = 3.14159265358979323846;

std::int64_t ToNs(double s) { return static_cast<std::int64_t>(std::llround(s * 1e9)); }

/// Heading wrapped to (-pi, pi] for the pose frames.
double WrapPi(double a) {
  double w = std::remainder(a, 2.0 * kPi);
  if (w <= -kPi) w += 2.0 * kPi;
  return w;
}

std::uint32_t Bit(bool b, std::uint32_t bit) { return b ? bit : 0u; }

}  // namespace

std::uint64_t MasterHeartbeatCycles(const FwConfig& config) {
  if (!config.drives.enabled || config.drives.master_heartbeat_s <= 0) return 0;
  return static_cast<std::uint64_t>(
      std::max(1.0, std::ceil(config.drives.master_heartbeat_s / config.sync.period_s - 1e-9)));
}

double DriveHeartbeatTimeoutS(const FwConfig& config) {
  if (config.drives.drive_heartbeat_timeout_s > 0) return config.drives.drive_heartbeat_timeout_s;
  return 3.0 * static_cast<double>(MasterHeartbeatCycles(config)) * config.sync.period_s;
}

CanopenMasterConfig MasterConfigFrom(const FwConfig& config) {
  CanopenMasterConfig m;
  for (const auto& n : config.encoder_nodes()) {
    m.node_ids.push_back(static_cast<std::uint8_t>(n.node_id));
  }
  const DriveSettings& d = config.drives;
  for (const auto& n : d.nodes) {
    const auto id = static_cast<std::uint8_t>(n.node_id);
    m.node_ids.push_back(id);
    namespace c402 = bus::cia402::od;
    m.node_writes.push_back(
        {id, c402::kModesOfOperation, 0, static_cast<std::uint32_t>(d.mode), 1});
    m.node_writes.push_back({id, c402::kAbortConnectionOption, 0,
                             static_cast<std::uint32_t>(d.abort_connection_option), 2});
    m.node_writes.push_back(
        {id, c402::kQuickStopOption, 0, static_cast<std::uint32_t>(d.quick_stop_option), 2});
    if (d.master_heartbeat_s > 0) {
      const std::uint32_t ms =
          static_cast<std::uint32_t>(std::llround(DriveHeartbeatTimeoutS(config) * 1e3));
      m.node_writes.push_back({id, bus::canopen::od::kConsumerHeartbeatTime, 1,
                               static_cast<std::uint32_t>(d.master_node_id) << 16 | ms, 4});
    }
  }
  const CanopenSettings& c = config.canopen;
  m.boot_timeout_ns = ToNs(c.boot_timeout_s);
  m.heartbeat_producer_ms = static_cast<std::uint16_t>(std::llround(c.heartbeat_period_s * 1e3));
  m.heartbeat_timeout_ns = ToNs(c.heartbeat_timeout_s);
  m.sdo_timeout_ns = ToNs(c.sdo_timeout_s);
  m.sdo_retries = c.sdo_retries;
  m.tpdo_transmission_type = static_cast<std::uint8_t>(c.tpdo_transmission_type);
  m.reset_communication_at_start = c.reset_communication_at_start;
  m.produce_sync = config.sync.produce;
  m.sync_period_ns = ToNs(config.sync.period_s);
  if (!config.sync.produce) {
    // Following SYNC the master runs on bus time (FwApp::MasterClockNs), which knows a frame's
    // instant only to the SYNC interval it came in: each timeout waits one period more, so it
    // never fires before it is due (at most one period late).
    m.boot_timeout_ns += m.sync_period_ns;
    m.sdo_timeout_ns += m.sync_period_ns;
    if (m.heartbeat_timeout_ns > 0) m.heartbeat_timeout_ns += m.sync_period_ns;
  }
  return m;
}

CycleAssemblerConfig AssemblerConfigFrom(const FwConfig& config) {
  CycleAssemblerConfig a;
  for (const auto& n : config.encoder_nodes()) {
    a.tpdo_nodes.push_back(static_cast<std::uint8_t>(n.node_id));
  }
  a.deadline_ns = ToNs(config.sync.deadline_s);  // 0: no deadline.
  return a;
}

FwApp::FwApp(const FwConfig& config, const FwProtocol& protocol, const DriveProtocol* drives)
    : config_(config),
      protocol_(protocol),
      master_(MasterConfigFrom(config), protocol),
      assembler_(AssemblerConfigFrom(config)),
      nodes_(config.encoder_nodes()),
      period_ns_(ToNs(config.sync.period_s)),
      bus_clock_(!config.sync.produce),
      sync_silence_ns_(
          std::max(kSyncSilenceMinNs, kSyncSilencePeriods * ToNs(config.sync.period_s))) {
  const std::string where =
      fmt::format("{}: {}", config.source_path, EstimatorName(config.estimator));
  try {
    switch (config.estimator) {
      case EstimatorKind::kPaper000SlipCorrection: {
        const Paper000Settings& p = config.paper000;
        SlipEstimatorConfig c;
        c.track_width_m = p.track_width_m;
        c.calibration_samples = static_cast<std::size_t>(p.calibration_samples);
        c.residual_mean_rad = p.residual_mean_rad;
        c.residual_sigma_rad = p.residual_sigma_rad;
        c.z = p.z;
        c.heading_rule = p.heading_rule;
        p000_.emplace(c);
        (void)EncoderIncrement(p.counts_per_rev, p.wheel_radius_m, p.counter_bits);  // Checks.
        break;
      }
      case EstimatorKind::kPaper001FollowerOdometry: {
        const Paper001Settings& p = config.paper001;
        FollowerOdometryConfig c;
        c.geometry.mount_radius_m = p.mount_radius_m;
        c.geometry.angles_rad = p.angles_rad;
        c.follower_radius_m = p.follower_radius_m;
        c.counts_per_rev = p.counts_per_rev;
        c.counter_bits = p.counter_bits;
        c.heading_rule = p.heading_rule;
        p001_.emplace(c);
        break;
      }
      case EstimatorKind::kPaper002Fusion: {
        const Paper002Settings& p = config.paper002;
        VelocityFusionConfig c;
        c.period_s = config.sync.period_s;
        c.accel_mount_radius_m = p.accel_mount_radius_m;
        for (std::size_t i = 0; i < 3; ++i) {
          const Paper002AxisSettings& a = p.axes[i];
          c.axes[i].observer = {a.k11_1_s, a.k12_u_s, a.k21_1_s2, a.k22_u_s2, a.boundary_layer_u};
          c.axes[i].disturbance_threshold_u_s2 = a.disturbance_threshold_u_s2;
          c.axes[i].recovery_time_s = a.recovery_time_s;
        }
        c.k_min = p.k_min;
        c.observer_uses_commanded_accel = false;  // No commanded acceleration on the bus.
        p002_.emplace(c);
        p002_geometry_.mount_radius_m = p.wheel_mount_radius_m;
        p002_geometry_.angles_rad = p.angles_rad;
        (void)EncoderIncrement(p.counts_per_rev, p.wheel_radius_m, p.counter_bits);  // Checks.
        const FollowerTwist probe = BodyTwistFromRimSpeeds(p002_geometry_, {1.0, 2.0, 3.0});
        if (!std::isfinite(probe.vx_m_s) || !std::isfinite(probe.vy_m_s) ||
            !std::isfinite(probe.omega_rad_s)) {
          throw std::invalid_argument("wheels: angle_deg values give a singular geometry");
        }
        break;
      }
    }
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(fmt::format("{}: {}", where, e.what()));
  }
  if (config.drives.enabled) {
    if (!drives) {
      throw std::invalid_argument(fmt::format(
          "{}: drives: no drive protocol (cia402_drive.dbc) given", config.source_path));
    }
    const double hb_s = static_cast<double>(MasterHeartbeatCycles(config)) * config.sync.period_s;
    if (hb_s > 0 && DriveHeartbeatTimeoutS(config) <= hb_s) {
      throw std::invalid_argument(fmt::format(
          "{}: drives: drive_heartbeat_timeout_s ({}) must exceed the firmware's heartbeat "
          "period ({} s: master_heartbeat_s rounded up to whole sync periods)",
          config.source_path, DriveHeartbeatTimeoutS(config), hb_s));
    }
    drives_.emplace(config.drives, *drives, config.sync.period_s);
    heartbeat_every_cycles_ = MasterHeartbeatCycles(config);
    if (config.path.enabled) {
      bool holonomic = false;
      for (const auto& n : config.drives.nodes) holonomic = holonomic || n.has_rollers;
      follower_.emplace(config.path, holonomic);
    }
  }
}

void FwApp::Start(std::int64_t t_ns, std::vector<bus::CanFrame>& out) {
  last_sync_host_ns_ = t_ns;  // Following SYNC: bus time 0, the silence counted from here.
  bus_ns_ = 0;
  master_.Start(MasterClockNs(t_ns));
  next_startup_status_ns_ = t_ns;
  state_ = FwState::kWaitingForNodes;
  Poll(t_ns, out);
}

void FwApp::HandleMasterPoll(CanopenMaster::PollResult r, std::int64_t t_ns,
                             std::vector<bus::CanFrame>& out) {
  for (const auto& f : r.frames) {
    if (r.sync_sent && !f.extended && f.id == bus::canopen::kSyncCobId) {
      // Close the previous cycle (its outputs go out first), then the SYNC of the next one.
      if (auto closed = assembler_.OnSync(t_ns)) OnCycle(*closed, out);
      out.push_back(f);
      ++stats_.frames_out;
      // With no synchronous inputs the SYNC itself completes the cycle.
      continue;
    }
    out.push_back(f);
    ++stats_.frames_out;
  }
}

void FwApp::OnFrameArrived(const bus::CanFrame& frame, std::int64_t arrival_ns,
                           std::vector<bus::CanFrame>& out) {
  const std::int64_t t = std::max(arrival_ns, last_t_ns_);
  Poll(t, out);
  OnFrame(frame, t, out);
}

std::int64_t ArrivalOnMonotonicNs(std::int64_t stamp_real_ns, std::int64_t now_real_ns,
                                  std::int64_t now_mono_ns, std::int64_t max_age_ns) {
  const std::int64_t age = now_real_ns - stamp_real_ns;
  return age >= 0 && age <= max_age_ns ? now_mono_ns - age : now_mono_ns;
}

std::int64_t FwApp::MasterClockNs(std::int64_t t_ns) const {
  if (!bus_clock_) return t_ns;
  // Bus time stands still between SYNCs; only a silence longer than sync_silence_ns_ lets it
  // run on with the host clock (from the end of that grace, so it never jumps).
  const std::int64_t over = t_ns - last_sync_host_ns_ - sync_silence_ns_;
  return over > 0 ? bus_ns_ + over : bus_ns_;
}

void FwApp::Poll(std::int64_t t_ns, std::vector<bus::CanFrame>& out) {
  last_t_ns_ = std::max(last_t_ns_, t_ns);
  if (bus_clock_ && !sync_silent_ && t_ns - last_sync_host_ns_ > sync_silence_ns_) {
    sync_silent_ = true;  // No SYNC for that long: the master's timers go on the host clock.
    ++stats_.sync_silences;
  }
  HandleMasterPoll(master_.Poll(MasterClockNs(t_ns)), t_ns, out);
  if (auto closed = assembler_.Poll(t_ns)) OnCycle(*closed, out);
  if (StartupStatusDue() && t_ns >= next_startup_status_ns_) {
    // Alive while waiting for the nodes: a receiver that sees no FW_Status for 3 cycles takes
    // the firmware for lost (wheelhil_fw.dbc). Cycle 0: no cycle has run yet.
    SendStatus(0, out);
    next_startup_status_ns_ = t_ns + period_ns_;
  }
  if (state_ == FwState::kWaitingForNodes && master_.started()) state_ = FwState::kRunning;
}

bool FwApp::StartupStatusDue() const {
  return config_.sync.produce && !master_.started() && stats_.cycles == 0;
}

std::int64_t FwApp::NextEventNs() const {
  std::int64_t master_next = master_.NextEventNs();
  if (bus_clock_ && master_next != std::numeric_limits<std::int64_t>::max()) {
    // The host instant MasterClockNs reaches it: due now when bus time is already there,
    // else only through the fallback (bus time does not move between SYNCs otherwise).
    const std::int64_t ahead = master_next - bus_ns_;
    const std::int64_t fallback_ns = last_sync_host_ns_ + sync_silence_ns_;
    if (ahead <= 0) {
      master_next = last_sync_host_ns_;
    } else if (ahead > std::numeric_limits<std::int64_t>::max() - fallback_ns) {
      master_next = std::numeric_limits<std::int64_t>::max();
    } else {
      master_next = fallback_ns + ahead;
    }
  }
  std::int64_t next = std::min(master_next, assembler_.NextDeadlineNs());
  if (StartupStatusDue()) next = std::min(next, next_startup_status_ns_);
  return next;
}

void FwApp::OnFrame(const bus::CanFrame& frame, std::int64_t t_ns,
                    std::vector<bus::CanFrame>& out) {
  last_t_ns_ = std::max(last_t_ns_, t_ns);
  ++stats_.frames_in;
  std::uint8_t node = 0;
  const FrameKind kind = protocol_.Classify(frame, node);
  auto bad = [&] {
    ++stats_.bad_frames;
    event_faults_ |= kFaultBadFrame;
  };
  auto ours = [&](std::uint8_t id) {
    for (const auto& n : nodes_) {
      if (n.node_id == id) return true;
    }
    for (const auto& n : config_.drives.nodes) {
      if (n.node_id == id) return true;
    }
    return false;
  };
  if (drives_) {
    bool undecodable = false;
    if (drives_->OnFrame(frame, undecodable)) {  // A drive's TPDO1 / TPDO2.
      if (undecodable) bad();
      return;
    }
  }
  switch (kind) {
    case FrameKind::kUnknown:
      ++stats_.unknown_frames;
      bad();
      return;
    case FrameKind::kErrorControl:
    case FrameKind::kSdoResponse:
    case FrameKind::kEmcy: {
      if (!ours(node)) {
        ++stats_.foreign_frames;
        return;
      }
      const std::uint64_t bad_before = master_.bad_frames();
      master_.OnFrame(frame, MasterClockNs(t_ns));
      if (master_.bad_frames() != bad_before) {
        bad();
        return;
      }
      if (kind == FrameKind::kEmcy) {
        std::uint16_t code = 0;
        std::uint8_t reg = 0;
        if (protocol_.DecodeEmcy(frame, code, reg) && code != 0) last_emcy_node_ = node;
      }
      // A node reset may have made it pre-operational: the master answers at once.
      HandleMasterPoll(master_.Poll(MasterClockNs(t_ns)), t_ns, out);
      return;
    }
    case FrameKind::kSync:
      if (config_.sync.produce) {
        ++stats_.foreign_frames;  // Another SYNC producer: not ours to follow.
        return;
      }
      if (frame.len > 1) {
        bad();
        return;
      }
      // Bus time moves on by one period (or to where the host-clock fallback took it); the
      // master's timeouts due by now are judged before the closing cycle reports them.
      bus_ns_ = std::max(bus_ns_ + period_ns_, MasterClockNs(t_ns));
      last_sync_host_ns_ = std::max(last_sync_host_ns_, t_ns);
      sync_silent_ = false;
      HandleMasterPoll(master_.Poll(bus_ns_), t_ns, out);
      if (auto closed = assembler_.OnSync(t_ns)) OnCycle(*closed, out);
      return;
    case FrameKind::kTpdo1: {
      if (!ours(node)) {
        ++stats_.foreign_frames;
        return;
      }
      std::uint32_t position = 0;
      std::int16_t speed = 0;
      if (!protocol_.DecodeTpdo1(frame, position, speed)) {
        bad();
        return;
      }
      const std::uint64_t dup = assembler_.duplicates() + assembler_.late_frames();
      auto closed = assembler_.OnTpdo(node, position, speed, t_ns);
      if (assembler_.duplicates() + assembler_.late_frames() != dup) {
        event_faults_ |= kFaultLateFrame;
      }
      if (closed) OnCycle(*closed, out);
      return;
    }
    case FrameKind::kImuYaw: {
      double rate = 0.0;
      if (!protocol_.DecodeYawRate(frame, rate)) {
        bad();
        return;
      }
      assembler_.OnYawRate(rate - config_.imu.gyro_bias_rad_s, t_ns);
      return;
    }
    case FrameKind::kAccel: {
      std::array<double, 4> a{};
      int counter = -1;
      if (!protocol_.DecodeAccel(frame, a, counter)) {
        bad();
        return;
      }
      if (counter >= 0 && last_accel_counter_ >= 0) {
        const int step = (counter - last_accel_counter_ + 16) % 16;
        if (step == 0) {
          ++stats_.accel_duplicates;
          event_faults_ |= kFaultLateFrame;
          return;
        }
        stats_.accel_gaps += static_cast<std::uint64_t>(step - 1);
      }
      last_accel_counter_ = counter;
      assembler_.OnAccel(a, t_ns);
      return;
    }
    case FrameKind::kImuOther:
    case FrameKind::kNmt:
    case FrameKind::kSdoRequest:
    case FrameKind::kOwnOutput:
      ++stats_.foreign_frames;
      return;
  }
}

void FwApp::Send(OutMessage m, const OutValues& v, std::vector<bus::CanFrame>& out) {
  if (!protocol_.HasOutput(m)) return;
  bus::CanFrame f;
  (void)protocol_.EncodeOutput(m, v, f);  // Saturated values are still sent (DBC contract).
  out.push_back(f);
  ++stats_.frames_out;
}

void FwApp::OnCycle(const AssembledCycle& c, std::vector<bus::CanFrame>& out) {
  ++stats_.cycles;
  // Asynchronous inputs of this interval; hold the last value when a source was silent.
  if (c.yaw_samples > 0) {
    last_yaw_rate_rad_s_ = c.yaw_rate_sum_rad_s / c.yaw_samples;
    imu_silent_cycles_ = 0;
  } else if (config_.imu.enabled) {
    ++imu_silent_cycles_;
    if (c.index > 0) event_faults_ |= kFaultCycleIncomplete;
  }
  if (c.accel_samples > 0) {
    for (std::size_t i = 0; i < 4; ++i) last_accel_m_s2_[i] = c.accel_sum_m_s2[i] / c.accel_samples;
    accel_silent_cycles_ = 0;
  } else if (config_.accel.enabled) {
    ++accel_silent_cycles_;
    if (c.index > 0) event_faults_ |= kFaultCycleIncomplete;
  }
  const double period_s = config_.sync.period_s;
  carry_dth_gyro_rad_ += last_yaw_rate_rad_s_ * period_s;

  if (!c.complete()) {
    ++stats_.skipped_steps;
    event_faults_ |= kFaultCycleIncomplete;
    // Paper 002 keeps its 1-period rhythm through the gap on the accelerometers alone.
    if (p002_ && have_step_cycle_) Step002Unobserved();
  } else if (!have_step_cycle_) {
    // The first complete cycle primes the counters: the estimators start here, at rest.
    for (std::size_t i = 0; i < nodes_.size(); ++i) last_position_[i] = c.encoders[i].position;
    have_step_cycle_ = true;
    last_step_cycle_ = c.index;
    carry_dth_gyro_rad_ = 0.0;
  } else {
    const double dt_s = static_cast<double>(c.index - last_step_cycle_) * period_s;
    last_step_cycle_ = c.index;
    if (p000_) Step000(c, dt_s, out);
    if (p001_) Step001(c, dt_s, out);
    if (p002_) Step002(c, dt_s, out);
    carry_dth_gyro_rad_ = 0.0;
    ++stats_.steps;
  }

  if (drives_) CommandDrives(c.index, out);

  // Estimate frames (held values when no step happened), then the status frame.
  OutValues v;
  v.Set(OutField::kCycle, static_cast<double>(c.index));
  if (p000_) {
    const SlipStepResult& r = p000_->last();
    OutValues pose = v, raw = v, slip = v;
    pose.Set(OutField::kX, p000_->pose_corrected().x_m);
    pose.Set(OutField::kY, p000_->pose_corrected().y_m);
    pose.Set(OutField::kTheta, WrapPi(p000_->pose_corrected().theta_rad));
    raw.Set(OutField::kX, p000_->pose_encoder().x_m);
    raw.Set(OutField::kY, p000_->pose_encoder().y_m);
    raw.Set(OutField::kTheta, WrapPi(p000_->pose_encoder().theta_rad));
    slip.Set(OutField::kSlipLeft, r.slip_left ? 1 : 0);
    slip.Set(OutField::kSlipRight, r.slip_right ? 1 : 0);
    slip.Set(OutField::kSlipUnattributed, r.slip_unattributed ? 1 : 0);
    slip.Set(OutField::kOutOfBand, r.out_of_band ? 1 : 0);
    // "Calibrated": the band is known and, when it came from a calibration window, that window
    // passed the normality test (configured statistics count as accepted).
    const auto& normality = p000_->calibration_normality();
    const bool accepted = !normality || normality->accepted;
    slip.Set(OutField::kCalibrated, p000_->calibrated() && accepted ? 1 : 0);
    slip.Set(OutField::kResidual, r.residual_rad);
    slip.Set(OutField::kBandLow, r.band_low_rad);
    slip.Set(OutField::kBandHigh, r.band_high_rad);
    Send(OutMessage::kPose, pose, out);
    Send(OutMessage::kPoseRaw, raw, out);
    Send(OutMessage::kSlipStatus, slip, out);
    OutValues vel = v;
    vel.Set(OutField::kVx, vel_[0]);
    vel.Set(OutField::kVy, vel_[1]);
    vel.Set(OutField::kOmega, vel_[2]);
    Send(OutMessage::kVelocity, vel, out);
  }
  if (p001_) {
    const Pose2 X = PaperToForwardPose(p001_->pose());
    OutValues pose = v, vel = v;
    pose.Set(OutField::kX, X.x_m);
    pose.Set(OutField::kY, X.y_m);
    pose.Set(OutField::kTheta, WrapPi(X.theta_rad));
    vel.Set(OutField::kVx, vel_[0]);
    vel.Set(OutField::kVy, vel_[1]);
    vel.Set(OutField::kOmega, vel_[2]);
    Send(OutMessage::kPose, pose, out);
    Send(OutMessage::kVelocity, vel, out);
  }
  if (p002_) {
    const FusionOutput& f = p002_->last();
    OutValues pose = v;
    pose.Set(OutField::kX, p002_pose_.x_m);
    pose.Set(OutField::kY, p002_pose_.y_m);
    pose.Set(OutField::kTheta, WrapPi(p002_pose_.theta_rad));
    Send(OutMessage::kPose, pose, out);
    const std::array<OutField, 3> fields = {OutField::kVx, OutField::kVy, OutField::kOmega};
    OutValues fused = v, odom = v, acc = v;
    for (std::size_t i = 0; i < 3; ++i) {
      fused.Set(fields[i], f.axes[i].fused);
      odom.Set(fields[i], f.axes[i].odometry);
      acc.Set(fields[i], f.axes[i].accel_integrated);
    }
    Send(OutMessage::kVelocity, fused, out);
    Send(OutMessage::kVelocityOdom, odom, out);
    Send(OutMessage::kVelocityAccel, acc, out);
  }

  SendStatus(c.index, out);
}

bool FwApp::EstimateReady() const { return have_step_cycle_ && (!p000_ || p000_->calibrated()); }

Pose2 FwApp::SteeringPose() const {
  if (p000_) {
    return config_.path.steer_from == SteerFrom::kRaw ? p000_->pose_encoder()
                                                      : p000_->pose_corrected();
  }
  if (p001_) return PaperToForwardPose(p001_->pose());
  return p002_pose_;
}

void FwApp::CommandDrives(std::uint64_t cycle, std::vector<bus::CanFrame>& out) {
  // Supervision first: a drive or encoder that is gone stops the robot before it is commanded.
  const auto& master_nodes = master_.nodes();
  const std::size_t first_drive = nodes_.size();  // MasterConfigFrom: encoders, then drives
  std::vector<bool> operational(config_.drives.nodes.size(), false);
  for (std::size_t j = 0; j < master_nodes.size(); ++j) {
    const CanopenMaster::NodeStatus& n = master_nodes[j];
    if (n.lost || n.state == CanopenMaster::NodeState::kMissing) {
      drives_->Stop(DriveStopReason::kNodeLost, n.node_id);
    }
    if (j >= first_drive) {
      if (n.emcy_active) drives_->Stop(DriveStopReason::kEmcy, n.node_id);
      operational[j - first_drive] = n.state == CanopenMaster::NodeState::kOperational && !n.lost;
    }
  }
  BodyVelocity v;
  if (drives_->all_enabled() && EstimateReady()) {
    const double period_s = config_.sync.period_s;
    if (follower_ &&
        static_cast<double>(enabled_cycles_) * period_s >= config_.path.start_delay_s) {
      v = follower_->Step(SteeringPose(), period_s);
    }
    ++enabled_cycles_;
  }
  std::vector<double> wheel(config_.drives.nodes.size(), 0.0);
  WheelSpeedsFor(config_.drives, v, wheel.data());
  const std::size_t before = out.size();
  drives_->Cycle(wheel, operational, out);
  if (heartbeat_every_cycles_ > 0 && cycle % heartbeat_every_cycles_ == 0) {
    bus::CanFrame hb;
    if (protocol_.EncodeHeartbeat(static_cast<std::uint8_t>(config_.drives.master_node_id),
                                  bus::canopen::nmt_state::kOperational, hb)) {
      out.push_back(hb);
    }
  }
  stats_.frames_out += out.size() - before;
}

void FwApp::SendStatus(std::uint64_t cycle, std::vector<bus::CanFrame>& out) {
  OutValues v;
  v.Set(OutField::kCycle, static_cast<double>(cycle));
  const bool imu_lost = config_.imu.enabled && imu_silent_cycles_ >= kLostAfterCycles;
  const bool accel_lost = config_.accel.enabled && accel_silent_cycles_ >= kLostAfterCycles;
  std::uint32_t faults = master_.faults() | event_faults_;
  faults &= ~static_cast<std::uint32_t>(kFaultBadFrame);  // Per cycle: only this cycle's.
  faults |= event_faults_ & kFaultBadFrame;
  faults |= Bit(imu_lost || accel_lost, kFaultNodeLost);
  const std::uint32_t lost_mask = master_.nodes_lost_mask();
  OutValues st = v;
  st.Set(OutField::kHeartbeat, static_cast<double>(heartbeat_++ & 0xFFFFFFFFu));
  if (drives_ && drives_->stopped()) {
    state_ = FwState::kFault;  // Safe stop: latched until the firmware restarts.
  } else if (!master_.started()) {
    state_ = FwState::kWaitingForNodes;
  } else if (p000_ && !p000_->calibrated()) {
    state_ = FwState::kCalibrating;
  } else if ((faults & ~static_cast<std::uint32_t>(kFaultBadFrame)) != 0) {
    state_ = FwState::kDegraded;
  } else {
    state_ = FwState::kRunning;
  }
  st.Set(OutField::kState, static_cast<double>(state_));
  st.Set(OutField::kFaults, faults);
  st.Set(OutField::kFaultBootTimeout, (faults & kFaultBootTimeout) ? 1 : 0);
  st.Set(OutField::kFaultNodeLost, (faults & kFaultNodeLost) ? 1 : 0);
  st.Set(OutField::kFaultEmcy, (faults & kFaultEmcy) ? 1 : 0);
  st.Set(OutField::kFaultSdo, (faults & kFaultSdo) ? 1 : 0);
  st.Set(OutField::kFaultBadFrame, (faults & kFaultBadFrame) ? 1 : 0);
  st.Set(OutField::kFaultCycleIncomplete, (faults & kFaultCycleIncomplete) ? 1 : 0);
  st.Set(OutField::kFaultLateFrame, (faults & kFaultLateFrame) ? 1 : 0);
  st.Set(OutField::kFaultEstimator, (faults & kFaultEstimator) ? 1 : 0);
  // The DBC's "config" bit: the nodes do not match the configuration (SDO failed, no boot-up).
  st.Set(OutField::kFaultConfig, (faults & (kFaultSdo | kFaultBootTimeout | kFaultConfig)) ? 1 : 0);
  st.Set(OutField::kNodesLost, lost_mask);
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    const OutField f = NodeLostField(nodes_[i].node_id);
    if (f != OutField::kNone) st.Set(f, (lost_mask >> i) & 1u);
  }
  st.Set(OutField::kNodeLostImu, imu_lost ? 1 : 0);
  st.Set(OutField::kNodeLostAccel, accel_lost ? 1 : 0);
  st.Set(OutField::kEmcyNodeId, last_emcy_node_);
  st.Set(OutField::kBadFrameCount, static_cast<double>(stats_.bad_frames));
  Send(OutMessage::kStatus, st, out);
  last_faults_ = faults;
  event_faults_ = 0;
}

void FwApp::Step000(const AssembledCycle& c, double dt_s, std::vector<bus::CanFrame>& /*out*/) {
  const Paper000Settings& p = config_.paper000;
  std::array<double, 2> d{};
  for (std::size_t i = 0; i < 2; ++i) {
    const std::int64_t counts =
        CounterDelta(last_position_[i], c.encoders[i].position, p.counter_bits) * nodes_[i].sign;
    last_position_[i] = c.encoders[i].position;
    d[i] = CountsToMeters(counts, p.counts_per_rev, p.wheel_radius_m);
  }
  if (!p000_->Step(d[0], d[1], carry_dth_gyro_rad_)) {
    event_faults_ |= kFaultEstimator;
    return;
  }
  const SlipStepResult& r = p000_->last();
  vel_ = {r.ds_m / dt_s, 0.0, r.dtheta_rad / dt_s};
}

void FwApp::Step001(const AssembledCycle& c, double dt_s, std::vector<bus::CanFrame>& /*out*/) {
  const Paper001Settings& p = config_.paper001;
  std::array<std::int64_t, 3> d{};
  for (std::size_t i = 0; i < 3; ++i) {
    d[i] = CounterDelta(last_position_[i], c.encoders[i].position, p.counter_bits) * nodes_[i].sign;
    last_position_[i] = c.encoders[i].position;
  }
  p001_->StepDeltaCounts(d);
  const FollowerTwist v = PaperToForwardTwist(p001_->last_body_displacement());
  vel_ = {v.vx_m_s / dt_s, v.vy_m_s / dt_s, v.omega_rad_s / dt_s};
}

void FwApp::Step002(const AssembledCycle& c, double /*dt_s*/, std::vector<bus::CanFrame>& /*out*/) {
  const Paper002Settings& p = config_.paper002;
  std::array<double, 3> rim{};
  for (std::size_t i = 0; i < 3; ++i) {
    const std::int64_t counts =
        CounterDelta(last_position_[i], c.encoders[i].position, p.counter_bits) * nodes_[i].sign;
    last_position_[i] = c.encoders[i].position;
    rim[i] = CountsToMeters(counts, p.counts_per_rev, p.wheel_radius_m);
  }
  const FollowerTwist d = BodyTwistFromRimSpeeds(p002_geometry_, rim);
  p002_odometry_[0] += d.vx_m_s;
  p002_odometry_[1] += d.vy_m_s;
  p002_odometry_[2] += d.omega_rad_s;
  p002_pose_ = AdvancePose(p002_pose_, d.vx_m_s, d.vy_m_s, d.omega_rad_s, HeadingRule::kMidpoint);
  if (!p002_->StepRaw(p002_odometry_, last_accel_m_s2_, {0.0, 0.0, 0.0})) {
    event_faults_ |= kFaultEstimator;
  }
}

void FwApp::Step002Unobserved() {
  // An encoder is missing: the kinematics needs all three wheels, so no axis is observed. The
  // counts of the gap arrive with the next complete cycle (absolute counters) and move the
  // odometry position then; VelocityFusion takes that catch-up into its observers' position.
  if (!p002_->StepRawUnobserved(last_accel_m_s2_, {0.0, 0.0, 0.0})) {
    event_faults_ |= kFaultEstimator;
  }
}

}  // namespace wheelhil::fw
