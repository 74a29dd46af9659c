#include "firmware_stub/cia402_drives.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace wheelhil::fw {
namespace {

constexpr double kPi = 3.14159265358979323846;
using bus::cia402::State;
namespace cw = bus::cia402::controlword;

}  // namespace

const char* DriveStopReasonName(DriveStopReason r) noexcept {
  switch (r) {
    case DriveStopReason::kNone:
      return "none";
    case DriveStopReason::kDriveFault:
      return "drive_fault";
    case DriveStopReason::kLeftEnabled:
      return "left_operation_enabled";
    case DriveStopReason::kEmcy:
      return "emcy";
    case DriveStopReason::kNodeLost:
      return "node_lost";
    case DriveStopReason::kTrackingError:
      return "tracking_error";
    case DriveStopReason::kRequested:
      return "requested";
  }
  return "?";
}

Cia402Drives::Cia402Drives(const DriveSettings& settings, const DriveProtocol& protocol,
                           double cycle_s)
    : settings_(settings), protocol_(protocol) {
  if (settings_.tracking_error_rad_s > 0 && cycle_s > 0) {
    tracking_limit_cycles_ =
        std::max(1, static_cast<int>(std::ceil(settings_.tracking_error_time_s / cycle_s - 1e-9)));
    tracking_window_units_ =
        std::abs(static_cast<double>(ToDriveUnits(settings_.tracking_error_rad_s)));
  }
  for (const auto& n : settings_.nodes) {
    Drive d;
    d.node_id = static_cast<std::uint8_t>(n.node_id);
    drives_.push_back(d);
  }
}

bool Cia402Drives::OnFrame(const bus::CanFrame& f, bool& bad) {
  bad = false;
  std::uint8_t node = 0;
  const int which = protocol_.TpdoOf(f, node);
  if (which == 0) return false;
  auto it = std::find_if(drives_.begin(), drives_.end(),
                         [&](const Drive& d) { return d.node_id == node; });
  if (it == drives_.end()) return false;
  Drive& d = *it;
  if (which == 1) {
    if (!protocol_.DecodeTpdo1(f, d.statusword, d.velocity_actual)) {
      bad = true;
      return true;
    }
    d.seen = true;
    d.state = bus::cia402::StateOf(d.statusword);
    if (d.state == State::kOperationEnabled) d.was_enabled = true;
    if (d.state == State::kFault || d.state == State::kFaultReactionActive) {
      Stop(DriveStopReason::kDriveFault, d.node_id);
    } else if (d.was_enabled && d.state != State::kOperationEnabled && !stopped()) {
      Stop(DriveStopReason::kLeftEnabled, d.node_id);
    }
  } else if (!protocol_.DecodeTpdo2(f, d.position_actual, d.torque_actual)) {
    bad = true;
  }
  return true;
}

void Cia402Drives::Stop(DriveStopReason reason, std::uint8_t node_id) {
  if (stopped() || reason == DriveStopReason::kNone) return;
  stop_ = reason;
  stop_node_ = node_id;
}

bool Cia402Drives::all_enabled() const {
  if (stopped()) return false;
  return std::all_of(drives_.begin(), drives_.end(),
                     [](const Drive& d) { return d.state == State::kOperationEnabled; });
}

std::uint16_t Cia402Drives::Controlword(const Drive& d) const {
  if (stopped()) return cw::kQuickStop;  // Ramps down where enabled, disables elsewhere.
  if (!d.state) return cw::kShutdown;
  switch (*d.state) {
    case State::kNotReadyToSwitchOn:
    case State::kSwitchOnDisabled:
      return cw::kShutdown;
    case State::kReadyToSwitchOn:
      return cw::kSwitchOn;
    case State::kSwitchedOn:
    case State::kOperationEnabled:
      return cw::kEnableOperation;
    case State::kQuickStopActive:
    case State::kFaultReactionActive:
    case State::kFault:
      return cw::kQuickStop;  // Only reached stopped (OnFrame latches the stop).
  }
  return cw::kQuickStop;
}

std::int32_t Cia402Drives::ToDriveUnits(double wheel_rad_s) const {
  const double motor_rev_s = wheel_rad_s * settings_.gear_ratio / (2.0 * kPi);
  const double v =
      settings_.velocity_rpm ? motor_rev_s * 60.0 : motor_rev_s * settings_.counts_per_rev;
  if (!std::isfinite(v)) return 0;
  return static_cast<std::int32_t>(
      std::clamp(std::round(v), static_cast<double>(std::numeric_limits<std::int32_t>::min()),
                 static_cast<double>(std::numeric_limits<std::int32_t>::max())));
}

void Cia402Drives::Cycle(const std::vector<double>& wheel_rad_s,
                         const std::vector<bool>& node_operational,
                         std::vector<bus::CanFrame>& out) {
  for (std::size_t i = 0; i < drives_.size(); ++i) {
    Drive& d = drives_[i];
    if (!d.seen) continue;  // No statusword yet: nothing to base a command on.
    // Tracking: the velocity actual against the set points of the last two cycles (the
    // statusword and velocity may be a cycle old); inside their span is following.
    if (tracking_limit_cycles_ > 0 && !stopped() && d.target_sent &&
        d.state == State::kOperationEnabled) {
      const double lo = std::min(d.last_target, d.previous_target);
      const double hi = std::max(d.last_target, d.previous_target);
      const double v = d.velocity_actual;
      const double error = v < lo ? lo - v : (v > hi ? v - hi : 0.0);
      d.tracking_cycles = error > tracking_window_units_ ? d.tracking_cycles + 1 : 0;
      if (d.tracking_cycles >= tracking_limit_cycles_) {
        Stop(DriveStopReason::kTrackingError, d.node_id);
      }
    }
    // A stop goes to every drive, also one the master lost: a drive that fell silent may
    // still listen, and would otherwise run on at its last set point.
    const bool operational = i < node_operational.size() && node_operational[i];
    if (!operational && !stopped()) continue;
    const std::uint16_t word = Controlword(d);
    const bool moving = !stopped() && d.state == State::kOperationEnabled && i < wheel_rad_s.size();
    const std::int32_t target = moving ? ToDriveUnits(wheel_rad_s[i]) : 0;
    d.previous_target = d.target_sent ? d.last_target : target;
    d.last_target = target;
    d.target_sent = moving;
    bus::CanFrame f;
    if (protocol_.EncodeRpdo1(d.node_id, word, target, f)) out.push_back(f);
  }
}

}  // namespace wheelhil::fw
