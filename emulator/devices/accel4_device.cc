#include "emulator/devices/accel4_device.h"

#include <cmath>

#include <fmt/format.h>

#include "emulator/faults/device_faults.h"
#include "emulator/faults/sensor_faults.h"

namespace wheelhil::emulator {

BodyKinematics AccelKinematics(const physics::BodyTruth& b) {
  BodyKinematics k;
  k.a_WBo_B = b.q_WB.conjugate() * b.a_WB_W;
  k.omega_WB_B = b.q_WB.conjugate() * b.omega_WB_W;
  k.alpha_WB_B = b.q_WB.conjugate() * b.alpha_WB_W;
  k.g_B = b.q_WB.conjugate() * Eigen::Vector3d(0.0, 0.0, -9.80665);
  return k;
}

Accel4Device::Accel4Device(std::shared_ptr<const bus::DbcDatabase> accel4_dbc,
                           const std::array<AccelerometerParams, 4>& sensors,
                           std::int64_t first_sample_ns)
    : params_(sensors), node_(std::move(accel4_dbc), sensors, first_sample_ns) {}

Accel4Device::~Accel4Device() = default;

// Once the worker reads ahead, it alone samples the sensors and walks ahead_next_ns_: a copy
// shares the first (and never samples them) and does not read the second.
Accel4Device::Accel4Device(const Accel4Device& other)
    : Device(other),
      name_(other.name_),
      params_(other.params_),
      node_(other.node_),
      ahead_(other.ahead_),
      ahead_next_ns_(other.ahead_ ? 0 : other.ahead_next_ns_),
      faults_(CopyOf(other.faults_)) {
  if (!ahead_) node_.OwnSensors();
}

std::unique_ptr<Device> Accel4Device::Clone() const {
  return std::unique_ptr<Device>(new Accel4Device(*this));
}

std::vector<std::string> Accel4Device::sensor_channels() const {
  return {"accel4.1", "accel4.2", "accel4.3", "accel4.4"};
}

double Accel4Device::channel_noise_std(const std::string& channel) const {
  const std::size_t c = static_cast<std::size_t>(channel.back() - '1');
  return params_[c < 4 ? c : 0].noise_density_m_s2_sqrt_hz * std::sqrt(params_[0].rate_hz);
}

void Accel4Device::ArmFaults(DeviceFaults faults) {
  TakeDeviceFaults(faults);
  for (auto& [channel, injector] : faults.sensors) {
    for (std::size_t c = 0; c < 4; ++c) {
      if (channel == fmt::format("accel4.{}", c + 1)) faults_[c] = std::move(injector);
    }
  }
}

void Accel4Device::StartReadingsAhead() {
  ahead_ = true;
  ahead_next_ns_ = node_.next_sample_ns();
}

void Accel4Device::TakeReadingsAhead(std::int64_t t_after_ns, const physics::BodyTruth& body,
                                     std::vector<double>& out) {
  for (; ahead_next_ns_ <= t_after_ns; ahead_next_ns_ += node_.period_ns()) {
    const std::array<double, 4> a = node_.SampleSensors(AccelKinematics(body));
    out.insert(out.end(), a.begin(), a.end());
  }
}

void Accel4Device::Poll(std::int64_t t_ns, const DeviceWorld& world, DevicePort& port) {
  std::size_t taken = 0;
  while (node_.next_sample_ns() <= t_ns) {
    const std::int64_t ts = node_.next_sample_ns();
    std::array<double, 4> a{};
    if (!ahead_) {
      a = node_.SampleSensors(AccelKinematics(*world.body));
    } else if (taken + 4 <= world.readings.size()) {
      for (std::size_t c = 0; c < 4; ++c) a[c] = world.readings[taken + c];
      taken += 4;
    } else {
      // Cannot happen (the worker walks the same instants); fail loudly rather than differ.
      port.Fail("internal: accel4 sample missing from the physics worker");
      break;
    }
    const bool dropped = !ApplyToChannels(faults_, a, ts);
    std::vector<NodeFrame> frames(1);
    frames[0].due_ns = ts;
    (void)node_.EncodeSample(a, frames[0].frame);  // advances (and counts) even when dropped
    if (dropped) continue;
    SendThroughDeviceFaults(std::move(frames), true, port);
  }
}

}  // namespace wheelhil::emulator
