#pragma once
/// A CANopen servo drive after CiA 301 (communication) and CiA 402 (drives and motion control,
/// IEC 61800-7-201) powering one wheel, as a pure state machine in virtual time (integer ns):
/// no threads, no I/O, no physics. The caller feeds frames off the bus (OnFrame), the wheel's
/// measured state after each physics step (SetMeasurement) and collects the frames the node
/// sends (Poll); WheelCommand() is what the power stage applies to the wheel's motor. Every
/// output carries the instant it is due. docs/closed-loop.md describes it for users.
///
/// Units: the dictionary's are the drive's (velocity in rpm or increments/s of the motor shaft,
/// position in increments of the motor encoder, torque and current in per mille of the rated
/// values 0x6076 / 0x6075); inside, and at SetMeasurement / WheelCommand, SI at the wheel
/// (rad, rad/s, N*m wheel side), converted through the gear ratio and the polarity 0x607E.
///
/// CiA 301: NMT (boot-up after power_on_delay, pre-operational / operational / stopped, reset
/// node and reset communication); heartbeat producer 0x1017 and one heartbeat consumer 0x1016:1;
/// SDO server, expedited, on every object below; RPDO1/2 (0x1400/0x1401, mapping
/// 0x1600/0x1601) and TPDO1/2 (0x1800/0x1801, mapping 0x1A00/0x1A01) with dynamic mapping (sub
/// 0 to 0, entries, sub 0 to n; mappable objects only, at most 64 bits), RPDO transmission type
/// 0..240 = applied at the next SYNC, 254/255 = on receipt, RPDO event timer (sub 5, ms) =
/// deadline monitoring; TPDO type 1..240 = every n-th SYNC, 254/255 = every event timer ms.
/// PDOs only in operational. EMCY when a fault occurs (error code 0x603F, error register 0x1001)
/// and the error reset (code 0) when it is reset.
///
/// CiA 402 state machine (statusword 0x6041 bits 0..6, commands from controlword 0x6040 bits
/// 0..3 and 7); illegal commands leave the state unchanged, as a drive does:
///   Not ready to switch on -(1, automatic)-> Switch on disabled -(2 shutdown)-> Ready to switch
///   on -(3 switch on)-> Switched on -(4 enable operation)-> Operation enabled; 5 disable
///   operation, 6/8 shutdown, 7/9/10/12 disable voltage, 7/10/11 quick stop, 12 quick stop done
///   (option codes 1, 2), 16 enable operation in Quick stop active (option codes 5, 6), 13 a
///   fault in any state -> Fault reaction active -(14, reaction done)-> Fault -(15, fault reset
///   0->1 edge of bit 7, cause gone)-> Switch on disabled.
/// Torque is on in Operation enabled, Quick stop active and Fault reaction active (ramps); off
/// (the wheel coasts) everywhere else. Modes 0x6060/0x6061: 3 profile velocity (target 0x60FF
/// reached along profile acceleration 0x6083 / deceleration 0x6084), 9 cyclic synchronous
/// velocity (target followed as given); any other mode holds zero. Quick stop option 0x605A (0
/// coast, 1 profile ramp, 2 quick stop ramp 0x6085, 5/6 the same and stay in Quick stop active),
/// fault reaction 0x605E (0 coast, 1 profile ramp, 2 quick stop ramp), abort connection 0x6007
/// (0 nothing, 1 fault 0x8130 heartbeat / 0x8250 RPDO timeout, 2 disable voltage, 3 quick stop)
/// when the heartbeat consumer times out, the RPDO deadline passes or NMT leaves operational in
/// Operation enabled. Over-current (a trip current exceeded for a trip time, or TripOverCurrent)
/// is fault 0x2310 with the power stage off at once. Statusword bit 9 remote, 10 target
/// reached (|actual - target| <= 0x606D), 11 internal limit (torque at its limit), 12 pv: speed
/// zero (|actual| <= 0x606F) / csv: following the target. Thread-compatible.

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "bus/can_frame.h"
#include "bus/cia402.h"
#include "emulator/devices/canopen_encoder_node.h"
#include "emulator/devices/wheel_drive.h"

