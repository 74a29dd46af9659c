#pragma once
/// Timing model of one classic CAN bus (vcan has no bitrate; this is ours).
///
/// Frame length on the wire follows can-utils' `canframelen.c` (SOF to end of the 3-bit
/// interframe space, in bits, n = data bytes):
///   kNoStuffing   standard 47 + 8n, extended 67 + 8n (no stuff bits);
///   kWorstCase    can-utils' current CFL_WORSTCASE (Davis et al. 2007, "CAN schedulability
///                 analysis: refuted, revisited and revised"): of the 34 + 8n (standard) or
///                 54 + 8n (extended) stuffable bits, the first stuff bit after 5, then one
///                 every 4: 47 + 8n + floor((33 + 8n) / 4) = 55 + 10n standard,
///                 67 + 8n + floor((53 + 8n) / 4) = 80 + 10n extended;
///   kTindell      older can-utils CFL_WORSTCASE (Tindell 1994, one stuff bit per 5 bits, an
///                 underestimate): (269 + 48n) / 5 standard, (389 + 48n) / 5 extended;
///   kExact        the real stuff bits of this frame: the bit stream SOF..CRC (CRC-15, poly
///                 0x4599, over SOF..data) is built and a complementary bit is counted after
///                 every run of 5 equal bits (stuff bits start new runs), as canframelen's
///                 CFL_EXACT does. Remote frames carry no data field on the wire (the DLC is
///                 still sent); can-utils counts DLC data bytes for RTR frames, we do not.
/// CAN FD frames are not modelled (Enqueue rejects them).
///
/// Arbitration: whenever the bus is idle, every node whose head-of-queue frame is ready contends;
/// the lowest arbitration field wins, bit by bit, dominant 0: 11-bit base id, then RTR
/// (standard) / SRR = 1 (extended), then IDE (0 standard, 1 extended), then the 18 extension
/// bits and RTR of extended frames. So a standard data frame beats an extended frame with the
/// same base id, and a data frame beats a remote frame with the same id. Two nodes sending the
/// same arbitration field would collide on a real bus; here the lower node index wins.
/// Each node has its own transmit queue (FIFO like a socket's qdisc, or by priority like a
/// controller with many mailboxes) of bounded depth; a full queue rejects the frame (ENOBUFS).
///
/// Timestamps are integer ns of virtual time. A frame that wins at SOF instant s occupies
/// s .. s + bits * T_bit; its `complete_ns` (the log timestamp: the instant the frame is valid
/// for receivers, end of EOF) is s + (bits - 3) * T_bit, the bus is free again after the
/// 3-bit interframe space. Bus load = busy time (whole frames, IFS included) / elapsed time.
/// Thread-compatible.

#include <cstdint>
#include <deque>
#include <string>
#include <vector>

#include "bus/can_frame.h"

namespace wheelhil::emulator {

enum class StuffingMode { kNoStuffing, kTindell, kWorstCase, kExact };

/// Bits a classic frame needs on the wire, SOF to end of the 3-bit interframe space.
/// Returns 0 for frames this model does not cover (FD, error frames, invalid frames).
unsigned CanFrameBits(const bus::CanFrame& frame, StuffingMode mode) noexcept;

/// Arbitration key of a frame: lower wins. Bit layout (MSB first, 32 bits used): base id (11),
/// RTR/SRR, IDE, extension id (18), extended RTR.
std::uint32_t ArbitrationKey(const bus::CanFrame& frame) noexcept;

/// A frame as it went over the wire.
struct WireFrame {
  bus::CanFrame frame;
  int node = -1;                 ///< Sending node index.
  std::int64_t ready_ns = 0;     ///< Instant the frame was queued.
  std::int64_t start_ns = 0;     ///< SOF instant.
  std::int64_t complete_ns = 0;  ///< End of EOF: the log timestamp.
  unsigned bits = 0;             ///< Frame length incl. stuff bits and IFS.
};

struct CanBusConfig {
  std::uint32_t bitrate_bps = 1'000'000;  ///< 125 000 .. 1 000 000, T_bit must be whole ns.
  StuffingMode stuffing = StuffingMode::kExact;
};

class CanBusModel {
 public:
  enum class QueueOrder { kFifo, kPriority };

