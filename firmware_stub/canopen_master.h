#pragma once
/// The firmware's CANopen master (CiA 301 subset) as a pure state machine in time (integer ns of
/// any monotonic clock): no sockets, no threads. Feed it every frame off the bus with OnFrame and
/// call Poll regularly (at least at NextEventNs()); Poll returns the frames to send.
///
/// Start-up, per node: wait for its boot-up message (0x700+id [00]; a heartbeat also shows the
/// node is there) up to boot_timeout -> configure by expedited SDO download (0x1800:2 TPDO1
/// transmission type, u8; 0x1017 producer heartbeat time, u16 ms; each only when configured;
/// then the node's own writes of CanopenMasterConfig::node_writes, e.g. a drive's mode) ->
/// NMT start (0x000 [01 id]) -> operational. A node whose boot-up never comes gets the fault
/// kFaultBootTimeout and the rest goes on; if it boots later it is configured and started then.
/// A boot-up at any time (node reset) restarts that node's sequence. An SDO abort or an SDO that
/// stays unanswered after the retries sets kFaultSdo and the sequence continues with the next
/// step (a node that cannot be configured is still started: degrade, not die).
/// Supervision: heartbeat consumer per node (no heartbeat for heartbeat_timeout -> node lost,
/// kFaultNodeLost; cleared when heartbeats return); a heartbeat reporting pre-operational
/// after start re-sends NMT start; EMCY with a non-zero code sets kFaultEmcy for the node until
/// its error-reset EMCY (code 0).
/// SYNC (0x080) is produced every sync_period once start-up is over (every node operational,
/// missing or given up), when produce_sync; the first one a period after the last NMT start. Poll
/// reports each SYNC it emits (sync_sent). Thread-compatible.

#include <cstdint>
#include <vector>

#include "bus/can_frame.h"
#include "firmware_stub/fw_protocol.h"

namespace wheelhil::fw {

/// Fault bits (status frame FW_Status and the firmware's state), shared by master and app.
enum FaultBit : std::uint32_t {
  kFaultBootTimeout = 1u << 0,      ///< A node's boot-up did not come in time.
  kFaultNodeLost = 1u << 1,         ///< Heartbeat consumer timeout.
  kFaultEmcy = 1u << 2,             ///< An EMCY with a non-zero error code is active.
  kFaultSdo = 1u << 3,              ///< An SDO was aborted or timed out.
  kFaultBadFrame = 1u << 4,         ///< Wrong DLC, unknown id, undecodable frame seen.
  kFaultCycleIncomplete = 1u << 5,  ///< A cycle closed with inputs missing.
  kFaultLateFrame = 1u << 6,        ///< Late or duplicated input frame.
  kFaultEstimator = 1u << 7,        ///< The estimator rejected a sample / could not step.
  kFaultConfig = 1u << 8,           ///< Reserved: the configuration could not be applied.
};

/// One expedited SDO download to one node at start-up.
struct NodeSdoWrite {
  std::uint8_t node_id = 0;
  std::uint16_t index = 0;
  std::uint8_t subindex = 0;
  std::uint32_t value = 0;
  std::uint8_t size = 1;  ///< Bytes, 1..4.
};

struct CanopenMasterConfig {
  std::vector<std::uint8_t> node_ids;     ///< 1..127, distinct.
  std::vector<NodeSdoWrite> node_writes;  ///< After the common steps, in order, per node.
  std::int64_t boot_timeout_ns = 2'000'000'000;
  std::uint16_t heartbeat_producer_ms = 100;        ///< Written to 0x1017; 0 = not written.
  std::int64_t heartbeat_timeout_ns = 350'000'000;  ///< 0 = no supervision.
  std::int64_t sdo_timeout_ns = 100'000'000;
  int sdo_retries = 2;
  std::uint8_t tpdo_transmission_type = 1;  ///< Written to 0x1800:2; 0 = not written.
  bool reset_communication_at_start = false;
  bool produce_sync = true;
  std::int64_t sync_period_ns = 10'000'000;
};

class CanopenMaster {
 public:
  enum class NodeState : std::uint8_t {
    kWaitBoot,     ///< Waiting for the boot-up message.
    kMissing,      ///< Boot timeout passed without it (kFaultBootTimeout).
    kConfiguring,  ///< SDO downloads in progress.
    kOperational,  ///< NMT start sent.
  };

