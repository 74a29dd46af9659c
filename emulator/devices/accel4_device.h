#pragma once
/// Paper 002's four single-axis accelerometers as one CAN device (Accel4Node over
/// bus/dbc/wheelhil_accel4.dbc): at each sample instant the four sensors are sampled from the
/// body kinematics of that step (specific force at their mounting points), sensor faults
/// (channels "accel4.1" .. "accel4.4") act on each reading (a dropped reading drops the frame;
/// the counter still advances) and one frame carries all four. The sensor readings depend on
/// the kinematics and the sensors' own noise streams only, so they may be taken on the physics
/// worker (ReadsAhead). Device faults act on its frames. Thread-compatible.

#include <array>
#include <cstdint>
#include <memory>
#include <string>

#include "emulator/devices/accel4_node.h"
#include "emulator/devices/device.h"

namespace wheelhil::emulator {

/// The body kinematics an accelerometer sees (body frame B, gravity included as g_B).
BodyKinematics AccelKinematics(const physics::BodyTruth& body);

class Accel4Device final : public Device {
 public:
  Accel4Device(std::shared_ptr<const bus::DbcDatabase> accel4_dbc,
               const std::array<AccelerometerParams, 4>& sensors, std::int64_t first_sample_ns);
  ~Accel4Device() override;
  std::unique_ptr<Device> Clone() const override;

  const std::string& name() const override { return name_; }
  std::string fault_name() const override { return "accel4"; }
  std::int64_t NextEventNs() const override { return node_.next_sample_ns(); }
  void Poll(std::int64_t t_ns, const DeviceWorld& world, DevicePort& port) override;
  bool ReadsFrame(std::uint32_t) const override { return false; }  // it only sends
  std::vector<std::string> sensor_channels() const override;
  double channel_noise_std(const std::string& channel) const override;
  void ArmFaults(DeviceFaults faults) override;

  bool ReadsAhead() const override { return true; }
  void StartReadingsAhead() override;
  void TakeReadingsAhead(std::int64_t t_after_ns, const physics::BodyTruth& body,
                         std::vector<double>& out) override;

 private:
  Accel4Device(const Accel4Device& other);

  std::string name_ = "accel4";
  std::array<AccelerometerParams, 4> params_;
  Accel4Node node_;
  bool ahead_ = false;
  std::int64_t ahead_next_ns_ = 0;  // the worker's next sample instant
  std::array<std::unique_ptr<SensorFaultInjector>, 4> faults_;
};

}  // namespace wheelhil::emulator