  /// Throws std::invalid_argument on a bitrate outside 125k..1M or with a fractional bit time.
  explicit CanBusModel(const CanBusConfig& config);

  /// Adds a transmitting node; returns its index (0, 1, ...).
  int AddNode(std::string name, QueueOrder order = QueueOrder::kFifo, std::size_t max_queue = 64);

  /// Queues a frame that becomes ready to send at ready_ns. Returns false (and counts the drop)
  /// for an unknown node, an invalid/FD/error frame, ready_ns before the last AdvanceTo instant,
  /// or a full queue.
  [[nodiscard]] bool Enqueue(int node, const bus::CanFrame& frame, std::int64_t ready_ns) noexcept;

  /// Runs the bus up to t_ns and returns the frames that completed in (last t, t_ns], in
  /// completion order. Frames whose SOF would be at or after t_ns stay queued (a frame queued
  /// later for the same instant can still take part in that arbitration).
  std::vector<WireFrame> AdvanceTo(std::int64_t t_ns);
  /// The same into `done` (cleared first): a caller that advances often keeps one buffer.
  void AdvanceTo(std::int64_t t_ns, std::vector<WireFrame>& done);

  /// The earliest instant at which the bus changes state other than its clock: the next SOF
  /// of a queued frame (with nothing enqueued meanwhile) or the next completion; INT64_MAX
  /// when idle with empty queues. AdvanceTo(t) with now < t < NextEventNs() only moves the
  /// clock to t (no frame starts, none is returned).
  std::int64_t NextEventNs() const;

  /// Runs until every queue is empty; returns all remaining frames.
  std::vector<WireFrame> Drain();

  std::int64_t bit_time_ns() const { return bit_time_ns_; }
  std::int64_t now_ns() const { return now_ns_; }
  /// Busy time (frames incl. IFS) that lies in [0, now] divided by now; 0 before any time passed.
  double BusLoad() const;
  /// Busy ns between 0 and now.
  std::int64_t busy_ns() const;
  std::uint64_t frames_sent() const { return frames_sent_; }
  std::uint64_t frames_dropped() const { return frames_dropped_; }
  /// Longest queueing delay (SOF minus ready) seen so far.
  std::int64_t max_queue_delay_ns() const { return max_queue_delay_ns_; }

 private:
  struct Pending {
    bus::CanFrame frame;
    std::int64_t ready_ns;
    std::uint64_t seq;
  };
  struct Node {
    std::string name;
    QueueOrder order;
    std::size_t max_queue;
    std::deque<Pending> queue;
  };

  /// Starts transmissions with SOF < limit_ns; appends them to in_flight_.
  void Schedule(std::int64_t limit_ns);
  /// Index in n.queue of the frame the node would send at SOF instant s, or -1.
  static std::ptrdiff_t HeadAt(const Node& n, std::int64_t s);
  /// Earliest instant any of the node's frames is ready (INT64_MAX when empty).
  static std::int64_t EarliestReady(const Node& n);

  CanBusConfig config_;
  std::int64_t bit_time_ns_;
  std::vector<Node> nodes_;
  std::deque<WireFrame> in_flight_;  ///< Scheduled, not yet reported (completion order).
  std::int64_t bus_free_ns_ = 0;
  std::int64_t now_ns_ = 0;
  std::int64_t busy_ns_total_ = 0;  ///< Sum of whole scheduled frames.
  std::uint64_t seq_ = 0;
  std::uint64_t frames_sent_ = 0;
  std::uint64_t frames_dropped_ = 0;
  std::int64_t max_queue_delay_ns_ = 0;
};

}  // namespace wheelhil::emulator