namespace wheelhil::emulator {

struct Cia402DriveConfig {
  std::uint8_t node_id = 1;                      ///< 1..127.
  std::int64_t power_on_delay_ns = 100'000'000;  ///< Power-on to boot-up.
  std::int64_t reset_delay_ns = 10'000'000;      ///< NMT reset to boot-up.
  std::int64_t response_delay_ns = 0;            ///< SYNC / SDO request to the answer.
  std::uint16_t heartbeat_ms = 0;                ///< 0x1017 default.
  std::uint32_t consumer_heartbeat = 0;          ///< 0x1016:1 default: node << 16 | ms.
  std::uint32_t device_type = 0x00020192;        ///< 0x1000: profile 402, servo drive.
  std::uint32_t vendor_id = 0, product_code = 0, revision = 0, serial = 0;  ///< 0x1018.
  /// A PDO's defaults: COB-ID (0: the pre-defined connection set's, valid), transmission type,
  /// event timer (TPDO: cycle, RPDO: deadline; ms) and mapping entries (index << 16 | sub << 8
  /// | bits).
  struct PdoDefaults {
    std::uint32_t cob_id = 0;
    bool valid = true;
    std::uint8_t type = 255;
    std::uint16_t event_ms = 0;
    std::vector<std::uint32_t> map;
  };
  /// RPDO1: controlword + target velocity; RPDO2 (not valid): controlword + modes of operation.
  std::array<PdoDefaults, 2> rpdo = {PdoDefaults{0, true, 255, 0, {0x60400010, 0x60FF0020}},
                                     PdoDefaults{0, false, 255, 0, {0x60400010, 0x60600008}}};
  /// TPDO1: statusword + velocity actual; TPDO2: position actual + torque actual; both on every
  /// SYNC.
  std::array<PdoDefaults, 2> tpdo = {PdoDefaults{0, true, 1, 0, {0x60410010, 0x606C0020}},
                                     PdoDefaults{0, true, 1, 0, {0x60640020, 0x60770010}}};
  std::int8_t default_mode = 0;              ///< 0x6060 default (0: none).
  std::int16_t abort_connection_option = 1;  ///< 0x6007 default.
  std::int16_t quick_stop_option = 2;        ///< 0x605A default.
  std::int16_t fault_reaction_option = 2;    ///< 0x605E default.
  /// Velocity unit: rpm of the motor shaft (true) or increments/s of its encoder (false).
  bool velocity_rpm = true;
  std::uint32_t counts_per_rev = 4096;         ///< Motor encoder increments per motor turn.
  double gear_ratio = 1.0;                     ///< Motor turns per wheel turn.
  std::uint8_t polarity = 0;                   ///< 0x607E: bit 7 position, bit 6 velocity inverted.
  std::uint32_t profile_acceleration = 10000;  ///< 0x6083, velocity unit per s.
  std::uint32_t profile_deceleration = 10000;  ///< 0x6084.
  std::uint32_t quick_stop_deceleration = 50000;  ///< 0x6085.
  std::uint32_t max_motor_speed = 0;              ///< 0x6080, velocity unit; 0 = no limit.
  std::uint32_t rated_torque_mnm = 1000;          ///< 0x6076, motor side.
  std::uint32_t rated_current_ma = 10000;         ///< 0x6075.
  std::uint16_t velocity_window = 10;             ///< 0x606D, velocity unit.
  std::uint16_t velocity_threshold = 10;          ///< 0x606F, velocity unit.
  double trip_current_a = 0;  ///< Over-current trip level (|current| above it); 0 = none.
  double trip_time_s = 0.01;  ///< ... for this long.
  /// Objects beyond the built-in dictionary (from the vendor's EDS), served by SDO.
  std::vector<Cia406NodeConfig::ExtraObject> extra_objects{};
};

class Cia402DriveNode {
 public:
  enum class NmtState : std::uint8_t {
    kOff = 0xFF,
    kPreOperational = 0x7F,
    kOperational = 0x05,
    kStopped = 0x04
  };
  using State = bus::cia402::State;

