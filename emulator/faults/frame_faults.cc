#include "emulator/faults/frame_faults.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <fmt/format.h>

#include "bus/dbc_codec.h"

namespace wheelhil::emulator {

std::optional<FrameFaultKind> ParseFrameFaultKind(std::string_view name) noexcept {
  for (auto k : {FrameFaultKind::kDrop, FrameFaultKind::kDelay, FrameFaultKind::kDuplicate,
                 FrameFaultKind::kCorrupt, FrameFaultKind::kWrongCounter,
                 FrameFaultKind::kWrongChecksum, FrameFaultKind::kWrongDlc}) {
    if (FrameFaultKindName(k) == name) return k;
  }
  return std::nullopt;
}

std::string_view FrameFaultKindName(FrameFaultKind kind) noexcept {
  switch (kind) {
    case FrameFaultKind::kDrop:
      return "drop";
    case FrameFaultKind::kDelay:
      return "delay";
    case FrameFaultKind::kDuplicate:
      return "duplicate";
    case FrameFaultKind::kCorrupt:
      return "corrupt";
    case FrameFaultKind::kWrongCounter:
      return "wrong_counter";
    case FrameFaultKind::kWrongChecksum:
      return "wrong_checksum";
    case FrameFaultKind::kWrongDlc:
      return "wrong_dlc";
  }
  return "?";
}

FrameFaultFilter::FrameFaultFilter(std::vector<FrameFault> faults,
                                   std::shared_ptr<const bus::DbcDatabase> dbc, std::uint64_t seed,
                                   FaultEventLog* log)
    : dbc_(std::move(dbc)), rng_(seed), log_(log) {
  for (std::size_t i = 0; i < faults.size(); ++i) {
    const FrameFault& f = faults[i];
    const std::string field = fmt::format("frame_faults[{}]", i);
    auto fail = [&](std::string_view what) {
      throw std::invalid_argument(fmt::format("{}.{}", field, what));
    };
    if (!f.window.IsValid()) fail("window: must have 0 <= t0 < t1");
    if (!(f.probability >= 0.0 && f.probability <= 1.0)) fail("probability: must be in [0, 1]");
    if (f.delay_ns < 0) fail("delay_ns: must be >= 0");
    if (f.kind == FrameFaultKind::kCorrupt && (f.bit_flips < 1 || f.bit_flips > 64)) {
      fail("bit_flips: must be in 1..64");
    }
    if (f.kind == FrameFaultKind::kWrongDlc && f.dlc > 8) fail("dlc: must be in 0..8");
    if (f.kind == FrameFaultKind::kWrongCounter) {
      if (f.counter_signal.empty()) fail("counter_signal: required");
      if (f.counter_offset == 0) fail("counter_offset: must not be 0");
    }
    if (f.kind == FrameFaultKind::kWrongChecksum && f.checksum_signal.empty()) {
      fail("checksum_signal: required");
    }
    if ((f.kind == FrameFaultKind::kWrongCounter || f.kind == FrameFaultKind::kWrongChecksum) &&
        !dbc_) {
      fail("kind: counter/checksum faults need the DBC database");
    }
    const std::uint32_t max_id =
        f.extended ? bus::CanFrame::kMaxExtendedId : bus::CanFrame::kMaxStandardId;
    if (f.id > max_id || f.mask > max_id) fail("id/mask: beyond the identifier range");
    State s{
        f, {}, fmt::format("id 0x{:X} mask 0x{:X}{}", f.id, f.mask, f.extended ? " ext" : ""), 0};
    states_.push_back(std::move(s));
  }
}

bool FrameFaultFilter::Selects(const State& s, const NodeFrame& f) const {
  const FrameFault& x = s.fault;
  return !f.frame.error && f.frame.extended == x.extended &&
         (f.frame.id & x.mask) == (x.id & x.mask) && x.window.Contains(f.due_ns);
}

bool FrameFaultFilter::Chance(double p) {
  if (p >= 1.0) return true;
  if (p <= 0.0) return false;
  return std::uniform_real_distribution<double>(0.0, 1.0)(rng_) < p;
}

void FrameFaultFilter::Filter(NodeFrame f, std::vector<NodeFrame>& out) {
  std::vector<NodeFrame> extra;
  for (State& s : states_) {
    s.phase.Advance(f.due_ns, s.fault.window, log_, "frame", FrameFaultKindName(s.fault.kind),
                    s.target, "");
    if (!Selects(s, f)) continue;
    const FrameFault& x = s.fault;
    bus::CanFrame& fr = f.frame;
    const std::span<std::uint8_t> payload(fr.data.data(), fr.len);
    switch (x.kind) {
      case FrameFaultKind::kDrop:
        if (Chance(x.probability)) {
          ++s.affected;
          return;
        }
        break;
      case FrameFaultKind::kDelay:
        f.due_ns += x.delay_ns;
        ++s.affected;
        break;
      case FrameFaultKind::kDuplicate:
        if (Chance(x.probability)) {
          NodeFrame copy = f;
          copy.due_ns += x.delay_ns;
          extra.push_back(copy);
          ++s.affected;
        }
        break;
      case FrameFaultKind::kCorrupt: {
        if (fr.len == 0 || !Chance(x.probability)) break;
        // Classic payload bits (the first 8 bytes of a longer FD payload).
        const int bits = 8 * std::min<int>(fr.len, 8);
        const int flips = std::min(x.bit_flips, bits);
        std::uint64_t used = 0;  // bits already flipped (<= 64 payload bits)
        for (int i = 0; i < flips;) {
          const int b = std::uniform_int_distribution<int>(0, bits - 1)(rng_);
          if (used & (1ULL << b)) continue;
          used |= 1ULL << b;
          fr.data[static_cast<std::size_t>(b / 8)] ^= static_cast<std::uint8_t>(1u << (b % 8));
          ++i;
        }
        ++s.affected;
        break;
      }
      case FrameFaultKind::kWrongCounter:
      case FrameFaultKind::kWrongChecksum: {
        const bus::DbcMessage* msg = dbc_->FindMessage(fr.id, fr.extended);
        const bool counter = x.kind == FrameFaultKind::kWrongCounter;
        const bus::DbcSignal* sig =
            msg ? msg->FindSignal(counter ? x.counter_signal : x.checksum_signal) : nullptr;
        const bus::DbcSignal* checksum = counter && msg && !x.checksum_signal.empty()
                                             ? msg->FindSignal(x.checksum_signal)
                                             : nullptr;
        std::uint64_t raw = 0;
        if (!sig || !bus::ExtractRaw(*sig, payload, raw) ||
            (counter && !x.checksum_signal.empty() && !checksum)) {
          ++unapplied_;
          break;
        }
        const std::uint64_t mask = sig->length >= 64 ? ~0ULL : ((1ULL << sig->length) - 1);
        const std::int64_t delta = counter ? x.counter_offset : 1;
        bus::InsertRaw(*sig, (raw + static_cast<std::uint64_t>(delta)) & mask, payload);
        if (checksum) WriteChecksum(x.checksum, *checksum, payload);
        ++s.affected;
        break;
      }
      case FrameFaultKind::kWrongDlc:
        for (std::size_t i = fr.len; i < bus::CanFrame::kMaxClassicLen; ++i) fr.data[i] = 0;
        fr.len = x.dlc;
        ++s.affected;
        break;
    }
  }
  out.push_back(f);
  // A duplicate's copy is taken when the duplicate fault acts: later faults touch the original.
  for (NodeFrame& e : extra) out.push_back(e);
}

std::vector<NodeFrame> FrameFaultFilter::Process(const std::vector<NodeFrame>& in,
                                                 std::int64_t t_ns) {
  for (const NodeFrame& f : in) Filter(f, held_);
  // Windows that started/ended with no frame in them are still recorded.
  for (State& s : states_) {
    s.phase.Advance(t_ns, s.fault.window, log_, "frame", FrameFaultKindName(s.fault.kind), s.target,
                    "");
  }
  std::stable_sort(held_.begin(), held_.end(),
                   [](const NodeFrame& a, const NodeFrame& b) { return a.due_ns < b.due_ns; });
  const auto split =
      std::find_if(held_.begin(), held_.end(), [&](const NodeFrame& f) { return f.due_ns > t_ns; });
  std::vector<NodeFrame> out(held_.begin(), split);
  held_.erase(held_.begin(), split);
  return out;
}

}  // namespace wheelhil::emulator
