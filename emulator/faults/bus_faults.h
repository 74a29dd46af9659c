#pragma once
/// Bus faults around one CanBusModel, over a window [t0, t1):
///   kErrorBurst  `error_frames` error frames right after t0: the bus is unavailable to every node
///                while they last. Model: each error frame is a zero-length id-0x000 blocker
///                frame sent by a hidden top-priority node (it wins the next arbitration after t0
///                and those after it; the frame in progress at t0 completes - CanBusModel cannot
///                abort a frame, so the destroyed-and-retransmitted frame of a real bus is not
///                modelled) and is reported as a SocketCAN error frame (CanFrame.error, id =
///                CAN_ERR_PROT | CAN_ERR_BUSERROR = 0x88, len 8) completing when the blocker would.
///                A blocker occupies 53 bit times (exact stuffing), a real error frame 17..23
///                bits plus the interframe space: the burst is modelled longer than on a real bus.
///   kBusOff      node `node` is bus-off: frames it queues (ready instant) in the window are
///                discarded (frames queued before t0 still go out).
///   kFlood       a hidden node sends `flood_len`-byte frames on `flood_id` (default 0x001: beats
///                every CANopen and sensor id but 0x000 NMT) every period such that the flood's
///                own frames take `load` (0..1] of the bus time: period = bits * T_bit / load.
///                Flood frames appear in the wire output like any frame.
/// Start/end go to the log (category "bus"). Thread-compatible.

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "emulator/devices/can_bus_model.h"
#include "emulator/faults/fault_event.h"

namespace wheelhil::emulator {

enum class BusFaultKind : std::uint8_t { kErrorBurst, kBusOff, kFlood };

/// "error_burst", "bus_off", "flood".
std::optional<BusFaultKind> ParseBusFaultKind(std::string_view name) noexcept;
std::string_view BusFaultKindName(BusFaultKind kind) noexcept;

struct BusFault {
  BusFaultKind kind = BusFaultKind::kErrorBurst;
  FaultWindow window;
  int error_frames = 1;            ///< kErrorBurst: 1..1000.
  int node = -1;                   ///< kBusOff: bus node index (CanBusModel::AddNode).
  std::string node_name;           ///< kBusOff: for the log.
  double load = 0.5;               ///< kFlood: (0, 1].
  std::uint32_t flood_id = 0x001;  ///< kFlood: standard id.
  std::uint8_t flood_len = 8;      ///< kFlood: 0..8.
};

/// SocketCAN error class bits an error-burst frame carries (linux/can/error.h).
inline constexpr std::uint32_t kCanErrProt = 0x00000008U;
inline constexpr std::uint32_t kCanErrBusError = 0x00000080U;

class FaultyCanBus {
 public:
  /// Adds the hidden error/flood nodes to `bus` (after the device nodes, so the device nodes
  /// keep their indices). `stuffing` must be the bus's stuffing mode (flood period). Throws
  /// std::invalid_argument ("bus_faults[i].field: problem"). `bus` must outlive this object.
  FaultyCanBus(CanBusModel& bus, std::vector<BusFault> faults,
               StuffingMode stuffing = StuffingMode::kExact, FaultEventLog* log = nullptr);
  /// `other` in its present state, around `bus` (a copy of other's bus model).
  FaultyCanBus(const FaultyCanBus& other, CanBusModel& bus);
  FaultyCanBus(const FaultyCanBus&) = delete;
  FaultyCanBus& operator=(const FaultyCanBus&) = delete;

  /// CanBusModel::Enqueue unless the node is bus-off at ready_ns (then false, counted).
  [[nodiscard]] bool Enqueue(int node, const bus::CanFrame& frame, std::int64_t ready_ns) noexcept;
  /// Generates the flood / error frames due before t_ns and runs the bus to t_ns; error-burst
  /// blockers come back as error frames.
  std::vector<WireFrame> AdvanceTo(std::int64_t t_ns);

  std::uint64_t dropped_bus_off() const { return dropped_bus_off_; }
  std::uint64_t flood_frames() const { return flood_frames_; }
  std::uint64_t error_frames() const { return error_frames_; }
  int flood_node() const { return flood_node_; }
  int error_node() const { return error_node_; }

 private:
  struct State {
    BusFault fault;
    faults_internal::WindowPhase phase;
    std::int64_t period_ns = 0;  ///< kFlood.
    std::int64_t next_ns = 0;    ///< kFlood: next frame; kErrorBurst: INT64_MAX once queued.
    std::string target;
  };
  void Generate(std::int64_t t_ns);

  CanBusModel& bus_;
  std::vector<State> states_;
  FaultEventLog* log_;
  int flood_node_ = -1;
  int error_node_ = -1;
  std::uint64_t dropped_bus_off_ = 0;
  std::uint64_t flood_frames_ = 0;
  std::uint64_t error_frames_ = 0;
};

}  // namespace wheelhil::emulator
