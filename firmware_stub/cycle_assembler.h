#pragma once
/// Groups the input frames of one SYNC cycle so the estimator steps exactly once per cycle, as
/// soon as the cycle's data is in (event-driven: it keeps pace with an emulator that waits for
/// the firmware's outputs, and with wall-clock time on a real bus). Pure state machine in time
/// (integer ns, any monotonic clock); no I/O.
///
/// Cycle k opens at SYNC k. Its data:
///  - synchronous inputs: one TPDO1 from each expected encoder node, sent in answer to SYNC k;
///  - asynchronous inputs (yaw rate, accelerometers): every sample received since SYNC k-1, i.e.
///    the sampling interval that SYNC k ends (the encoder readings at SYNC k close the same
///    interval).
/// Cycle k closes (and is returned exactly once) at the first of: every expected TPDO present
/// (kComplete); SYNC k+1 (kNextSync); sync_ns + deadline (kDeadline, via Poll). A cycle that
/// closes incomplete lists its missing nodes in `missing_mask`.
/// Tolerated traffic: a TPDO for a node already present in the open cycle is a duplicate
/// (counted, first one kept); a TPDO when no cycle is open is late (counted, dropped; if the
/// node was present in the last closed cycle it counts as a duplicate); frames are accepted in
/// any order within a cycle. There is no cycle number in a TPDO, so a frame delayed past the next
/// SYNC counts for that next cycle; the estimators use absolute counter readings, so a
/// misattributed reading shifts a step's timing but loses no travel. Encoder counter wrap is
/// handled downstream (EncoderIncrement); the cycle index is 64-bit.
/// Thread-compatible; no allocation after construction.

#include <array>
#include <cstdint>
#include <optional>
#include <vector>

namespace wheelhil::fw {

struct CycleAssemblerConfig {
  std::vector<std::uint8_t> tpdo_nodes;  ///< Encoder node ids, at most kMaxNodes, distinct.
  std::int64_t deadline_ns = 0;          ///< > 0: close a cycle this long after its SYNC; 0: never.
};

struct EncoderReading {
  bool present = false;
  std::uint32_t position = 0;  ///< 0x6004, raw counts.
  std::int16_t speed = 0;      ///< 0x6030:1, raw.
  std::int64_t t_ns = 0;       ///< Receive time.
};

struct AssembledCycle {
  static constexpr std::size_t kMaxNodes = 8;
  enum class Close : std::uint8_t { kComplete, kNextSync, kDeadline };

  std::uint64_t index = 0;       ///< 0 for the first SYNC seen, +1 per SYNC.
  std::int64_t sync_ns = 0;      ///< Time of this cycle's SYNC.
  std::int64_t interval_ns = 0;  ///< sync_ns - previous SYNC (0 for the first cycle).
  std::array<EncoderReading, kMaxNodes> encoders{};  ///< In tpdo_nodes order.
  std::uint32_t missing_mask = 0;                    ///< Bit i: encoders[i] missing.
  Close close = Close::kComplete;
  // Asynchronous samples of the interval ending at this SYNC.
  std::uint32_t yaw_samples = 0;
  double yaw_rate_sum_rad_s = 0.0;
  std::uint32_t accel_samples = 0;
  std::array<double, 4> accel_sum_m_s2{};

  bool complete() const { return missing_mask == 0; }
};

class CycleAssembler {
 public:
  /// Throws std::invalid_argument on too many or repeated nodes, or deadline_ns < 0.
  explicit CycleAssembler(const CycleAssemblerConfig& config);

  /// A SYNC at t_ns (sent by us or seen on the bus). Returns the cycle it closes, if one was
  /// still open (kNextSync). Opens the next cycle.
  std::optional<AssembledCycle> OnSync(std::int64_t t_ns);
  /// A TPDO1 of `node_id`. Returns the open cycle when this frame completes it.
  std::optional<AssembledCycle> OnTpdo(std::uint8_t node_id, std::uint32_t position,
                                       std::int16_t speed, std::int64_t t_ns);
  void OnYawRate(double rate_rad_s, std::int64_t t_ns);
  void OnAccel(const std::array<double, 4>& a_m_s2, std::int64_t t_ns);
  /// Closes the open cycle when its deadline has passed (kDeadline).
  std::optional<AssembledCycle> Poll(std::int64_t t_ns);

  /// Deadline of the open cycle (INT64_MAX when none is open).
  std::int64_t NextDeadlineNs() const;
  bool cycle_open() const { return open_; }

  std::uint64_t cycles_closed() const { return closed_; }
  std::uint64_t incomplete_cycles() const { return incomplete_; }
  std::uint64_t duplicates() const { return duplicates_; }
  std::uint64_t late_frames() const { return late_; }
  std::uint64_t unexpected_nodes() const { return unexpected_; }

 private:
  AssembledCycle Close(AssembledCycle::Close why);
  int Slot(std::uint8_t node_id) const;

  CycleAssemblerConfig config_;
  std::uint32_t all_mask_ = 0;
  bool open_ = false;
  bool any_sync_ = false;
  AssembledCycle cur_;
  AssembledCycle bucket_;  // Async samples of the interval running now.
  std::uint32_t last_closed_present_ = 0;
  std::int64_t last_sync_ns_ = 0;
  std::uint64_t next_index_ = 0;
  std::uint64_t closed_ = 0, incomplete_ = 0, duplicates_ = 0, late_ = 0, unexpected_ = 0;
};

}  // namespace wheelhil::fw
