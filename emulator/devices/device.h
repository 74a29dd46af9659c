#pragma once
/// The one interface of every emulated CAN device (encoder node, IMU, accelerometer node, ...),
/// as the run's loop sees it. A device senses the vehicle (its sensor models sample the ground
/// truth after each physics step), keeps its own protocol state in virtual time (integer ns) and
/// hands the frames it sends, each with the instant it is due, to its DevicePort; the port runs
/// them through the device's faults and the frame faults onto the bus model. Devices never
/// block, never throw after construction and never read the wall clock. Thread-compatible: the
/// run's thread calls everything, except TakeReadingsAhead (see there).

#include <array>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bus/can_frame.h"
#include "emulator/devices/canopen_encoder_node.h"
#include "emulator/devices/wheel_drive.h"
#include "emulator/physics/roller_vehicle.h"

namespace wheelhil::emulator {

class DeviceFaultInjector;
class SensorFaultInjector;

/// A deep copy of what `p` owns (nullptr for nullptr), for the copies Device::Clone makes.
template <typename T>
std::unique_ptr<T> CopyOf(const std::unique_ptr<T>& p) {
  return p ? std::make_unique<T>(*p) : nullptr;
}
template <typename T, std::size_t N>
std::array<std::unique_ptr<T>, N> CopyOf(const std::array<std::unique_ptr<T>, N>& a) {
  std::array<std::unique_ptr<T>, N> copy;
  for (std::size_t i = 0; i < N; ++i) copy[i] = CopyOf(a[i]);
  return copy;
}

/// The vehicle after the latest physics step (world frame W, body frame B).
struct DeviceWorld {
  const physics::BodyTruth* body = nullptr;
  const std::vector<physics::WheelTruth>* wheels = nullptr;  ///< Vehicle wheel order.
  /// This device's readings taken ahead on the physics worker for this step (empty without).
  std::span<const double> readings;
};

/// A device's way onto the bus and into the run's record.
class DevicePort {
 public:
  virtual ~DevicePort() = default;
  /// Frames the device sends (after its own device faults). `from_poll`: produced by Poll at
  /// the step's end (their instants may lie inside the step), not by OnFrame.
  virtual void Send(std::vector<NodeFrame> frames, bool from_poll) = 0;
  /// Frames the device would have sent but a scenario fault keeps it silent.
  virtual void CountSilenced(std::size_t frames) = 0;
  /// An event for events.jsonl (its t_s is the time since the motion start).
  virtual void Event(nlohmann::json event) = 0;
  /// Seconds since the motion start of the instant t_ns (before it: since the run start).
  virtual double MotionSeconds(std::int64_t t_ns) const = 0;
  /// The run cannot go on (an internal inconsistency): it ends with this reason.
  virtual void Fail(std::string why) = 0;
};

/// The faults of one device, built from the scenario's fault list at the motion start.
struct DeviceFaults {
  /// Node-level faults (silent, heartbeat lost, reboot, EMCY) on this device's frames.
  std::unique_ptr<DeviceFaultInjector> device;
  /// Sensor faults by the device's channel name (see Device::sensor_channels()).
  std::vector<std::pair<std::string, std::unique_ptr<SensorFaultInjector>>> sensors;
  /// Faults of a drive (over-current, stuck, torque limit), windows in virtual time.
  std::vector<DriveFault> drive;
};

class Device {
 public:
  Device();
  virtual ~Device();
  Device& operator=(const Device&) = delete;

  /// A copy of the device as it is now (protocol state, sensor models and their noise streams,
  /// faults), for a forecast of what it will send: polled with the same worlds and frames, the
  /// copy sends what the device would. What the physics worker samples for a device that reads
  /// ahead is shared, not copied (the worker may be using it): a copy of such a device takes
  /// its readings from DeviceWorld::readings only. Fault windows' start/end events of the copy
  /// go to the same FaultEventLog as the device's.
  virtual std::unique_ptr<Device> Clone() const = 0;

