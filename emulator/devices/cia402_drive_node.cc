#include "emulator/devices/cia402_drive_node.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>

#include <fmt/format.h>

#include "bus/canopen.h"
#include "bus/cia402.h"

namespace wheelhil::emulator {
namespace {

namespace canopen = bus::canopen;
namespace sdo = bus::canopen::sdo;

constexpr std::int64_t kNever = std::numeric_limits<std::int64_t>::max();
constexpr std::int64_t kNsPerMs = 1'000'000;

// CiA 402 definitions (bus/cia402.h).
using namespace bus::cia402::od;
using bus::cia402::StatuswordPattern;
using bus::cia402::mode::kCyclicSyncVelocity;
using bus::cia402::mode::kProfileVelocity;
namespace sw_bits = bus::cia402::statusword;
// CiA 301 objects beyond bus/canopen.h's.
constexpr std::uint16_t kConsumerHeartbeat = canopen::od::kConsumerHeartbeatTime;
constexpr std::uint16_t kRpdoCommunication = 0x1400;
constexpr std::uint16_t kRpdoMapping = 0x1600;
constexpr std::uint16_t kTpdoCommunication = 0x1800;
constexpr std::uint16_t kTpdoMapping = 0x1A00;

// EMCY error codes (bus/cia402.h) and error register bits (CiA 301).
using bus::cia402::emcy::kHeartbeat;
using bus::cia402::emcy::kOverCurrent;
using bus::cia402::emcy::kRpdoTimeout;
constexpr std::uint8_t kRegGeneric = 0x01, kRegCurrent = 0x02, kRegCommunication = 0x10;

bool ValidTransmissionType(std::uint32_t t) { return t <= 240 || t == 254 || t == 255; }

std::uint32_t SignExtendMask(std::int64_t v, std::uint8_t bits) {
  const std::uint64_t mask = bits >= 32 ? 0xFFFFFFFFull : ((1ull << bits) - 1);
  return static_cast<std::uint32_t>(static_cast<std::uint64_t>(v) & mask);
}

std::int64_t SignedOf(std::uint32_t raw, std::uint8_t bits) {
  if (bits >= 32) return static_cast<std::int32_t>(raw);
  const std::uint32_t sign = 1u << (bits - 1);
  return static_cast<std::int64_t>((raw ^ sign)) - static_cast<std::int64_t>(sign);
}

bus::CanFrame Frame(std::uint32_t id, std::initializer_list<std::uint8_t> bytes) {
  bus::CanFrame f;
  f.id = id;
  f.len = static_cast<std::uint8_t>(bytes.size());
  std::copy(bytes.begin(), bytes.end(), f.data.begin());
  return f;
}

bus::CanFrame SdoFrame(std::uint8_t node, std::uint8_t command, std::uint16_t index,
                       std::uint8_t sub, std::uint32_t data) {
  return Frame(canopen::CobId(canopen::Function::kSdoResponse, node),
               {command, static_cast<std::uint8_t>(index), static_cast<std::uint8_t>(index >> 8),
                sub, static_cast<std::uint8_t>(data), static_cast<std::uint8_t>(data >> 8),
                static_cast<std::uint8_t>(data >> 16), static_cast<std::uint8_t>(data >> 24)});
}

}  // namespace

Cia402DriveNode::Cia402DriveNode(const Cia402DriveConfig& config, double motor_torque_limit_nm,
                                 std::int64_t power_on_ns)
    : config_(config), motor_limit_nm_(motor_torque_limit_nm), now_ns_(power_on_ns) {
  const auto bad = [&](const std::string& what) {
    throw std::invalid_argument(fmt::format("canopen_cia402 node {}: {}", config.node_id, what));
  };
  if (!canopen::IsValidNodeId(config.node_id)) bad("node_id must be in 1..127");
  if (config.power_on_delay_ns < 0 || config.reset_delay_ns < 0 || config.response_delay_ns < 0) {
    bad("power_on/reset/response delays must be >= 0");
  }
  if (!(config.gear_ratio > 0) || !std::isfinite(config.gear_ratio)) bad("gear_ratio must be > 0");
  if (config.counts_per_rev == 0) bad("counts_per_rev must be > 0");
  if (config.rated_torque_mnm == 0 || config.rated_current_ma == 0) {
    bad("rated torque and rated current must be > 0");
  }
  if (!(motor_torque_limit_nm > 0)) bad("the wheel's motor has no torque");
  if (config.trip_current_a < 0 || !(config.trip_time_s >= 0)) {
    bad("trip_current_a and trip_time_s must be >= 0");
  }
  ResetApplication();
  ResetCommunication();
  for (int i = 0; i < 4; ++i) {
    const bool rpdo = i < 2;
    const auto& d = rpdo ? config.rpdo[i] : config.tpdo[i - 2];
    const std::string which = fmt::format("{}PDO{}", rpdo ? 'R' : 'T', i % 2 + 1);
    if (!ValidTransmissionType(d.type)) {
      bad(which + " transmission type must be 0..240, 254 or 255");
    }
    if (d.cob_id > 0x7FF) bad(which + " COB-ID must be an 11-bit identifier");
    const Pdo& p = rpdo ? rpdo_[i] : tpdo_[i - 2];
    if (d.map.size() > 8 ||
        ValidateMapping(p, rpdo, static_cast<std::uint8_t>(d.map.size())) != 0) {
      bad(which +
          " mapping: every entry must be a mappable object of the drive"
          " (receive: writable) with its own size, 64 bits in all");
    }
  }
  ScheduleBoot(power_on_ns + config.power_on_delay_ns);
  last_ramp_ns_ = power_on_ns;
}

const char* Cia402DriveNode::StateName(State s) { return bus::cia402::StateName(s); }

void Cia402DriveNode::ResetApplication() {
  state_ = State::kNotReadyToSwitchOn;
  controlword_ = 0;
  mode_request_ = mode_ = config_.default_mode;
  target_velocity_ = 0;
  abort_option_ = config_.abort_connection_option;
  quick_stop_option_ = config_.quick_stop_option;
  fault_reaction_option_ = config_.fault_reaction_option;
  polarity_ = config_.polarity;
  profile_accel_ = config_.profile_acceleration;
  profile_decel_ = config_.profile_deceleration;
  quick_stop_decel_ = config_.quick_stop_deceleration;
  max_motor_speed_ = config_.max_motor_speed;
  max_torque_permille_ = 1000;
  velocity_window_ = config_.velocity_window;
  velocity_threshold_ = config_.velocity_threshold;
  error_code_ = 0;
  error_register_ = 0;
  demand_ = 0;
  over_current_s_ = 0;
  ResetExtraObjects(false);
}

void Cia402DriveNode::ResetExtraObjects(bool communication) {
  if (extra_.size() != config_.extra_objects.size()) extra_ = config_.extra_objects;
  for (std::size_t i = 0; i < extra_.size(); ++i) {
    if ((extra_[i].index < 0x2000) == communication)
      extra_[i].value = config_.extra_objects[i].value;
  }
}

void Cia402DriveNode::ResetCommunication() {
  ResetExtraObjects(true);
  heartbeat_ms_ = config_.heartbeat_ms;
  consumer_heartbeat_ = config_.consumer_heartbeat;
  const std::uint8_t id = config_.node_id;
  const auto init = [](Pdo& p, const Cia402DriveConfig::PdoDefaults& d, std::uint32_t cob) {
    p = Pdo{};
    p.cob_id = (d.cob_id != 0 ? d.cob_id : cob) | (d.valid ? 0u : canopen::kPdoCobIdInvalid);
    p.type = d.type;
    p.event_ms = d.event_ms;
    p.count = static_cast<std::uint8_t>(d.map.size());
    std::copy(d.map.begin(), d.map.end(), p.map);
  };
  init(rpdo_[0], config_.rpdo[0], canopen::CobId(canopen::Function::kRpdo1, id));
  init(rpdo_[1], config_.rpdo[1], canopen::CobId(canopen::Function::kRpdo2, id));
  init(tpdo_[0], config_.tpdo[0], canopen::CobId(canopen::Function::kTpdo1, id));
  init(tpdo_[1], config_.tpdo[1], canopen::CobId(canopen::Function::kTpdo2, id));
}

void Cia402DriveNode::ScheduleBoot(std::int64_t t_ns) {
  nmt_ = NmtState::kOff;
  boot_due_ns_ = t_ns;
  next_heartbeat_ns_ = kNever;
  consumer_deadline_ns_ = kNever;
  for (Pdo& p : tpdo_) p.next_ns = kNever;
  for (Pdo& p : rpdo_) p.next_ns = kNever;
}

void Cia402DriveNode::EnterOperational(std::int64_t t_ns) {
  nmt_ = NmtState::kOperational;
  for (Pdo& p : tpdo_) {
    p.sync_count = 0;
    p.next_ns = p.type >= 254 && p.event_ms > 0 ? t_ns + p.event_ms * kNsPerMs : kNever;
  }
  for (Pdo& p : rpdo_) {
    p.pending = false;
    p.next_ns = kNever;  // the deadline runs from the first RPDO
  }
}

void Cia402DriveNode::LeaveOperational(std::int64_t t_ns) {
  for (Pdo& p : tpdo_) p.next_ns = kNever;
  for (Pdo& p : rpdo_) p.next_ns = kNever;
  // The master took the node out of operational while it drove: the connection is lost.
  if (state_ == State::kOperationEnabled) AbortConnection(kHeartbeat, t_ns);
}

void Cia402DriveNode::SetMeasurement(double angle_rad, double omega_rad_s, double torque_nm,
                                     double current_a) noexcept {
  angle_rad_ = angle_rad;
  omega_rad_s_ = omega_rad_s;
  torque_nm_ = torque_nm;
  current_a_ = current_a;
}

double Cia402DriveNode::UnitToWheelRadS() const {
  const double motor = config_.velocity_rpm ? 2 * std::numbers::pi / 60.0
                                            : 2 * std::numbers::pi / config_.counts_per_rev;
  return motor / config_.gear_ratio;
}

std::int32_t Cia402DriveNode::VelocityActual() const {
  double v = omega_rad_s_ / UnitToWheelRadS();
  if (polarity_ & 0x40) v = -v;
  if (!std::isfinite(v)) return 0;
  return static_cast<std::int32_t>(std::clamp(std::round(v), -2147483648.0, 2147483647.0));
}

std::int32_t Cia402DriveNode::PositionActual() const {
  double counts = angle_rad_ * config_.gear_ratio * config_.counts_per_rev / (2 * std::numbers::pi);
  if (polarity_ & 0x80) counts = -counts;
  if (!std::isfinite(counts)) return 0;
  // The position counter wraps as a 32-bit register does.
  const auto c = static_cast<std::int64_t>(std::floor(counts));
  return static_cast<std::int32_t>(static_cast<std::uint32_t>(static_cast<std::uint64_t>(c)));
}

std::int16_t Cia402DriveNode::TorqueActual() const {
  double permille = 1e6 * torque_nm_ / (config_.gear_ratio * config_.rated_torque_mnm);
  if (polarity_ & 0x40) permille = -permille;
  if (!std::isfinite(permille)) return 0;
  return static_cast<std::int16_t>(std::clamp(std::round(permille), -32768.0, 32767.0));
}

std::int16_t Cia402DriveNode::CurrentActual() const {
  double permille = 1e6 * current_a_ / config_.rated_current_ma;
  if (polarity_ & 0x40) permille = -permille;
  if (!std::isfinite(permille)) return 0;
  return static_cast<std::int16_t>(std::clamp(std::round(permille), -32768.0, 32767.0));
}

std::uint16_t Cia402DriveNode::statusword() const {
  std::uint16_t sw = StatuswordPattern(state_);
  sw |= sw_bits::kRemote;  // remote: controlled over the bus
  const double actual = VelocityActual();
  if (state_ == State::kOperationEnabled) {
    const double target = mode_ == kProfileVelocity || mode_ == kCyclicSyncVelocity
                              ? static_cast<double>(target_velocity_)
                              : 0.0;
    if (std::abs(actual - target) <= velocity_window_) sw |= sw_bits::kTargetReached;
    if (mode_ == kProfileVelocity && std::abs(actual) <= velocity_threshold_)
      sw |= sw_bits::kModeSpecific12;
    if (mode_ == kCyclicSyncVelocity) sw |= sw_bits::kModeSpecific12;
  } else if (state_ == State::kQuickStopActive && demand_ == 0 &&
             std::abs(actual) <= velocity_window_) {
    sw |= sw_bits::kTargetReached;
  }
  const WheelDriveCommand cmd = WheelCommand();
  if (cmd.torque_limit_nm > 0 && std::abs(torque_nm_) >= 0.98 * cmd.torque_limit_nm)
    sw |= sw_bits::kInternalLimit;
  return sw;
}

WheelDriveCommand Cia402DriveNode::WheelCommand() const {
  WheelDriveCommand c;
  const bool torque_on = (state_ == State::kOperationEnabled || state_ == State::kQuickStopActive ||
                          state_ == State::kFaultReactionActive);
  if (!torque_on) return c;
  double v = demand_ * UnitToWheelRadS();
  if (polarity_ & 0x40) v = -v;
  c.omega_rad_s = v;
  const double by_object =
      max_torque_permille_ * 1e-6 * config_.rated_torque_mnm * config_.gear_ratio;
  c.torque_limit_nm = std::min({motor_limit_nm_, by_object, fault_torque_limit_nm_});
  c.torque_limit_nm = std::max(0.0, c.torque_limit_nm);
  return c;
}

void Cia402DriveNode::Emit(const bus::CanFrame& f, std::int64_t due_ns,
                           std::vector<NodeFrame>& out) {
  out.push_back(NodeFrame{f, due_ns});
}

void Cia402DriveNode::EmitEmcy(std::uint16_t code, std::int64_t due_ns) {
  if (nmt_ == NmtState::kOff || nmt_ == NmtState::kStopped) return;
  pending_.push_back(
      NodeFrame{Frame(canopen::CobId(canopen::Function::kEmcy, config_.node_id),
                      {static_cast<std::uint8_t>(code), static_cast<std::uint8_t>(code >> 8),
                       error_register_, 0, 0, 0, 0, 0}),
                due_ns});
}

void Cia402DriveNode::EnterFault(std::uint16_t code, std::uint8_t error_register, bool coast,
                                 std::int64_t t_ns) {
  if (state_ == State::kFault || state_ == State::kFaultReactionActive) return;
  error_code_ = code;
  error_register_ = static_cast<std::uint8_t>(error_register | kRegGeneric);
  EmitEmcy(code, t_ns);
  const bool torque_on = state_ == State::kOperationEnabled || state_ == State::kQuickStopActive;
  // Fault reaction (0x605E): 0 disables the drive function at once; 1/2 ramp down first.
  reaction_profile_ramp_ = fault_reaction_option_ == 1;
  if (coast || !torque_on || fault_reaction_option_ <= 0) {
    demand_ = 0;
    state_ = State::kFault;
  } else {
    state_ = State::kFaultReactionActive;
  }
}

void Cia402DriveNode::TripOverCurrent(std::int64_t t_ns, bool persists) {
  overcurrent_cause_ = persists;
  EnterFault(kOverCurrent, kRegCurrent, true, t_ns);
}

void Cia402DriveNode::RaiseFault(std::uint16_t error_code, std::int64_t t_ns) {
  EnterFault(error_code, 0x80, false, t_ns);
}

void Cia402DriveNode::AbortConnection(std::uint16_t code, std::int64_t t_ns) {
  if (state_ != State::kOperationEnabled) return;
  switch (abort_option_) {
    case 1:
      EnterFault(code, kRegCommunication, false, t_ns);
      break;
    case 2:
      state_ = State::kSwitchOnDisabled;  // disable voltage: the wheel coasts
      demand_ = 0;
      break;
    case 3:
      Controlword(static_cast<std::uint16_t>((controlword_ & ~0x0004u) | 0x0002u), t_ns);
      break;
    default:
      break;  // 0: no action
  }
}

void Cia402DriveNode::Controlword(std::uint16_t cw, std::int64_t t_ns) {
  const bool reset_edge = (cw & 0x80) && !(controlword_ & 0x80);
  controlword_ = cw;
  if (state_ == State::kFault) {
    if (reset_edge && !overcurrent_cause_) {
      state_ = State::kSwitchOnDisabled;  // 15
      error_code_ = 0;
      error_register_ = 0;
      over_current_s_ = 0;
      EmitEmcy(canopen::kEmcyErrorReset, t_ns);
    }
    return;
  }
  if (state_ == State::kFaultReactionActive || state_ == State::kNotReadyToSwitchOn) return;
  if (cw & 0x80) return;  // fault reset outside Fault: no state command
  const bool disable_voltage = (cw & 0x02) == 0;
  const bool quick_stop = (cw & 0x06) == 0x02;
  const bool shutdown = (cw & 0x07) == 0x06;
  const bool switch_on = (cw & 0x0F) == 0x07;
  const bool enable = (cw & 0x0F) == 0x0F;
  switch (state_) {
    case State::kSwitchOnDisabled:
      if (shutdown) state_ = State::kReadyToSwitchOn;  // 2
      break;
    case State::kReadyToSwitchOn:
      if (switch_on) state_ = State::kSwitchedOn;                            // 3
      if (enable) state_ = State::kOperationEnabled;                         // 3 + 4
      if (disable_voltage || quick_stop) state_ = State::kSwitchOnDisabled;  // 7
      break;
    case State::kSwitchedOn:
      if (enable) state_ = State::kOperationEnabled;                         // 4
      if (shutdown) state_ = State::kReadyToSwitchOn;                        // 6
      if (disable_voltage || quick_stop) state_ = State::kSwitchOnDisabled;  // 10
      break;
    case State::kOperationEnabled:
      if (switch_on) state_ = State::kSwitchedOn;              // 5
      if (shutdown) state_ = State::kReadyToSwitchOn;          // 8
      if (disable_voltage) state_ = State::kSwitchOnDisabled;  // 9
      if (quick_stop) {                                        // 11
        reaction_profile_ramp_ = quick_stop_option_ == 1 || quick_stop_option_ == 5;
        stay_in_quick_stop_ = quick_stop_option_ == 5 || quick_stop_option_ == 6;
        // Option 0 disables the drive function at once: the wheel coasts.
        state_ = quick_stop_option_ <= 0 ? State::kSwitchOnDisabled : State::kQuickStopActive;
      }
      break;
    case State::kQuickStopActive:
      if (disable_voltage) state_ = State::kSwitchOnDisabled;                // 12
      if (enable && stay_in_quick_stop_) state_ = State::kOperationEnabled;  // 16
      break;
    default:
      break;
  }
  if (state_ != State::kOperationEnabled && state_ != State::kQuickStopActive) demand_ = 0;
}

void Cia402DriveNode::StepRamp(std::int64_t t_ns) {
  // Called again at the same instant after a frame changed the target or the state: dt = 0.
  const double dt = std::max<double>(0.0, static_cast<double>(t_ns - last_ramp_ns_) * 1e-9);
  last_ramp_ns_ = std::max(last_ramp_ns_, t_ns);
  const auto toward = [&](double goal, double rate) {
    if (rate <= 0) {
      demand_ = goal;
      return;
    }
    const double step = rate * dt;
    demand_ = demand_ < goal ? std::min(goal, demand_ + step) : std::max(goal, demand_ - step);
  };
  switch (state_) {
    case State::kOperationEnabled: {
      if (stuck_ || (dt == 0 && mode_ != kCyclicSyncVelocity)) break;
      double target = 0;
      if (mode_ == kProfileVelocity || mode_ == kCyclicSyncVelocity) {
        target = target_velocity_;
      }
      if (max_motor_speed_ > 0) {
        target = std::clamp(target, -static_cast<double>(max_motor_speed_),
                            static_cast<double>(max_motor_speed_));
      }
      if (mode_ == kCyclicSyncVelocity) {
        demand_ = target;
      } else {
        // Away from zero: acceleration; toward zero (or through it): deceleration.
        const bool accelerating = std::abs(target) > std::abs(demand_) && target * demand_ >= 0;
        toward(target, accelerating ? profile_accel_ : profile_decel_);
      }
      break;
    }
    case State::kQuickStopActive:
    case State::kFaultReactionActive:
      toward(0.0, reaction_profile_ramp_ ? profile_decel_ : quick_stop_decel_);
      if (demand_ == 0) {
        if (state_ == State::kFaultReactionActive) {
          state_ = State::kFault;  // 14
        } else if (!stay_in_quick_stop_) {
          state_ = State::kSwitchOnDisabled;  // 12
        }
      }
      break;
    default:
      demand_ = 0;
      break;
  }
  // Over-current protection: the trip level held for the trip time.
  const bool torque_on = WheelCommand().torque_limit_nm > 0;
  if (config_.trip_current_a > 0 && torque_on && std::abs(current_a_) > config_.trip_current_a) {
    over_current_s_ += dt;
    if (over_current_s_ >= config_.trip_time_s) EnterFault(kOverCurrent, kRegCurrent, true, t_ns);
  } else {
    over_current_s_ = 0;
  }
}

std::vector<NodeFrame> Cia402DriveNode::Poll(std::int64_t t_ns) {
  std::vector<NodeFrame> out;
  if (t_ns < now_ns_) t_ns = now_ns_;
  now_ns_ = t_ns;
  if (nmt_ == NmtState::kOff && boot_due_ns_ <= t_ns) {
    nmt_ = NmtState::kPreOperational;
    state_ = State::kSwitchOnDisabled;  // 0, 1: initialisation done
    Emit(Frame(canopen::CobId(canopen::Function::kErrorControl, config_.node_id),
               {canopen::nmt_state::kBootUp}),
         boot_due_ns_, out);
    boot_due_ns_ = kNever;
    next_heartbeat_ns_ = heartbeat_ms_ > 0 ? t_ns + heartbeat_ms_ * kNsPerMs : kNever;
  }
  if (nmt_ != NmtState::kOff) {
    if (consumer_deadline_ns_ <= t_ns) {
      consumer_deadline_ns_ = kNever;  // supervision resumes with the next heartbeat
      AbortConnection(kHeartbeat, t_ns);
    }
    for (Pdo& p : rpdo_) {
      if (p.next_ns <= t_ns) {
        p.next_ns = kNever;
        AbortConnection(kRpdoTimeout, t_ns);
      }
    }
  }
  StepRamp(t_ns);
  for (NodeFrame& f : pending_) out.push_back(f);
  pending_.clear();
  while (next_heartbeat_ns_ <= t_ns) {
    Emit(Frame(canopen::CobId(canopen::Function::kErrorControl, config_.node_id),
               {static_cast<std::uint8_t>(nmt_)}),
         next_heartbeat_ns_, out);
    next_heartbeat_ns_ += heartbeat_ms_ * kNsPerMs;
  }
  if (nmt_ == NmtState::kOperational) {
    for (Pdo& p : tpdo_) {
      while (p.next_ns <= t_ns) {
        EmitTpdo(p, p.next_ns, out);
        p.next_ns += p.event_ms * kNsPerMs;
      }
    }
  }
  std::stable_sort(out.begin(), out.end(),
                   [](const NodeFrame& a, const NodeFrame& b) { return a.due_ns < b.due_ns; });
  return out;
}

std::int64_t Cia402DriveNode::NextEventNs() const {
  std::int64_t next = std::min({boot_due_ns_, next_heartbeat_ns_, consumer_deadline_ns_});
  for (const Pdo& p : rpdo_) next = std::min(next, p.next_ns);
  if (nmt_ == NmtState::kOperational) {
    for (const Pdo& p : tpdo_) next = std::min(next, p.next_ns);
  }
  if (!pending_.empty()) next = std::min(next, now_ns_);
  return next;
}

std::vector<NodeFrame> Cia402DriveNode::OnFrame(const bus::CanFrame& f, std::int64_t t_ns) {
  std::vector<NodeFrame> out;
  if (f.extended || f.rtr || f.error || f.fd) return out;
  const std::uint8_t id = config_.node_id;
  if (f.id == canopen::kNmtCobId) {
    if (f.len != 2) {
      ++rejected_frames_;
      return out;
    }
    if (f.data[1] == 0 || f.data[1] == id) HandleNmt(f.data[0], t_ns);
    return out;
  }
  if (nmt_ == NmtState::kOff) return out;
  if (f.id == canopen::kSyncCobId) {
    HandleSync(t_ns, out);
    return out;
  }
  if (f.id == canopen::CobId(canopen::Function::kSdoRequest, id)) {
    if (f.len != 8) {
      ++rejected_frames_;
      return out;
    }
    if (nmt_ != NmtState::kStopped) HandleSdo(f, t_ns, out);
    return out;
  }
  const std::uint16_t consumed = consumer_heartbeat_ >> 16 & 0xFF;
  const std::uint16_t consumer_ms = consumer_heartbeat_ & 0xFFFF;
  if (consumed != 0 && consumer_ms != 0 &&
      f.id ==
          canopen::CobId(canopen::Function::kErrorControl, static_cast<std::uint8_t>(consumed)) &&
      f.len >= 1) {
    consumer_deadline_ns_ = t_ns + consumer_ms * kNsPerMs;
    return out;
  }
  if (nmt_ != NmtState::kOperational) return out;
  for (Pdo& p : rpdo_) {
    if ((p.cob_id & canopen::kPdoCobIdInvalid) == 0 && f.id == (p.cob_id & 0x7FF)) {
      HandleRpdo(p, f, t_ns);
    }
  }
  StepRamp(t_ns);  // a new target acts on the power stage from this instant
  return out;
}

void Cia402DriveNode::HandleNmt(std::uint8_t command, std::int64_t t_ns) {
  if (nmt_ == NmtState::kOff) return;
  switch (command) {
    case canopen::nmt::kStart:
      if (nmt_ != NmtState::kOperational) EnterOperational(t_ns);
      break;
    case canopen::nmt::kStop:
      if (nmt_ == NmtState::kOperational) LeaveOperational(t_ns);
      nmt_ = NmtState::kStopped;
      break;
    case canopen::nmt::kEnterPreOperational:
      if (nmt_ == NmtState::kOperational) LeaveOperational(t_ns);
      nmt_ = NmtState::kPreOperational;
      break;
    case canopen::nmt::kResetNode:
      ResetApplication();
      ResetCommunication();
      ScheduleBoot(t_ns + config_.reset_delay_ns);
      break;
    case canopen::nmt::kResetCommunication:
      ResetCommunication();
      ScheduleBoot(t_ns + config_.reset_delay_ns);
      break;
    default:
      break;
  }
}

void Cia402DriveNode::HandleSync(std::int64_t t_ns, std::vector<NodeFrame>& out) {
  if (nmt_ != NmtState::kOperational) return;
  // Synchronous RPDOs take effect at the SYNC after they came; then the ramp runs with them.
  for (Pdo& p : rpdo_) {
    if (p.pending) {
      p.pending = false;
      ApplyRpdo(p, t_ns);
    }
  }
  StepRamp(t_ns);
  for (Pdo& p : tpdo_) {
    if ((p.cob_id & canopen::kPdoCobIdInvalid) || p.type == 0 || p.type > 240) continue;
    if (++p.sync_count >= p.type) {
      p.sync_count = 0;
      EmitTpdo(p, t_ns + config_.response_delay_ns, out);
    }
  }
}

void Cia402DriveNode::HandleRpdo(Pdo& p, const bus::CanFrame& f, std::int64_t t_ns) {
  std::uint32_t bits = 0;
  for (std::uint8_t i = 0; i < p.count; ++i) bits += p.map[i] & 0xFF;
  if (f.len < (bits + 7) / 8) {
    ++rejected_frames_;  // too short for its mapping: ignored (CiA 301 may signal EMCY 0x8210)
    return;
  }
  std::copy(f.data.begin(), f.data.begin() + 8, p.data);
  p.len = f.len;
  if (p.event_ms > 0) p.next_ns = t_ns + p.event_ms * kNsPerMs;
  if (p.type <= 240) {
    p.pending = true;
  } else {
    ApplyRpdo(p, t_ns);
  }
}

void Cia402DriveNode::ApplyRpdo(const Pdo& p, std::int64_t t_ns) {
  unsigned bit = 0;
  for (std::uint8_t i = 0; i < p.count; ++i) {
    const std::uint8_t n = p.map[i] & 0xFF;
    std::uint64_t v = 0;
    for (unsigned b = 0; b < n; ++b, ++bit) {
      if (p.data[bit / 8] >> (bit % 8) & 1) v |= 1ull << b;
    }
    const auto index = static_cast<std::uint16_t>(p.map[i] >> 16);
    const auto sub = static_cast<std::uint8_t>(p.map[i] >> 8);
    if (index == 0) continue;  // dummy entry
    (void)Write(index, sub, static_cast<std::uint32_t>(v), static_cast<std::uint8_t>(n / 8), t_ns,
                true);
  }
}

void Cia402DriveNode::EmitTpdo(Pdo& p, std::int64_t due_ns, std::vector<NodeFrame>& out) {
  if (p.cob_id & canopen::kPdoCobIdInvalid) return;
  bus::CanFrame f;
  f.id = p.cob_id & 0x7FF;
  unsigned bit = 0;
  for (std::uint8_t i = 0; i < p.count; ++i) {
    const std::uint8_t n = p.map[i] & 0xFF;
    std::uint32_t value = 0;
    std::uint8_t size = 0;
    (void)Read(static_cast<std::uint16_t>(p.map[i] >> 16), static_cast<std::uint8_t>(p.map[i] >> 8),
               value, size);
    for (unsigned b = 0; b < n; ++b, ++bit) {
      if (value >> b & 1) f.data[bit / 8] |= static_cast<std::uint8_t>(1u << (bit % 8));
    }
  }
  f.len = static_cast<std::uint8_t>((bit + 7) / 8);
  Emit(f, due_ns, out);
}

bool Cia402DriveNode::ObjectInfo(std::uint16_t index, std::uint8_t sub, std::uint8_t& bits,
                                 bool& writable, bool& mappable) const {
  writable = false;
  mappable = false;
  const auto is = [&](std::uint8_t b, bool w, bool m) {
    bits = b;
    writable = w;
    mappable = m;
    return true;
  };
  const bool sub0 = sub == 0;
  switch (index) {
    case canopen::od::kDeviceType:
      return sub0 && is(32, false, false);
    case canopen::od::kErrorRegister:
      return sub0 && is(8, false, true);
    case kConsumerHeartbeat:
      if (sub == 0) return is(8, false, false);
      return sub == 1 && is(32, true, false);
    case canopen::od::kProducerHeartbeatTime:
      return sub0 && is(16, true, false);
    case canopen::od::kIdentity:
      if (sub == 0) return is(8, false, false);
      return sub <= 4 && is(32, false, false);
    case kRpdoCommunication:
    case kRpdoCommunication + 1:
    case kTpdoCommunication:
    case kTpdoCommunication + 1:
      if (sub == 0) return is(8, false, false);
      if (sub == 1) return is(32, true, false);
      if (sub == 2) return is(8, true, false);
      if (sub == 5) return is(16, true, false);
      return false;
    case kRpdoMapping:
    case kRpdoMapping + 1:
    case kTpdoMapping:
    case kTpdoMapping + 1:
      if (sub == 0) return is(8, true, false);
      return sub <= 8 && is(32, true, false);
    case kAbortConnectionOption:
    case kQuickStopOption:
    case kFaultReactionOption:
      return sub0 && is(16, true, false);
    case kErrorCode:
      return sub0 && is(16, false, true);
    case kControlword:
      return sub0 && is(16, true, true);
    case kStatusword:
      return sub0 && is(16, false, true);
    case kModesOfOperation:
      return sub0 && is(8, true, true);
    case kModesDisplay:
      return sub0 && is(8, false, true);
    case kPositionActual:
    case kVelocityActual:
      return sub0 && is(32, false, true);
    case kVelocityWindow:
    case kVelocityThreshold:
      return sub0 && is(16, true, false);
    case kMaxTorque:
      return sub0 && is(16, true, true);
    case kRatedCurrent:
    case kRatedTorque:
      return sub0 && is(32, false, false);
    case kTorqueActual:
    case kCurrentActual:
      return sub0 && is(16, false, true);
    case kPolarity:
      return sub0 && is(8, true, false);
    case kMaxMotorSpeed:
    case kQuickStopDeceleration:
      return sub0 && is(32, true, false);
    case kProfileAcceleration:
    case kProfileDeceleration:
      return sub0 && is(32, true, true);
    case kTargetVelocity:
      return sub0 && is(32, true, true);
    case kSupportedModes:
      return sub0 && is(32, false, false);
    default:
      break;
  }
  for (const auto& e : extra_) {
    if (e.index == index && e.sub == sub)
      return is(static_cast<std::uint8_t>(8 * e.size), e.writable, false);
  }
  return false;
}

std::uint32_t Cia402DriveNode::Read(std::uint16_t index, std::uint8_t sub, std::uint32_t& value,
                                    std::uint8_t& size) const {
  std::uint8_t bits = 0;
  bool writable = false, mappable = false;
  if (!ObjectInfo(index, sub, bits, writable, mappable)) {
    const bool known_index = ObjectInfo(index, 0, bits, writable, mappable);
    return known_index ? sdo::kAbortNoSubindex : sdo::kAbortNoObject;
  }
  size = bits / 8;
  const auto pdo = [&](const Pdo& p) -> std::uint32_t {
    switch (sub) {
      case 0:
        return 5;
      case 1:
        return p.cob_id;
      case 2:
        return p.type;
      default:
        return p.event_ms;
    }
  };
  const auto map = [&](const Pdo& p) -> std::uint32_t {
    return sub == 0 ? p.count : p.map[sub - 1];
  };
  switch (index) {
    case canopen::od::kDeviceType:
      value = config_.device_type;
      break;
    case canopen::od::kErrorRegister:
      value = error_register_;
      break;
    case kConsumerHeartbeat:
      value = sub == 0 ? 1 : consumer_heartbeat_;
      break;
    case canopen::od::kProducerHeartbeatTime:
      value = heartbeat_ms_;
      break;
    case canopen::od::kIdentity: {
      const std::uint32_t v[5] = {4, config_.vendor_id, config_.product_code, config_.revision,
                                  config_.serial};
      value = v[sub];
      break;
    }
    case kRpdoCommunication:
    case kRpdoCommunication + 1:
      value = pdo(rpdo_[index - kRpdoCommunication]);
      break;
    case kTpdoCommunication:
    case kTpdoCommunication + 1:
      value = pdo(tpdo_[index - kTpdoCommunication]);
      break;
    case kRpdoMapping:
    case kRpdoMapping + 1:
      value = map(rpdo_[index - kRpdoMapping]);
      break;
    case kTpdoMapping:
    case kTpdoMapping + 1:
      value = map(tpdo_[index - kTpdoMapping]);
      break;
    case kAbortConnectionOption:
      value = SignExtendMask(abort_option_, 16);
      break;
    case kQuickStopOption:
      value = SignExtendMask(quick_stop_option_, 16);
      break;
    case kFaultReactionOption:
      value = SignExtendMask(fault_reaction_option_, 16);
      break;
    case kErrorCode:
      value = error_code_;
      break;
    case kControlword:
      value = controlword_;
      break;
    case kStatusword:
      value = statusword();
      break;
    case kModesOfOperation:
      value = SignExtendMask(mode_request_, 8);
      break;
    case kModesDisplay:
      value = SignExtendMask(mode_, 8);
      break;
    case kPositionActual:
      value = static_cast<std::uint32_t>(PositionActual());
      break;
    case kVelocityActual:
      value = static_cast<std::uint32_t>(VelocityActual());
      break;
    case kVelocityWindow:
      value = velocity_window_;
      break;
    case kVelocityThreshold:
      value = velocity_threshold_;
      break;
    case kMaxTorque:
      value = max_torque_permille_;
      break;
    case kRatedCurrent:
      value = config_.rated_current_ma;
      break;
    case kRatedTorque:
      value = config_.rated_torque_mnm;
      break;
    case kTorqueActual:
      value = SignExtendMask(TorqueActual(), 16);
      break;
    case kCurrentActual:
      value = SignExtendMask(CurrentActual(), 16);
      break;
    case kPolarity:
      value = polarity_;
      break;
    case kMaxMotorSpeed:
      value = max_motor_speed_;
      break;
    case kProfileAcceleration:
      value = profile_accel_;
      break;
    case kProfileDeceleration:
      value = profile_decel_;
      break;
    case kQuickStopDeceleration:
      value = quick_stop_decel_;
      break;
    case kTargetVelocity:
      value = static_cast<std::uint32_t>(target_velocity_);
      break;
    case kSupportedModes:
      value = 1u << (kProfileVelocity - 1) | 1u << (kCyclicSyncVelocity - 1);
      break;
    default:
      for (const auto& e : extra_) {
        if (e.index == index && e.sub == sub) value = e.value;
      }
      break;
  }
  return 0;
}

std::uint32_t Cia402DriveNode::ValidateMapping(const Pdo& p, bool rpdo, std::uint8_t count) const {
  if (count > 8) return sdo::kAbortValue;
  unsigned total = 0;
  for (std::uint8_t i = 0; i < count; ++i) {
    const auto index = static_cast<std::uint16_t>(p.map[i] >> 16);
    const auto sub = static_cast<std::uint8_t>(p.map[i] >> 8);
    const std::uint8_t n = p.map[i] & 0xFF;
    std::uint8_t bits = 0;
    bool writable = false, mappable = false;
    if (!ObjectInfo(index, sub, bits, writable, mappable) || !mappable || (rpdo && !writable) ||
        bits != n) {
      return sdo::kAbortNotMappable;
    }
    total += n;
  }
  return total > 64 ? sdo::kAbortPdoLength : 0;
}

std::uint32_t Cia402DriveNode::Write(std::uint16_t index, std::uint8_t sub, std::uint32_t value,
                                     std::uint8_t size, std::int64_t t_ns, bool from_pdo) {
  std::uint8_t bits = 0;
  bool writable = false, mappable = false;
  if (!ObjectInfo(index, sub, bits, writable, mappable)) {
    const bool known_index = ObjectInfo(index, 0, bits, writable, mappable);
    return known_index ? sdo::kAbortNoSubindex : sdo::kAbortNoObject;
  }
  if (!writable) return sdo::kAbortReadOnly;
  if (size != 0 && size != bits / 8) return sdo::kAbortLength;
  if (bits < 32) value &= (1u << bits) - 1u;  // unsized downloads: the object's bytes only
  const auto pdo_comm = [&](Pdo& p, bool rpdo) -> std::uint32_t {
    if (sub == 1) {
      const bool valid_now = (p.cob_id & canopen::kPdoCobIdInvalid) == 0;
      const bool valid_new = (value & canopen::kPdoCobIdInvalid) == 0;
      if ((value & canopen::kPdoCobIdExtended) || (value & 0x7FF) == 0) return sdo::kAbortValue;
      // A valid PDO's identifier changes only through invalid (CiA 301).
      if (valid_now && valid_new && (value & 0x7FF) != (p.cob_id & 0x7FF)) return sdo::kAbortValue;
      p.cob_id = value;
    } else if (sub == 2) {
      if (!ValidTransmissionType(value)) return sdo::kAbortValue;
      p.type = static_cast<std::uint8_t>(value);
      p.sync_count = 0;
    } else {
      p.event_ms = static_cast<std::uint16_t>(value);
    }
    if (!rpdo) {
      const bool cyclic = nmt_ == NmtState::kOperational && p.type >= 254 && p.event_ms > 0;
      p.next_ns = cyclic ? t_ns + p.event_ms * kNsPerMs : kNever;
    }
    return 0;
  };
  const auto pdo_map = [&](Pdo& p, bool rpdo) -> std::uint32_t {
    if (sub == 0) {
      Pdo trial = p;
      if (const std::uint32_t abort =
              ValidateMapping(trial, rpdo, static_cast<std::uint8_t>(value))) {
        return abort;
      }
      p.count = static_cast<std::uint8_t>(value);
      return 0;
    }
    // Entries change only while sub 0 is 0 (CiA 301).
    if (p.count != 0) return sdo::kAbortUnsupportedAccess;
    p.map[sub - 1] = value;
    return 0;
  };
  switch (index) {
    case kConsumerHeartbeat:
      consumer_heartbeat_ = value;
      consumer_deadline_ns_ = kNever;
      break;
    case canopen::od::kProducerHeartbeatTime:
      heartbeat_ms_ = static_cast<std::uint16_t>(value);
      next_heartbeat_ns_ =
          heartbeat_ms_ > 0 && nmt_ != NmtState::kOff ? t_ns + heartbeat_ms_ * kNsPerMs : kNever;
      break;
    case kRpdoCommunication:
    case kRpdoCommunication + 1:
      return pdo_comm(rpdo_[index - kRpdoCommunication], true);
    case kTpdoCommunication:
    case kTpdoCommunication + 1:
      return pdo_comm(tpdo_[index - kTpdoCommunication], false);
    case kRpdoMapping:
    case kRpdoMapping + 1:
      return pdo_map(rpdo_[index - kRpdoMapping], true);
    case kTpdoMapping:
    case kTpdoMapping + 1:
      return pdo_map(tpdo_[index - kTpdoMapping], false);
    case kAbortConnectionOption: {
      const auto v = static_cast<std::int16_t>(SignedOf(value, 16));
      if (v < 0 || v > 3) return sdo::kAbortValue;
      abort_option_ = v;
      break;
    }
    case kQuickStopOption: {
      const auto v = static_cast<std::int16_t>(SignedOf(value, 16));
      if (v < 0 || v == 3 || v == 4 || v > 6) return sdo::kAbortValue;
      quick_stop_option_ = v;
      break;
    }
    case kFaultReactionOption: {
      const auto v = static_cast<std::int16_t>(SignedOf(value, 16));
      if (v < 0 || v > 2) return sdo::kAbortValue;
      fault_reaction_option_ = v;
      break;
    }
    case kControlword:
      Controlword(static_cast<std::uint16_t>(value), t_ns);
      break;
    case kModesOfOperation: {
      const auto m = static_cast<std::int8_t>(SignedOf(value, 8));
      const bool supported = m == 0 || m == kProfileVelocity || m == kCyclicSyncVelocity;
      if (!supported) {
        if (!from_pdo) return sdo::kAbortValue;
        break;  // from a PDO: ignored, the display keeps the mode in effect
      }
      mode_request_ = mode_ = m;
      break;
    }
    case kVelocityWindow:
      velocity_window_ = static_cast<std::uint16_t>(value);
      break;
    case kVelocityThreshold:
      velocity_threshold_ = static_cast<std::uint16_t>(value);
      break;
    case kMaxTorque:
      if (value > 0xFFFF) return sdo::kAbortValue;
      max_torque_permille_ = static_cast<std::uint16_t>(value);
      break;
    case kPolarity:
      polarity_ = static_cast<std::uint8_t>(value & 0xC0);
      break;
    case kMaxMotorSpeed:
      max_motor_speed_ = value;
      break;
    case kProfileAcceleration:
      profile_accel_ = value;
      break;
    case kProfileDeceleration:
      profile_decel_ = value;
      break;
    case kQuickStopDeceleration:
      quick_stop_decel_ = value;
      break;
    case kTargetVelocity:
      target_velocity_ = static_cast<std::int32_t>(value);
      break;
    default:
      for (auto& e : extra_) {
        if (e.index == index && e.sub == sub) e.value = value;
      }
      break;
  }
  return 0;
}

void Cia402DriveNode::HandleSdo(const bus::CanFrame& f, std::int64_t t_ns,
                                std::vector<NodeFrame>& out) {
  const std::uint8_t command = f.data[0];
  const auto index = static_cast<std::uint16_t>(f.data[1] | f.data[2] << 8);
  const std::uint8_t sub = f.data[3];
  std::uint32_t data =
      static_cast<std::uint32_t>(f.data[4]) | static_cast<std::uint32_t>(f.data[5]) << 8 |
      static_cast<std::uint32_t>(f.data[6]) << 16 | static_cast<std::uint32_t>(f.data[7]) << 24;
  const std::uint8_t ccs = sdo::CommandSpecifier(command);
  if (ccs == sdo::kCsAbort) return;
  const std::int64_t due = t_ns + config_.response_delay_ns;
  std::uint32_t abort = 0;
  if (ccs == sdo::kCcsInitiateUpload) {
    std::uint32_t value = 0;
    std::uint8_t size = 0;
    abort = Read(index, sub, value, size);
    if (!abort) {
      Emit(SdoFrame(config_.node_id, sdo::ExpeditedUploadResponse(size), index, sub, value), due,
           out);
      return;
    }
  } else if (ccs == sdo::kCcsInitiateDownload && (command & sdo::kExpedited)) {
    const bool sized = command & sdo::kSizeIndicated;
    const std::uint8_t size = sized ? sdo::ExpeditedSize(command) : std::uint8_t{0};
    if (sized && size < 4) data &= (1u << (8 * size)) - 1u;
    abort = Write(index, sub, data, size, due, false);
    if (!abort) {
      StepRamp(due);
      Emit(SdoFrame(config_.node_id, sdo::kDownloadResponse, index, sub, 0), due, out);
      // A state change the write caused (EMCY of a fault reset) goes out after the answer.
      for (NodeFrame& p : pending_) {
        p.due_ns = std::max(p.due_ns, due);
        out.push_back(p);
      }
      pending_.clear();
      return;
    }
  } else {
    abort = sdo::kAbortCommand;
  }
  Emit(SdoFrame(config_.node_id, sdo::kAbort, index, sub, abort), due, out);
}

}  // namespace wheelhil::emulator
