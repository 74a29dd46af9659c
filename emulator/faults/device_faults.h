#pragma once
/// Device faults for one node, over a window [t0, t1):
///   kSilent         the node sends nothing (it still receives and keeps its state);
///   kHeartbeatLost  only its heartbeats (0x700+id, state byte != 0) are not sent;
///   kReboot         power cycle: off over [t0, t1) (t1 = t0 + 1 ns for an instant reboot),
///                   powered on again at t1 -> boot-up after the power-on delay, every
///                   parameter back to its configured default (a CiA 406 node is rebuilt);
///   kEmcy           device fault: RaiseFault(emcy_code, error_register) at t0 (EMCY on
///                   0x080+id), ClearFault at t1 (error-reset EMCY) unless t1 = kForever.
/// FilterOutputs works for any node's frames (NodeFrame.due_ns decides); ApplyTo performs the
/// reboot and EMCY actions on a CanopenEncoderNode and must be called with t_ns at or after
/// NextActionNs() before the node is polled for that instant. Start/end go to the event log
/// (category "device"). Thread-compatible.

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "emulator/devices/canopen_encoder_node.h"
#include "emulator/faults/fault_event.h"

namespace wheelhil::emulator {

enum class DeviceFaultKind : std::uint8_t { kSilent, kHeartbeatLost, kReboot, kEmcy };

/// "silent", "heartbeat_lost", "reboot", "emcy".
std::optional<DeviceFaultKind> ParseDeviceFaultKind(std::string_view name) noexcept;
std::string_view DeviceFaultKindName(DeviceFaultKind kind) noexcept;

struct DeviceFault {
  DeviceFaultKind kind = DeviceFaultKind::kSilent;
  FaultWindow window;
  std::uint16_t emcy_code = 0x7305;    ///< kEmcy: CiA 406 incremental sensor 1 fault.
  std::uint8_t error_register = 0x01;  ///< kEmcy: 0x1001 generic error.
};

class DeviceFaultInjector {
 public:
  /// `node_name` names the target in the log; node_id (1..127) identifies its heartbeats.
  /// Throws std::invalid_argument on a bad window or node id.
  DeviceFaultInjector(std::string node_name, std::uint8_t node_id, std::vector<DeviceFault> faults,
                      FaultEventLog* log = nullptr);

  /// Removes the frames the node must not send (silent, heartbeat lost, off while rebooting).
  void FilterOutputs(std::vector<NodeFrame>& frames);
  /// True when a frame the node sends at t_ns would be suppressed entirely (silent / off).
  bool SilentAt(std::int64_t t_ns) const;

  /// Records the start/end events due at or before t_ns (FilterOutputs and ApplyTo do this too;
  /// call it for a node that may produce no frame at all).
  void AdvanceTo(std::int64_t t_ns) { Track(t_ns); }

  /// Earliest pending reboot/EMCY action instant (INT64_MAX if none).
  std::int64_t NextActionNs() const;
  /// Performs every reboot / EMCY action due at or before t_ns on `node` (rebuilt from
  /// `config` and `codec` for a reboot). Returns the number of actions performed.
  int ApplyTo(CanopenEncoderNode& node, const Cia406NodeConfig& config,
              const std::shared_ptr<const Cia406Codec>& codec, std::int64_t t_ns);

  std::uint64_t suppressed_frames() const { return suppressed_; }

 private:
  struct State {
    DeviceFault fault;
    faults_internal::WindowPhase phase;
    bool start_done = false;
    bool end_done = false;
  };
  void Track(std::int64_t t_ns);

  std::string node_name_;
  std::uint8_t node_id_;
  std::vector<State> faults_;
  FaultEventLog* log_;
  std::uint64_t suppressed_ = 0;
};

}  // namespace wheelhil::emulator
