#pragma once
/// A wheel encoder as the CAN device a robot has: an incremental encoder on one wheel
/// (EncoderModel: lines, quadrature, missed counts, glitches, disc phase) read by a CiA 406
/// CANopen node (CanopenEncoderNode). Every physics step the encoder samples its wheel's angle
/// and speed, the sensor fault (channel "encoder.<wheel>") acts on the counts, device faults
/// (reboot, EMCY, silent, heartbeat lost) on the node, and the node answers SYNC, SDO and NMT.
/// NMT state changes are events ("node_state"). Thread-compatible.

#include <cstdint>
#include <memory>
#include <string>

#include "bus/canopen.h"
#include "emulator/devices/canopen_encoder_node.h"
#include "emulator/devices/device.h"
#include "emulator/sensors/encoder_model.h"

namespace wheelhil::emulator {

struct Cia406EncoderDeviceConfig {
  std::string wheel_name;        ///< Platform wheel the encoder sits on.
  std::size_t wheel_index = 0;   ///< Its index in the vehicle's wheels.
  int direction = 1;             ///< +1 / -1: counting sense against the wheel's spin.
  EncoderParams encoder;         ///< The encoder itself (its direction set from `direction`).
  Cia406NodeConfig node;         ///< The CANopen node.
  double initial_angle_rad = 0;  ///< The wheel's angle when the encoder powers on.
};

class Cia406EncoderDevice final : public Device {
 public:
  Cia406EncoderDevice(const Cia406EncoderDeviceConfig& config,
                      std::shared_ptr<const Cia406Codec> codec);
  ~Cia406EncoderDevice() override;
  std::unique_ptr<Device> Clone() const override;

  const std::string& name() const override { return name_; }
  std::int64_t NextEventNs() const override { return node_->NextEventNs(); }
  void Poll(std::int64_t t_ns, const DeviceWorld& world, DevicePort& port) override;
  void OnFrame(const bus::CanFrame& frame, std::int64_t t_ns, DevicePort& port) override;
  bool ReadsFrame(std::uint32_t id) const override { return node_->ReadsFrame(id); }
  bool Ready() const override {
    return node_->state() == CanopenEncoderNode::NmtState::kOperational;
  }
  void RaiseFault(std::uint16_t error_code, std::int64_t t_ns) override {
    node_->RaiseFault(error_code, 0x81, t_ns);
  }
  void ClearFault(std::int64_t t_ns) override { node_->ClearFault(t_ns); }
  std::vector<std::string> sensor_channels() const override { return {channel_}; }
  /// The encoder's own noise is its quantisation: 1/sqrt(12) count.
  double channel_noise_std(const std::string& channel) const override;
  void ArmFaults(DeviceFaults faults) override;
  std::int64_t missed_counts() const override;

  std::uint8_t canopen_node_id() const override { return config_.node.node_id; }
  std::string channel_label(const std::string&) const override {
    return "encoder " + config_.wheel_name;
  }

 private:
  Cia406EncoderDevice(const Cia406EncoderDevice& other);
  void Send(std::vector<NodeFrame> frames, bool from_poll, DevicePort& port);

  Cia406EncoderDeviceConfig config_;
  std::string name_;
  std::string channel_;
  std::shared_ptr<const Cia406Codec> codec_;
  EncoderModel model_;
  std::unique_ptr<CanopenEncoderNode> node_;
  std::unique_ptr<SensorFaultInjector> sensor_fault_;
  CanopenEncoderNode::NmtState last_state_ = CanopenEncoderNode::NmtState::kOff;
};

}  // namespace wheelhil::emulator
