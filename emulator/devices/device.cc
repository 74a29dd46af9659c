#include "emulator/devices/device.h"

#include "emulator/faults/device_faults.h"
#include "emulator/faults/sensor_faults.h"

namespace wheelhil::emulator {

Device::Device() = default;
Device::~Device() = default;

Device::Device(const Device& other)
    : silent_(other.silent_), device_faults_(CopyOf(other.device_faults_)) {}

void Device::EndStep(std::int64_t t_ns) {
  if (device_faults_) device_faults_->AdvanceTo(t_ns);
}

std::uint64_t Device::suppressed_frames() const {
  return device_faults_ ? device_faults_->suppressed_frames() : 0;
}

void Device::TakeDeviceFaults(DeviceFaults& faults) { device_faults_ = std::move(faults.device); }

void Device::SendThroughDeviceFaults(std::vector<NodeFrame> frames, bool from_poll,
                                     DevicePort& port) {
  if (device_faults_ && !frames.empty()) device_faults_->FilterOutputs(frames);
  port.Send(std::move(frames), from_poll);
}

}  // namespace wheelhil::emulator
