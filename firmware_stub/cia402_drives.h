#pragma once
/// The firmware's side of its CiA 402 drives: follows each drive's state from its TPDO1
/// statusword, walks it to Operation enabled through the state machine (Switch on disabled
/// -shutdown-> Ready to switch on -switch on-> Switched on -enable operation-> Operation
/// enabled), sends one RPDO1 (controlword, target velocity) per drive and control cycle, and
/// stops the robot safely: on a drive in Fault / Fault reaction active, a drive that leaves
/// Operation enabled unasked, a drive that does not follow its set point (velocity actual
/// further than tracking_error_rad_s outside the span of the last two cycles' set points, for
/// tracking_error_time_s), or a stop request (EMCY, lost node, from the app), every drive
/// gets quick stop (controlword 0x02, target 0) from then on; the stop is latched (a robot that
/// lost a drive mid-path does not resume by itself). Units: wheel speeds in rad/s in, drive
/// units out (rpm or increments/s of the motor, through gear ratio and sign). Pure (no clock,
/// no bus); thread-compatible.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "bus/can_frame.h"
#include "bus/cia402.h"
#include "firmware_stub/drive_protocol.h"
#include "firmware_stub/fw_config.h"

namespace wheelhil::fw {

enum class DriveStopReason : std::uint8_t {
  kNone,
  kDriveFault,     ///< A drive reported Fault or Fault reaction active.
  kLeftEnabled,    ///< A drive left Operation enabled without being told to.
  kEmcy,           ///< A drive sent an EMCY with a non-zero code.
  kNodeLost,       ///< A drive's heartbeat stopped or it never booted.
  kTrackingError,  ///< A drive did not follow its set point.
  kRequested,      ///< The app asked (e.g. its estimator failed).
};
const char* DriveStopReasonName(DriveStopReason r) noexcept;

class Cia402Drives {
 public:
  struct Drive {
    std::uint8_t node_id = 0;
    bool seen = false;  ///< A TPDO1 arrived.
    std::optional<bus::cia402::State> state;
    std::uint16_t statusword = 0;
    std::int32_t velocity_actual = 0;  ///< Drive units.
    std::int32_t position_actual = 0;  ///< Increments.
    std::int16_t torque_actual = 0;    ///< Per mille.
    bool was_enabled = false;          ///< Reached Operation enabled since the start.
    std::int32_t last_target = 0;      ///< Set point sent in the last cycle (drive units).
    std::int32_t previous_target = 0;  ///< ... and in the cycle before.
    bool target_sent = false;          ///< last_target went out while enabled.
    int tracking_cycles = 0;           ///< Cycles in a row outside the tracking window.
  };

  /// `cycle_s`: the control cycle (Cycle is called once per cycle), for the tracking time.
  Cia402Drives(const DriveSettings& settings, const DriveProtocol& protocol, double cycle_s);

  /// A TPDO1/TPDO2 of one of the drives: true when consumed; `bad` set when it did not decode.
  bool OnFrame(const bus::CanFrame& f, bool& bad);
  /// The control cycle's RPDO1 frames. `wheel_rad_s`: one set point per drive (in the
  /// settings' order), ignored while stopped; `node_operational[i]`: the CANopen master has
  /// started drive i (set points go only to started nodes; a stop goes to every drive).
  void Cycle(const std::vector<double>& wheel_rad_s, const std::vector<bool>& node_operational,
             std::vector<bus::CanFrame>& out);
  /// Latches a stop (the first reason is kept).
  void Stop(DriveStopReason reason, std::uint8_t node_id);

  /// Every drive is in Operation enabled (and no stop): set points move the robot.
  bool all_enabled() const;
  bool stopped() const { return stop_ != DriveStopReason::kNone; }
  DriveStopReason stop_reason() const { return stop_; }
  std::uint8_t stop_node() const { return stop_node_; }
  const std::vector<Drive>& drives() const { return drives_; }

  /// A wheel speed [rad/s] in the drives' 0x60FF unit (rounded, saturated to int32).
  std::int32_t ToDriveUnits(double wheel_rad_s) const;

 private:
  std::uint16_t Controlword(const Drive& d) const;

  DriveSettings settings_;
  const DriveProtocol& protocol_;
  std::vector<Drive> drives_;
  int tracking_limit_cycles_ = 0;     // 0: no tracking supervision
  double tracking_window_units_ = 0;  // tracking_error_rad_s in drive units
  DriveStopReason stop_ = DriveStopReason::kNone;
  std::uint8_t stop_node_ = 0;
};

}  // namespace wheelhil::fw
