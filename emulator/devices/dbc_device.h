#pragma once
/// A device whose frames are every cyclic message one node of the user's DBC file sends
/// (scenario `devices: [{kind: dbc, ...}]`, docs/own-hardware.md). Each signal is bound to a
/// quantity: the body rate about a sensor axis (rate_x/y/z), the specific force along it at the
/// mounting point (accel_x/y/z), a wheel's angle or speed, a temperature, a constant, a rolling
/// counter or a checksum; unbound signals carry their GenSigStartValue (raw), else raw 0.
///
/// Units come from each signal's DBC unit string (bus/dbc_units.h: deg/s, rad/s, rpm, g, m/s^2,
/// rad, deg, degC, K; a wheel angle in "counts" with the binding's counts_per_rev) times the
/// binding's gain. A value outside the signal's DBC [min|max] range (when given) is sent
/// clamped to it, beyond its raw range saturated; both are counted.
///
/// Timing: a message goes out every GenMsgCycleTime ms (or the override), the first one at the
/// device's start plus GenMsgStartDelayTime plus its phase; GenMsgSendType is read as its string
/// (a message whose type names no cycle, "Event", "OnChange", ..., is not sent unless an
/// override gives it a cycle time). Messages due at one instant share one sample of the
/// sensors; a counter counts frames of its message, or, `shared`, instants at which the device
/// sends. Checksums (frame_checksum.h) are computed last, over the payload with their bits zero.
/// A multiplexed message whose bound signals belong to several multiplexer values is sent as one
/// frame per bound value each cycle (ascending), the switch set to that value, carrying that
/// value's signals and the message's others; its switch cannot be bound then.
///
/// Sensors: three gyro axes and a three-axis accelerometer along the sensor axes, which are the
/// body axes rotated by the mounting's roll, pitch and yaw (R_BS = Rz(yaw) Ry(pitch) Rx(roll)),
/// at the mounting point r_BS_B. Sensor faults address "<name>.rate_x" .. "<name>.accel_z";
/// device faults the device's name.
///
/// Motor controller: signals of messages the node receives (sent by the firmware) can bind a
/// driven wheel's speed set point (`wheel_speed_setpoint`, an angular rate at the wheel in the
/// signal's unit, times the gain) and an enable flag (`drive_enable`: non-zero = power stage
/// on; without one the stage is on from the first set point); sent signals can report the
/// wheel's motor current and torque (`motor_current`, `motor_torque`) besides its angle and
/// speed. The wheel then follows the set point through the platform's motor model, with the
/// motor's torque limit; it coasts before the first set point, while disabled, and when no set
/// point frame came for setpoint_timeout_s. A received frame of the wrong length is refused
/// (counted; an event names it), so is one holding a NaN or infinite set point (counted; a
/// `setpoint_not_finite` event): neither moves a wheel nor counts as a set point frame for the
/// timeout. A multiplexed message's signals are read from the frames of their multiplexer
/// value only. Virtual time only; never blocks; thread-compatible.

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Geometry>

#include "bus/dbc.h"
#include "bus/dbc_units.h"
#include "emulator/devices/device.h"
#include "emulator/devices/frame_checksum.h"
#include "emulator/devices/six_axis_imu.h"

