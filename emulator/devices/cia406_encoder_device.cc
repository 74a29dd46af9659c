#include "emulator/devices/cia406_encoder_device.h"

#include <cmath>
#include <numbers>

#include <fmt/format.h>

#include "emulator/faults/device_faults.h"
#include "emulator/faults/sensor_faults.h"

namespace wheelhil::emulator {

namespace {

EncoderParams WithDirection(EncoderParams p, int direction) {
  p.direction = direction;
  return p;
}

}  // namespace

Cia406EncoderDevice::Cia406EncoderDevice(const Cia406EncoderDeviceConfig& config,
                                         std::shared_ptr<const Cia406Codec> codec)
    : config_(config),
      name_(fmt::format("encoder{}", config.node.node_id)),
      channel_("encoder." + config.wheel_name),
      codec_(std::move(codec)),
      model_(WithDirection(config.encoder, config.direction)),
      node_(std::make_unique<CanopenEncoderNode>(config.node, codec_, 0)) {
  model_.Reset(config.initial_angle_rad, 0);
}

Cia406EncoderDevice::~Cia406EncoderDevice() = default;

Cia406EncoderDevice::Cia406EncoderDevice(const Cia406EncoderDevice& other)
    : Device(other),
      config_(other.config_),
      name_(other.name_),
      channel_(other.channel_),
      codec_(other.codec_),
      model_(other.model_),
      node_(CopyOf(other.node_)),
      sensor_fault_(CopyOf(other.sensor_fault_)),
      last_state_(other.last_state_) {}

std::unique_ptr<Device> Cia406EncoderDevice::Clone() const {
  return std::unique_ptr<Device>(new Cia406EncoderDevice(*this));
}

double Cia406EncoderDevice::channel_noise_std(const std::string&) const {
  return 1.0 / std::sqrt(12.0);
}

void Cia406EncoderDevice::ArmFaults(DeviceFaults faults) {
  TakeDeviceFaults(faults);
  for (auto& [channel, injector] : faults.sensors) {
    if (channel == channel_) sensor_fault_ = std::move(injector);
  }
}

std::int64_t Cia406EncoderDevice::missed_counts() const {
  return sensor_fault_ ? sensor_fault_->missed_counts() : 0;
}

void Cia406EncoderDevice::Send(std::vector<NodeFrame> frames, bool from_poll, DevicePort& port) {
  if (silent()) {
    port.CountSilenced(frames.size());
    return;
  }
  SendThroughDeviceFaults(std::move(frames), from_poll, port);
}

void Cia406EncoderDevice::Poll(std::int64_t t_ns, const DeviceWorld& world, DevicePort& port) {
  const physics::WheelTruth& wheel = (*world.wheels)[config_.wheel_index];
  std::optional<std::uint32_t> counts = model_.Sample(wheel.angle_rad);
  if (sensor_fault_) counts = sensor_fault_->ApplyCounts(*counts, t_ns);
  const double speed = wheel.omega_rad_s * model_.counts_per_rev() / (2.0 * std::numbers::pi) *
                       config_.direction;
  // A dropped sample (dropout) leaves the node's last measurement in place.
  if (counts) node_->SetMeasurement(*counts, speed);
  if (DeviceFaultInjector* faults = device_faults()) {
    if (faults->NextActionNs() <= t_ns) (void)faults->ApplyTo(*node_, config_.node, codec_, t_ns);
    faults->AdvanceTo(t_ns);
  }
  Send(node_->Poll(t_ns), true, port);
  if (node_->state() != last_state_) {
    last_state_ = node_->state();
    port.Event(nlohmann::json{{"t_s", port.MotionSeconds(t_ns)},
                              {"event", "node_state"},
                              {"node_id", config_.node.node_id},
                              {"state", static_cast<int>(last_state_)}});
  }
}

void Cia406EncoderDevice::OnFrame(const bus::CanFrame& frame, std::int64_t t_ns,
                                  DevicePort& port) {
  Send(node_->OnFrame(frame, t_ns), false, port);
}

}  // namespace wheelhil::emulator