  struct NodeStatus {
    std::uint8_t node_id = 0;
    NodeState state = NodeState::kWaitBoot;
    bool lost = false;         ///< Heartbeat consumer timeout.
    bool emcy_active = false;  ///< Last EMCY had a non-zero code.
    std::uint16_t last_emcy_code = 0;
    std::uint8_t last_heartbeat_state = 0xFF;
    std::int64_t last_heartbeat_ns = 0;
    std::uint32_t sdo_failures = 0;
    std::uint32_t boot_count = 0;
  };

  struct PollResult {
    std::vector<bus::CanFrame> frames;  ///< To send, in order.
    bool sync_sent = false;             ///< One of `frames` is the SYNC of a new cycle.
  };

  /// Throws std::invalid_argument on a bad config. `protocol` must outlive the master.
  CanopenMaster(const CanopenMasterConfig& config, const FwProtocol& protocol);

  /// Begins the start-up at t_ns (first Poll sends the optional reset-communication).
  void Start(std::int64_t t_ns);

  /// A frame off the bus at t_ns; returns true when the master consumed it (boot-up, heartbeat,
  /// EMCY, SDO response for one of its nodes). Malformed frames of those kinds count as bad.
  bool OnFrame(const bus::CanFrame& frame, std::int64_t t_ns);

  /// Timed work due at or before t_ns: SDO timeouts, boot timeout, heartbeat supervision,
  /// SYNC production. t_ns must not go backwards.
  PollResult Poll(std::int64_t t_ns);

  /// Next instant Poll has something to do (INT64_MAX if nothing).
  std::int64_t NextEventNs() const;

  /// The start-up phase is over: each node is operational or missing.
  bool started() const;
  /// OR of the FaultBit values currently active.
  std::uint32_t faults() const;
  /// Bit (i) set: node_ids[i] is lost or missing.
  std::uint32_t nodes_lost_mask() const;
  const std::vector<NodeStatus>& nodes() const { return nodes_; }
  std::uint64_t bad_frames() const { return bad_frames_; }
  std::uint64_t syncs_sent() const { return syncs_sent_; }

 private:
  struct SdoStep {
    std::uint16_t index;
    std::uint8_t subindex;
    std::uint32_t value;
    std::uint8_t size;
  };
  struct NodeRun {
    std::vector<SdoStep> steps;
    std::size_t next_step = 0;
    bool sdo_pending = false;
    std::int64_t sdo_deadline_ns = 0;
    int sdo_attempts = 0;
    bool send_now = false;   ///< Send the current step at the next Poll.
    bool start_now = false;  ///< Send NMT start at the next Poll.
  };

  void Boot(std::size_t i, std::int64_t t_ns);
  void SendStep(std::size_t i, std::vector<bus::CanFrame>& out);
  void NextStep(std::size_t i);
  int IndexOf(std::uint8_t node_id) const;

  CanopenMasterConfig config_;
  const FwProtocol& protocol_;
  std::vector<NodeStatus> nodes_;
  std::vector<NodeRun> runs_;
  bool running_ = false;
  bool reset_pending_ = false;
  std::int64_t start_ns_ = 0;
  std::int64_t next_sync_ns_ = 0;
  bool sync_started_ = false;
  std::uint64_t bad_frames_ = 0;
  std::uint64_t syncs_sent_ = 0;
  bool sdo_fault_ = false;
};

}  // namespace wheelhil::fw