namespace wheelhil::emulator {

enum class DbcQuantity : std::uint8_t {
  kRateX,
  kRateY,
  kRateZ,
  kAccelX,
  kAccelY,
  kAccelZ,  // sensor axes
  kWheelAngle,
  kWheelSpeed,
  kTemperature,
  kConstant,
  kCounter,
  kChecksum,
  kWheelSpeedSetpoint,
  kDriveEnable,  // received (motor controller)
  kMotorCurrent,
  kMotorTorque,  // sent, of a driven wheel
};
/// Quantities read from received frames (the others are sent).
constexpr bool IsReceivedQuantity(DbcQuantity q) {
  return q == DbcQuantity::kWheelSpeedSetpoint || q == DbcQuantity::kDriveEnable;
}
/// "rate_x" ... "accel_z", "wheel_angle", "wheel_speed", "temperature", "constant", "counter",
/// "checksum"; nullopt otherwise.
std::optional<DbcQuantity> ParseDbcQuantity(std::string_view name) noexcept;
/// The names above, for messages.
std::string_view DbcQuantityNames() noexcept;

/// One signal's binding. `message` empty: the signal of that name in every message of the node
/// (a counter or a CRC that all frames carry).
struct DbcSignalBinding {
  std::string message;
  std::string signal;
  DbcQuantity quantity = DbcQuantity::kConstant;
  double gain = 1.0;
  std::size_t wheel_index = 0;  ///< Wheel quantities (vehicle wheel order).
  /// kWheelSpeedSetpoint: the wheel motor's own torque limit (wheel side, the platform's).
  double motor_torque_limit_nm = 0;
  double counts_per_rev = 0;  ///< kWheelAngle in a dimensionless unit ("counts").
  double value = 0;           ///< kConstant: the physical value, in the signal's unit.
  std::int64_t counter_step = 1;
  std::optional<std::uint64_t> counter_modulo;  ///< Default 2^bits.
  bool counter_shared = false;  ///< Counts the device's send instants, not the message's frames.
  ChecksumSpec checksum;
  std::string field;  ///< Where it was configured, for messages ("devices[0].signals.CRC").
};

/// Timing overrides of one message.
struct DbcMessageTiming {
  std::string message;
  std::optional<double> cycle_time_ms;
  double phase_ms = 0;
  std::optional<double> start_delay_ms;  ///< Replaces GenMsgStartDelayTime.
  std::string field;
};

struct DbcDeviceConfig {
  std::string name = "dbc";   ///< Its node name on the run's record and in faults.
  std::string field = "dbc";  ///< Its configuration's field, for messages ("devices[0]").
  std::string node;           ///< The DBC node (BU_) whose messages it sends.
  std::vector<DbcSignalBinding> signals;
  std::vector<DbcMessageTiming> timing;
  Eigen::Vector3d r_BS_B = Eigen::Vector3d::Zero();    ///< Mounting point [m].
  Eigen::Matrix3d R_BS = Eigen::Matrix3d::Identity();  ///< Sensor axes in the body frame.
  GyroParams gyro;            ///< Per axis (axis, rate and seed are set by the device).
  AccelerometerParams accel;  ///< Three axes (axes, point, rate and seed set by the device).
  double temperature_k = 298.15;
  std::uint64_t seed = 0;
  std::int64_t start_ns = 0;  ///< When the device starts sending (its power-on).
  /// Motor controller: no set point frame for this long turns the power stages off; 0 = never.
  double setpoint_timeout_s = 0;
};

/// R_BS from roll, pitch, yaw in degrees (z-y'-x'' intrinsic, as ROS and URDF write them).
Eigen::Matrix3d MountRotation(const Eigen::Vector3d& rpy_deg);

class DbcDevice final : public Device {
 public:
  /// Throws std::invalid_argument ("<field>: problem") for a node that sends nothing cyclic, a
  /// binding to a missing message or signal, a unit that does not fit its quantity, a counter
  /// or checksum its signal cannot carry, a message larger than a classic CAN frame.
  DbcDevice(std::shared_ptr<const bus::DbcDatabase> dbc, const DbcDeviceConfig& config);
  ~DbcDevice() override;
  std::unique_ptr<Device> Clone() const override;

  const std::string& name() const override { return name_; }
  std::int64_t NextEventNs() const override;
  void Poll(std::int64_t t_ns, const DeviceWorld& world, DevicePort& port) override;
  std::vector<std::string> sensor_channels() const override;
  double channel_noise_std(const std::string& channel) const override;
  void ArmFaults(DeviceFaults faults) override;
  void OnFrame(const bus::CanFrame& frame, std::int64_t t_ns, DevicePort& port) override;
  bool ReadsFrame(std::uint32_t id) const override;
  void EndStep(std::int64_t t_ns) override;
  std::vector<WheelDrive> wheel_drives() const override;
  /// Motor controller: set-point frames taken, and refused (wrong length).
  std::uint64_t setpoint_frames() const { return setpoint_frames_; }
  std::uint64_t rejected_frames() const { return rejected_frames_; }
  /// Set points beyond +-1000 rad/s at the wheel, clamped to it (`setpoint_clamped` events).
  std::uint64_t clamped_setpoints() const { return clamped_setpoints_; }
  /// NaN or infinite set points (float signals), each refusing its frame
  /// (`setpoint_not_finite` events).
  std::uint64_t nonfinite_setpoints() const { return nonfinite_setpoints_; }