  /// The bus node's name: "encoder1", "imu", "accel4", ...
  virtual const std::string& name() const = 0;
  /// The next instant the device has something due on its own (INT64_MAX: nothing).
  virtual std::int64_t NextEventNs() const = 0;
  /// Called at the end of every physics step (t_ns): samples the world, then sends what is
  /// due at or before t_ns (each frame with its own due instant).
  virtual void Poll(std::int64_t t_ns, const DeviceWorld& world, DevicePort& port) = 0;
  /// A frame another node put on the bus, complete at t_ns.
  virtual void OnFrame(const bus::CanFrame& frame, std::int64_t t_ns, DevicePort& port) {
    (void)frame, (void)t_ns, (void)port;
  }
  /// False when OnFrame leaves the device as it was for every classic standard data frame with
  /// this 11-bit id (it reads none): the firmware may then run ahead through its sends of such
  /// frames (docs/virtual-time.md). Conservative by default.
  virtual bool ReadsFrame(std::uint32_t id) const {
    (void)id;
    return true;
  }
  /// After every device was polled at t_ns and the frame faults released what was due: the
  /// device faults' windows advance (their start/end events).
  virtual void EndStep(std::int64_t t_ns);
  /// The name fault specs and the fault log use for the device ("gyro" for the IMU).
  virtual std::string fault_name() const { return name(); }
  /// Its CANopen node id (1..127); 0: not a CANopen node.
  virtual std::uint8_t canopen_node_id() const { return 0; }
  /// Ready for the motion phase (a CANopen node: started by the master).
  virtual bool Ready() const { return true; }
  /// A drive: the wheels it powers (a CiA 402 drive one, a DBC motor controller maybe several)
  /// and what its power stages apply now (before the next physics step). Other devices: none.
  virtual std::vector<WheelDrive> wheel_drives() const { return {}; }

  /// Scenario faults on the device as a whole: it stops sending while silent ...
  virtual void SetSilent(bool silent) { silent_ = silent; }
  bool silent() const { return silent_; }
  /// ... and reports a device fault (CANopen: EMCY with `error_code`) until it clears.
  virtual void RaiseFault(std::uint16_t error_code, std::int64_t t_ns) { (void)error_code, (void)t_ns; }
  virtual void ClearFault(std::int64_t t_ns) { (void)t_ns; }

  /// Names of the sensor channels sensor faults can address ("gyro", "accel4.1", ...).
  virtual std::vector<std::string> sensor_channels() const { return {}; }
  /// A channel's name in the fault log.
  virtual std::string channel_label(const std::string& channel) const { return channel; }
  /// The white-noise standard deviation of a channel (a noise-scaling fault's unit).
  virtual double channel_noise_std(const std::string& channel) const {
    (void)channel;
    return 0.0;
  }
  /// Takes the faults built for this device (at the motion start).
  virtual void ArmFaults(DeviceFaults faults) = 0;
  /// Totals of its faults for report.json: frames its device faults suppressed, encoder
  /// counts its sensor faults removed.
  virtual std::uint64_t suppressed_frames() const;
  virtual std::int64_t missed_counts() const { return 0; }

  /// Readings that depend on the body kinematics and the sensors' own noise streams only may be
  /// taken on the physics worker, ahead of the run's thread. After StartReadingsAhead, the
  /// worker calls TakeReadingsAhead after each step with the instant that step ends and the body
  /// then, and Poll gets them in DeviceWorld::readings. Default: none.
  virtual bool ReadsAhead() const { return false; }
  virtual void StartReadingsAhead() {}
  virtual void TakeReadingsAhead(std::int64_t t_after_ns, const physics::BodyTruth& body,
                                 std::vector<double>& out) {
    (void)t_after_ns, (void)body, (void)out;
  }

 protected:
  Device(const Device& other);
  /// Keeps the device faults of `faults` (ArmFaults): SendThroughDeviceFaults applies them, and
  /// EndStep advances their windows.
  void TakeDeviceFaults(DeviceFaults& faults);
  DeviceFaultInjector* device_faults() const { return device_faults_.get(); }
  /// `frames` through the device faults (silent, heartbeat lost, off) to the port.
  void SendThroughDeviceFaults(std::vector<NodeFrame> frames, bool from_poll, DevicePort& port);

 private:
  bool silent_ = false;
  std::unique_ptr<DeviceFaultInjector> device_faults_;
};

}  // namespace wheelhil::emulator
