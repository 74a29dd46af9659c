#pragma once
/// CiA 402 (drives and motion control, IEC 61800-7-201) definitions shared by the emulated drive
/// (emulator/devices/cia402_drive_node.h) and any master (the reference firmware): object
/// indices, the state machine's states and their statusword patterns, controlword commands,
/// modes of operation, the EMCY codes the drive uses. Header-only, constexpr; thread-safe.
/// CiA 301 communication definitions live in bus/canopen.h.

#include <cstdint>
#include <optional>

namespace wheelhil::bus::cia402 {

/// Object dictionary indices of the drive profile.
namespace od {
inline constexpr std::uint16_t kAbortConnectionOption = 0x6007;
inline constexpr std::uint16_t kErrorCode = 0x603F;
inline constexpr std::uint16_t kControlword = 0x6040;
inline constexpr std::uint16_t kStatusword = 0x6041;
inline constexpr std::uint16_t kQuickStopOption = 0x605A;
inline constexpr std::uint16_t kFaultReactionOption = 0x605E;
inline constexpr std::uint16_t kModesOfOperation = 0x6060;
inline constexpr std::uint16_t kModesDisplay = 0x6061;
inline constexpr std::uint16_t kPositionActual = 0x6064;
inline constexpr std::uint16_t kVelocityActual = 0x606C;
inline constexpr std::uint16_t kVelocityWindow = 0x606D;
inline constexpr std::uint16_t kVelocityThreshold = 0x606F;
inline constexpr std::uint16_t kMaxTorque = 0x6072;
inline constexpr std::uint16_t kRatedCurrent = 0x6075;
inline constexpr std::uint16_t kRatedTorque = 0x6076;
inline constexpr std::uint16_t kTorqueActual = 0x6077;
inline constexpr std::uint16_t kCurrentActual = 0x6078;
inline constexpr std::uint16_t kPolarity = 0x607E;
inline constexpr std::uint16_t kMaxMotorSpeed = 0x6080;
inline constexpr std::uint16_t kProfileAcceleration = 0x6083;
inline constexpr std::uint16_t kProfileDeceleration = 0x6084;
inline constexpr std::uint16_t kQuickStopDeceleration = 0x6085;
inline constexpr std::uint16_t kTargetVelocity = 0x60FF;
inline constexpr std::uint16_t kSupportedModes = 0x6502;
}  // namespace od

/// The power drive system's states (CiA 402 figure "state machine").
enum class State : std::uint8_t {
  kNotReadyToSwitchOn,
  kSwitchOnDisabled,
  kReadyToSwitchOn,
  kSwitchedOn,
  kOperationEnabled,
  kQuickStopActive,
  kFaultReactionActive,
  kFault,
};

/// Statusword bits 0..6 of each state (bit 4 voltage enabled is set where the power stage may
/// be on); StateOf compares through kStateMask*.
constexpr std::uint16_t StatuswordPattern(State s) {
  switch (s) {
    case State::kNotReadyToSwitchOn:
      return 0x0000;
    case State::kSwitchOnDisabled:
      return 0x0040;
    case State::kReadyToSwitchOn:
      return 0x0031;
    case State::kSwitchedOn:
      return 0x0033;
    case State::kOperationEnabled:
      return 0x0037;
    case State::kQuickStopActive:
      return 0x0017;
    case State::kFaultReactionActive:
      return 0x001F;
    case State::kFault:
      return 0x0008;
  }
  return 0;
}

/// Statusword bits beyond the state.
namespace statusword {
inline constexpr std::uint16_t kWarning = 0x0080;
inline constexpr std::uint16_t kRemote = 0x0200;
inline constexpr std::uint16_t kTargetReached = 0x0400;
inline constexpr std::uint16_t kInternalLimit = 0x0800;
/// Mode specific: pv speed zero, csv following the target.
inline constexpr std::uint16_t kModeSpecific12 = 0x1000;
/// Masks CiA 402 gives for recognising a state: 0x4F for the states without quick stop
/// meaning (not ready, switch on disabled, fault reaction, fault), 0x6F for the others.
inline constexpr std::uint16_t kStateMaskShort = 0x004F;
inline constexpr std::uint16_t kStateMaskLong = 0x006F;
}  // namespace statusword

/// The state a statusword reports; nullopt for a pattern CiA 402 does not define.
constexpr std::optional<State> StateOf(std::uint16_t sw) {
  using namespace statusword;
  switch (sw & kStateMaskShort) {
    case 0x0000:
      return State::kNotReadyToSwitchOn;
    case 0x0040:
      return State::kSwitchOnDisabled;
    case 0x000F:
      return State::kFaultReactionActive;
    case 0x0008:
      return State::kFault;
    default:
      break;
  }
  switch (sw & kStateMaskLong) {
    case 0x0021:
      return State::kReadyToSwitchOn;
    case 0x0023:
      return State::kSwitchedOn;
    case 0x0027:
      return State::kOperationEnabled;
    case 0x0007:
      return State::kQuickStopActive;
    default:
      break;
  }
  return std::nullopt;
}

constexpr const char* StateName(State s) {
  switch (s) {
    case State::kNotReadyToSwitchOn:
      return "not_ready_to_switch_on";
    case State::kSwitchOnDisabled:
      return "switch_on_disabled";
    case State::kReadyToSwitchOn:
      return "ready_to_switch_on";
    case State::kSwitchedOn:
      return "switched_on";
    case State::kOperationEnabled:
      return "operation_enabled";
    case State::kQuickStopActive:
      return "quick_stop_active";
    case State::kFaultReactionActive:
      return "fault_reaction_active";
    case State::kFault:
      return "fault";
  }
  return "?";
}

/// Controlword commands (bits 0..3 and 7; bits 4..6, 8 are mode specific and left 0).
namespace controlword {
inline constexpr std::uint16_t kDisableVoltage = 0x0000;
inline constexpr std::uint16_t kQuickStop = 0x0002;
inline constexpr std::uint16_t kShutdown = 0x0006;
inline constexpr std::uint16_t kSwitchOn = 0x0007;  ///< Also "disable operation".
inline constexpr std::uint16_t kEnableOperation = 0x000F;
inline constexpr std::uint16_t kFaultReset = 0x0080;  ///< Acts on its 0 -> 1 edge.
}  // namespace controlword

/// Modes of operation 0x6060 / 0x6061.
namespace mode {
inline constexpr std::int8_t kProfileVelocity = 3;
inline constexpr std::int8_t kCyclicSyncVelocity = 9;
}  // namespace mode

/// EMCY error codes a drive sends (CiA 301 / CiA 402 table of error codes).
namespace emcy {
inline constexpr std::uint16_t kOverCurrent = 0x2310;  ///< Continuous over-current.
inline constexpr std::uint16_t kHeartbeat = 0x8130;    ///< Life guard / heartbeat error.
inline constexpr std::uint16_t kRpdoTimeout = 0x8250;  ///< RPDO timeout.
}  // namespace emcy

}  // namespace wheelhil::bus::cia402