  /// The messages it sends, in DBC order, and their periods.
  std::size_t message_count() const { return messages_.size(); }
  const bus::DbcMessage& message(std::size_t i) const { return *messages_[i].msg; }
  std::int64_t period_ns(std::size_t i) const { return messages_[i].period_ns; }
  std::uint64_t frames_sent() const { return frames_sent_; }
  /// Values clamped to their DBC range, or saturated at their raw range.
  std::uint64_t clamped() const { return clamped_; }

 private:
  struct Bound {
    const DbcSignalBinding* binding;
    const bus::DbcSignal* signal;
    bus::UnitToSi unit;  // signal unit -> SI (gain applied when encoding)
    std::uint64_t counter = 0;
    std::uint64_t modulo = 0;
  };
  struct Message {
    const bus::DbcMessage* msg = nullptr;
    std::vector<Bound> values;
    std::vector<Bound> counters;
    std::vector<Bound> checksums;
    /// GenSigStartValue (raw) of the signals that have one, read once.
    std::vector<std::pair<const bus::DbcSignal*, std::uint64_t>> start_values;
    /// The multiplexer values of its bound signals, ascending: one frame each per cycle.
    std::vector<int> mux_values;
    std::int64_t period_ns = 0;
    std::int64_t next_ns = 0;
  };
  struct Sample {
    std::array<double, 6> imu{};  // rate x y z, accel x y z, sensor axes
  };
  /// A message the node receives with set-point bindings.
  struct Received {
    const bus::DbcMessage* msg = nullptr;
    std::vector<Bound> values;
  };
  /// One driven wheel the node commands.
  struct Channel {
    std::size_t wheel = 0;
    double torque_limit_nm = 0;
    double omega_rad_s = 0;
    bool commanded_bound = false;  // a wheel_speed_setpoint signal exists for this wheel
    bool commanded = false;        // a set point came
    bool enable_bound = false;     // a drive_enable signal exists for this wheel
    bool enabled = false;
  };
  /// One frame of `m`; `mux_value`: the multiplexer value it carries (the switch set to it).
  // The copy's bindings point into this device's configuration (it must outlive the copy).
  DbcDevice(const DbcDevice& other);
  void Encode(Message& m, std::optional<int> mux_value, const Sample& s, const DeviceWorld& world,
              bus::CanFrame& out);
  void SplitByMultiplexerValue(Message& m);
  Channel& ChannelOf(std::size_t wheel);
  void BindReceived(const DbcSignalBinding& b);

  std::string name_;
  std::shared_ptr<const bus::DbcDatabase> dbc_;
  DbcDeviceConfig config_;
  std::vector<Message> messages_;
  std::uint64_t shared_counter_ = 0;
  std::unique_ptr<SixAxisImu> imu_;
  std::uint64_t frames_sent_ = 0;
  std::uint64_t clamped_ = 0;
  std::vector<Received> received_;
  std::vector<Channel> channels_;
  std::int64_t last_setpoint_ns_ = 0;
  bool setpoint_timed_out_ = false;
  std::uint64_t setpoint_frames_ = 0;
  std::uint64_t rejected_frames_ = 0;
  std::uint64_t clamped_setpoints_ = 0;
  std::uint64_t nonfinite_setpoints_ = 0;
  // OnFrame's scratch: the bound signals a received frame carries, decoded once.
  std::vector<std::pair<const Bound*, double>> decoded_;
};

}  // namespace wheelhil::emulator
