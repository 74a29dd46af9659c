#include "emulator/devices/cia402_drive_device.h"

#include <limits>

#include "bus/canopen.h"
#include "emulator/faults/device_faults.h"

namespace wheelhil::emulator {

namespace {

const char* DriveFaultName(DriveFault::Kind k) {
  switch (k) {
    case DriveFault::Kind::kOverCurrent:
      return "overcurrent";
    case DriveFault::Kind::kStuck:
      return "stuck";
    case DriveFault::Kind::kTorqueLimit:
      return "torque_limit";
  }
  return "?";
}

}  // namespace

Cia402DriveDevice::Cia402DriveDevice(const Cia402DriveDeviceConfig& config)
    : config_(config), node_(config.node, config.motor_torque_limit_nm, 0) {}

Cia402DriveDevice::~Cia402DriveDevice() = default;

std::int64_t Cia402DriveDevice::NextEventNs() const {
  std::int64_t next = node_.NextEventNs();
  for (std::size_t i = 0; i < drive_faults_.size(); ++i) {
    next = std::min(next, active_[i] ? drive_faults_[i].t1_ns : drive_faults_[i].t0_ns);
  }
  return next;
}

void Cia402DriveDevice::ArmFaults(DeviceFaults faults) {
  TakeDeviceFaults(faults);
  drive_faults_ = std::move(faults.drive);
  active_.assign(drive_faults_.size(), 0);
}

void Cia402DriveDevice::ApplyDriveFaults(std::int64_t t_ns, DevicePort& port) {
  bool stuck = false;
  bool persists = false;
  double limit = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < drive_faults_.size(); ++i) {
    const DriveFault& f = drive_faults_[i];
    const bool on = t_ns >= f.t0_ns && t_ns < f.t1_ns;
    if (on != static_cast<bool>(active_[i])) {
      active_[i] = on;
      nlohmann::json ev{{"t_s", port.MotionSeconds(on ? f.t0_ns : f.t1_ns)},
                        {"event", on ? "fault_start" : "fault_end"},
                        {"category", "drive"},
                        {"fault", DriveFaultName(f.kind)},
                        {"drive", config_.name},
                        {"wheel", config_.wheel_name}};
      if (f.kind == DriveFault::Kind::kTorqueLimit) ev["torque_limit_nm"] = f.torque_limit_nm;
      port.Event(ev);
      if (on && f.kind == DriveFault::Kind::kOverCurrent) node_.TripOverCurrent(t_ns, true);
    }
    if (!on) continue;
    if (f.kind == DriveFault::Kind::kStuck) stuck = true;
    if (f.kind == DriveFault::Kind::kOverCurrent) persists = true;
    if (f.kind == DriveFault::Kind::kTorqueLimit) limit = std::min(limit, f.torque_limit_nm);
  }
  node_.SetStuck(stuck);
  node_.SetFaultTorqueLimit(limit);
  if (!persists) node_.ClearOverCurrentCause();
}

void Cia402DriveDevice::Send(std::vector<NodeFrame> frames, bool from_poll, DevicePort& port) {
  if (silent()) {
    port.CountSilenced(frames.size());
    return;
  }
  SendThroughDeviceFaults(std::move(frames), from_poll, port);
}

void Cia402DriveDevice::Track(std::int64_t t_ns, DevicePort& port) {
  if (node_.nmt_state() != last_nmt_) {
    last_nmt_ = node_.nmt_state();
    port.Event(nlohmann::json{{"t_s", port.MotionSeconds(t_ns)},
                              {"event", "node_state"},
                              {"node_id", config_.node.node_id},
                              {"state", static_cast<int>(last_nmt_)}});
  }
  if (node_.state() != last_state_) {
    last_state_ = node_.state();
    nlohmann::json ev{{"t_s", port.MotionSeconds(t_ns)},
                      {"event", "drive_state"},
                      {"drive", config_.name},
                      {"node_id", config_.node.node_id},
                      {"state", Cia402DriveNode::StateName(last_state_)},
                      {"statusword", node_.statusword()}};
    if (last_state_ == Cia402DriveNode::State::kFault) ev["error_code"] = node_.error_code();
    port.Event(ev);
  }
}

void Cia402DriveDevice::Poll(std::int64_t t_ns, const DeviceWorld& world, DevicePort& port) {
  const physics::WheelTruth& w = (*world.wheels)[config_.wheel_index];
  node_.SetMeasurement(w.angle_rad, w.omega_rad_s, w.motor_torque_nm, w.motor_current_a);
  ApplyDriveFaults(t_ns, port);
  if (DeviceFaultInjector* faults = device_faults()) faults->AdvanceTo(t_ns);
  Send(node_.Poll(t_ns), true, port);
  Track(t_ns, port);
}

void Cia402DriveDevice::OnFrame(const bus::CanFrame& frame, std::int64_t t_ns, DevicePort& port) {
  Send(node_.OnFrame(frame, t_ns), false, port);
  Track(t_ns, port);
}

}  // namespace wheelhil::emulator
