#pragma once
/// A wheel's servo drive as the CAN device a robot has: a CiA 402 node (Cia402DriveNode) whose
/// power stage drives the wheel's motor. Every physics step the drive measures its wheel (angle,
/// speed, motor torque and current), runs its state machine and ramps, and answers SYNC, SDO,
/// NMT and RPDOs; wheel_drives() is the set point and torque limit the physics applies before the
/// next step. Device faults (silent, heartbeat lost) act on its frames; drive faults (over-current
/// trip, stuck set point, lowered torque limit) on the drive, over their windows, each start and
/// end an event ("drive_fault"). State changes are events ("drive_state", "node_state").
/// Thread-compatible.

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "emulator/devices/cia402_drive_node.h"
#include "emulator/devices/device.h"

namespace wheelhil::emulator {

struct Cia402DriveDeviceConfig {
  std::string name;  ///< Device name ("drive_left", ...).
  std::string wheel_name;
  std::size_t wheel_index = 0;
  double motor_torque_limit_nm = 0;  ///< The platform motor's wheel-side limit.
  Cia402DriveConfig node;
};

class Cia402DriveDevice final : public Device {
 public:
  explicit Cia402DriveDevice(const Cia402DriveDeviceConfig& config);
  ~Cia402DriveDevice() override;
  std::unique_ptr<Device> Clone() const override {
    return std::unique_ptr<Device>(new Cia402DriveDevice(*this));
  }

  const std::string& name() const override { return config_.name; }
  std::int64_t NextEventNs() const override;
  void Poll(std::int64_t t_ns, const DeviceWorld& world, DevicePort& port) override;
  void OnFrame(const bus::CanFrame& frame, std::int64_t t_ns, DevicePort& port) override;
  bool Ready() const override {
    return node_.nmt_state() == Cia402DriveNode::NmtState::kOperational;
  }
  std::vector<WheelDrive> wheel_drives() const override {
    return {WheelDrive{config_.wheel_index, node_.WheelCommand()}};
  }
  void RaiseFault(std::uint16_t error_code, std::int64_t t_ns) override {
    node_.RaiseFault(error_code, t_ns);
  }
  void ArmFaults(DeviceFaults faults) override;
  std::uint8_t canopen_node_id() const override { return config_.node.node_id; }

  const Cia402DriveNode& node() const { return node_; }

 private:
  Cia402DriveDevice(const Cia402DriveDevice&) = default;
  void Send(std::vector<NodeFrame> frames, bool from_poll, DevicePort& port);
  void ApplyDriveFaults(std::int64_t t_ns, DevicePort& port);
  void Track(std::int64_t t_ns, DevicePort& port);

  Cia402DriveDeviceConfig config_;
  Cia402DriveNode node_;
  std::vector<DriveFault> drive_faults_;
  std::vector<char> active_;
  Cia402DriveNode::State last_state_ = Cia402DriveNode::State::kNotReadyToSwitchOn;
  Cia402DriveNode::NmtState last_nmt_ = Cia402DriveNode::NmtState::kOff;
};

}  // namespace wheelhil::emulator
