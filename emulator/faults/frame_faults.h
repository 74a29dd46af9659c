#pragma once
/// Frame faults: a filter between a device's output (NodeFrame: frame + due instant) and the
/// bus. Each fault selects frames by (id & mask) == (fault id & mask), the same frame format
/// (standard/extended), and its window [t0, t1) on the frame's due instant:
///   kDrop           the frame is not sent, with probability `probability` (seeded RNG);
///   kDelay          the frame becomes due delay_ns later (held by the filter until then);
///   kDuplicate      a second copy follows, due delay_ns after the first (with probability);
///   kCorrupt        bit_flips distinct bits of the (first 8) payload bytes flipped at random
///                   (with probability);
///   kWrongCounter   the DBC counter signal re-encoded as (counter + counter_offset) mod 2^n
///                   (default -1: the previous counter repeated), then the checksum signal
///                   re-computed when one is named, so only the counter is wrong;
///   kWrongChecksum  the DBC checksum signal re-encoded as (checksum + 1) mod 2^n;
///   kWrongDlc       the frame's length set to `dlc` (0..8; bytes beyond the old length zero).
/// Faults apply in their list order; a dropped frame meets no later fault. Counter/checksum
/// faults find the frame's message in the DBC database (by id); frames it does not describe are
/// passed unchanged and counted as unapplied. Randomness: one std::mt19937_64 seeded with `seed`,
/// drawn only for frames a random fault selects: same seed and frames -> same output.
/// Start/end of each window go to the log (category "frame"). Thread-compatible.

#include <cstdint>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <string_view>
#include <vector>

#include "bus/dbc.h"
#include "emulator/devices/canopen_encoder_node.h"
#include "emulator/devices/frame_checksum.h"
#include "emulator/faults/fault_event.h"

namespace wheelhil::emulator {

enum class FrameFaultKind : std::uint8_t {
  kDrop,
  kDelay,
  kDuplicate,
  kCorrupt,
  kWrongCounter,
  kWrongChecksum,
  kWrongDlc,
};

/// "drop", "delay", "duplicate", "corrupt", "wrong_counter", "wrong_checksum", "wrong_dlc".
std::optional<FrameFaultKind> ParseFrameFaultKind(std::string_view name) noexcept;
std::string_view FrameFaultKindName(FrameFaultKind kind) noexcept;

struct FrameFault {
  FrameFaultKind kind = FrameFaultKind::kDrop;
  FaultWindow window;
  std::uint32_t id = 0;
  std::uint32_t mask = 0x7FF;  ///< 0x7FF: exactly `id` (standard); 0: every frame.
  bool extended = false;
  double probability = 1.0;          ///< kDrop / kDuplicate / kCorrupt: chance per selected frame.
  std::int64_t delay_ns = 0;         ///< kDelay: added latency; kDuplicate: gap to the copy (>= 0).
  int bit_flips = 1;                 ///< kCorrupt: bits flipped per frame (1..8*len).
  std::uint8_t dlc = 0;              ///< kWrongDlc: the length sent (0..8).
  std::string counter_signal;        ///< kWrongCounter.
  std::int64_t counter_offset = -1;  ///< kWrongCounter: added to the counter (non-zero).
  std::string checksum_signal;       ///< kWrongChecksum; kWrongCounter: re-computed if set.
  ChecksumKind checksum = ChecksumKind::kXor;  ///< Algorithm for the re-computation.
};

class FrameFaultFilter {
 public:
  /// `dbc` is needed only for counter/checksum faults (may be null otherwise). Throws
  /// std::invalid_argument ("frame_faults[i].field: problem") on a bad parameter.
  FrameFaultFilter(std::vector<FrameFault> faults, std::shared_ptr<const bus::DbcDatabase> dbc,
                   std::uint64_t seed, FaultEventLog* log = nullptr);

  /// Filters the frames a node produced (any order) and returns, sorted by due instant (stable),
  /// every frame due at or before t_ns: the passed/modified ones and delayed ones released now.
  /// Frames that become due later (delay, a duplicate's copy) are held for a later call.
  std::vector<NodeFrame> Process(const std::vector<NodeFrame>& in, std::int64_t t_ns);
  /// Frames each fault acted on (index = position in the fault list).
  std::uint64_t affected(std::size_t fault_index) const { return states_[fault_index].affected; }
  std::uint64_t unapplied() const { return unapplied_; }

 private:
  struct State {
    FrameFault fault;
    faults_internal::WindowPhase phase;
    std::string target;
    std::uint64_t affected = 0;
  };
  bool Selects(const State& s, const NodeFrame& f) const;
  /// Runs every fault on one frame; appends the results (0..n frames) to out.
  void Filter(NodeFrame f, std::vector<NodeFrame>& out);
  bool Chance(double p);

  std::vector<State> states_;
  std::shared_ptr<const bus::DbcDatabase> dbc_;
  std::mt19937_64 rng_;
  FaultEventLog* log_;
  std::vector<NodeFrame> held_;
  std::uint64_t unapplied_ = 0;
};

}  // namespace wheelhil::emulator