  /// Powers on at power_on_ns. `motor_torque_limit_nm`: the motor's own wheel-side limit (the
  /// platform's), for the torque scaling. Throws std::invalid_argument on a bad configuration.
  Cia402DriveNode(const Cia402DriveConfig& config, double motor_torque_limit_nm,
                  std::int64_t power_on_ns = 0);

  /// The wheel after the latest physics step: angle, speed, motor torque (wheel side), current.
  void SetMeasurement(double angle_rad, double omega_rad_s, double torque_nm,
                      double current_a) noexcept;
  /// Frames off the bus at t_ns (NMT, SYNC, SDO requests, RPDOs, heartbeats of the consumed
  /// node). Call Poll(t_ns) first to keep the order of timed events.
  std::vector<NodeFrame> OnFrame(const bus::CanFrame& frame, std::int64_t t_ns);
  /// Timed work due at or before t_ns (boot-up, heartbeats, cyclic TPDOs, ramps, supervision),
  /// in due order. t_ns must not go backwards.
  std::vector<NodeFrame> Poll(std::int64_t t_ns);
  std::int64_t NextEventNs() const;

  /// The power stage's output after the latest Poll.
  WheelDriveCommand WheelCommand() const;

  /// Scenario faults: over-current trip (fault 0x2310; a reset is refused while `persists`);
  /// a set point that is ignored (the demand freezes); a lowered torque limit (wheel side,
  /// N*m; infinity = none).
  void TripOverCurrent(std::int64_t t_ns, bool persists);
  void ClearOverCurrentCause() { overcurrent_cause_ = false; }
  void SetStuck(bool stuck) { stuck_ = stuck; }
  void SetFaultTorqueLimit(double limit_nm) { fault_torque_limit_nm_ = limit_nm; }
  /// A generic device fault from the scenario (EMCY with the code, into Fault).
  void RaiseFault(std::uint16_t error_code, std::int64_t t_ns);

  NmtState nmt_state() const { return nmt_; }
  State state() const { return state_; }
  std::uint16_t statusword() const;
  std::uint16_t controlword() const { return controlword_; }
  std::int8_t mode_display() const { return mode_; }
  std::uint16_t error_code() const { return error_code_; }
  /// Demand velocity of the ramp (drive unit), what the motor servo is told.
  double demand_velocity() const { return demand_; }
  std::uint64_t rejected_frames() const { return rejected_frames_; }
  static const char* StateName(State s);

 private:
  struct Pdo {
    std::uint32_t cob_id = 0;
    std::uint8_t type = 255;
    std::uint16_t event_ms = 0;
    std::uint8_t count = 0;     // mapping sub 0
    std::uint32_t map[8] = {};  // mapping entries
    std::int64_t next_ns = 0;   // TPDO: next cyclic send; RPDO: deadline
    unsigned sync_count = 0;
    bool pending = false;  // RPDO: received, applied at the next SYNC
    std::uint8_t data[8] = {};
    std::uint8_t len = 0;
  };

  void ResetApplication();
  void ResetCommunication();
  // Extra (EDS) objects back to their defaults: the communication area (< 0x2000) or the rest.
  void ResetExtraObjects(bool communication);
  void ScheduleBoot(std::int64_t t_ns);
  void EnterOperational(std::int64_t t_ns);
  void LeaveOperational(std::int64_t t_ns);
  void HandleNmt(std::uint8_t command, std::int64_t t_ns);
  void HandleSync(std::int64_t t_ns, std::vector<NodeFrame>& out);
  void HandleSdo(const bus::CanFrame& f, std::int64_t t_ns, std::vector<NodeFrame>& out);
  void HandleRpdo(Pdo& p, const bus::CanFrame& f, std::int64_t t_ns);
  void ApplyRpdo(const Pdo& p, std::int64_t t_ns);
  std::uint32_t Read(std::uint16_t index, std::uint8_t sub, std::uint32_t& value,
                     std::uint8_t& size) const;
  std::uint32_t Write(std::uint16_t index, std::uint8_t sub, std::uint32_t value, std::uint8_t size,
                      std::int64_t t_ns, bool from_pdo);
  bool ObjectInfo(std::uint16_t index, std::uint8_t sub, std::uint8_t& bits, bool& writable,
                  bool& mappable) const;
  std::uint32_t ValidateMapping(const Pdo& p, bool rpdo, std::uint8_t count) const;
  void EmitTpdo(Pdo& p, std::int64_t due_ns, std::vector<NodeFrame>& out);
  void Controlword(std::uint16_t cw, std::int64_t t_ns);
  void EnterFault(std::uint16_t code, std::uint8_t error_register, bool coast, std::int64_t t_ns);
  void AbortConnection(std::uint16_t code, std::int64_t t_ns);
  void StepRamp(std::int64_t t_ns);
  void Emit(const bus::CanFrame& f, std::int64_t due_ns, std::vector<NodeFrame>& out);
  void EmitEmcy(std::uint16_t code, std::int64_t due_ns);
  double UnitToWheelRadS() const;  // rad/s at the wheel per velocity unit
  std::int32_t VelocityActual() const;
  std::int32_t PositionActual() const;
  std::int16_t TorqueActual() const;
  std::int16_t CurrentActual() const;

  Cia402DriveConfig config_;
  double motor_limit_nm_;
  NmtState nmt_ = NmtState::kOff;
  State state_ = State::kNotReadyToSwitchOn;
  std::int64_t now_ns_ = 0;
  std::int64_t boot_due_ns_ = 0;
  std::int64_t next_heartbeat_ns_ = 0;
  std::int64_t consumer_deadline_ns_ = 0;  // INT64_MAX until the first heartbeat
  std::int64_t last_ramp_ns_ = 0;
  std::vector<NodeFrame> pending_;  // EMCY and other frames for Poll
  // Communication objects.
  std::uint16_t heartbeat_ms_ = 0;
  std::uint32_t consumer_heartbeat_ = 0;
  Pdo rpdo_[2], tpdo_[2];
  // Application objects.
  std::uint16_t controlword_ = 0;
  std::int8_t mode_request_ = 0, mode_ = 0;
  std::int32_t target_velocity_ = 0;
  std::int16_t abort_option_ = 1, quick_stop_option_ = 2, fault_reaction_option_ = 2;
  std::uint8_t polarity_ = 0;
  std::uint32_t profile_accel_ = 0, profile_decel_ = 0, quick_stop_decel_ = 0;
  std::uint32_t max_motor_speed_ = 0;
  std::uint16_t max_torque_permille_ = 1000;  // 0x6072
  std::uint16_t velocity_window_ = 0, velocity_threshold_ = 0;
  std::uint16_t error_code_ = 0;
  std::uint8_t error_register_ = 0;
  std::vector<Cia406NodeConfig::ExtraObject> extra_;
  // Drive function.
  double demand_ = 0;  // velocity unit, motor side, before polarity
  bool reaction_profile_ramp_ = false;
  bool stay_in_quick_stop_ = false;
  // Measurement.
  double angle_rad_ = 0, omega_rad_s_ = 0, torque_nm_ = 0, current_a_ = 0;
  double over_current_s_ = 0;
  bool overcurrent_cause_ = false;
  bool stuck_ = false;
  double fault_torque_limit_nm_ = 1e300;
  std::uint64_t rejected_frames_ = 0;
};

}  // namespace wheelhil::emulator
