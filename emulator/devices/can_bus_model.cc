#include "emulator/devices/can_bus_model.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <limits>
#include <stdexcept>

namespace wheelhil::emulator {
namespace {

constexpr unsigned kTrailerBits = 3 + 7 + 3;  // CRC delimiter, ACK slot, ACK delimiter; EOF; IFS
constexpr unsigned kIfsBits = 3;

// One pass over the bits SOF .. CRC of a classic frame: the CRC-15 (poly 0x4599, init 0) over
// SOF .. data as the bits go by, and the stuff bits the transmitter inserts: after 5 equal bits
// one complementary bit, which starts a new run (the first bit starts the first run).
struct StuffCounter {
  std::uint16_t crc = 0;
  bool crc_on = true;  // false once the CRC field itself is sent
  unsigned bits = 0;
  unsigned stuffed = 0;
  int run = 0;
  unsigned prev = 2;
  constexpr void Bit(unsigned b) {
    if (crc_on) {
      const bool crc_next = (b != 0) != ((crc & 0x4000u) != 0);
      crc = static_cast<std::uint16_t>((crc << 1) & 0x7FFF);
      if (crc_next) crc ^= 0x4599;
    }
    ++bits;
    if (b == prev) {
      ++run;
    } else {
      prev = b;
      run = 1;
    }
    if (run == 5) {
      ++stuffed;
      prev ^= 1u;
      run = 1;
    }
  }
  constexpr void Push(std::uint32_t value, int count) {
    for (int i = count - 1; i >= 0; --i) Bit((value >> i) & 1u);
  }
};

// The stream a chunk of k = 1..8 bits at a time. After the SOF bit the run state is prev in
// {0, 1} and run in 1..4 (a run of 5 has just been stuffed and restarted at 1): 8 states. For
// each k, state and k-bit value: the stuff bits inserted, the state after, and the CRC-15 of
// the chunk from a zero register (the register is linear, so crc' = (crc << k) ^
// crc_of[(crc >> (15 - k)) ^ value]). Built by StuffCounter::Bit, bit by bit, at compile time.
// Entries of k bits start at 8 * (2^k - 2) (stuff tables) and 2^k - 2 (CRC table).
struct ChunkTables {
  std::uint8_t stuffed[8 * 510] = {};
  std::uint8_t next[8 * 510] = {};
  std::uint16_t crc_of[510] = {};
};

constexpr ChunkTables MakeChunkTables() {
  ChunkTables t;
  for (unsigned k = 1; k <= 8; ++k) {
    const unsigned values = 1u << k;
    for (unsigned s = 0; s < 8; ++s) {
      for (unsigned d = 0; d < values; ++d) {
        StuffCounter c;
        c.crc_on = false;
        c.prev = s >> 2;
        c.run = static_cast<int>(s & 3u) + 1;
        c.Push(d, static_cast<int>(k));
        const unsigned i = 8 * (values - 2) + s * values + d;
        t.stuffed[i] = static_cast<std::uint8_t>(c.stuffed);
        t.next[i] = static_cast<std::uint8_t>(c.prev << 2 | static_cast<unsigned>(c.run - 1));
      }
    }
    for (unsigned d = 0; d < values; ++d) {
      StuffCounter c;
      c.Push(d, static_cast<int>(k));
      t.crc_of[values - 2 + d] = c.crc;
    }
  }
  return t;
}

constexpr ChunkTables kChunkTables = MakeChunkTables();

// The stream SOF .. CRC through the tables: after the SOF bit the run state is always one of
// the 8 table states, so every chunk of bits (at any position) is one lookup for the stuff
// bits and one for the CRC: a field goes as its leading count % 8 bits, then whole bytes.
struct TableStuffCounter {
  std::uint16_t crc = 0;
  unsigned bits = 0;
  unsigned stuffed = 0;
  unsigned state = 0;  // prev << 2 | (run - 1), valid after the SOF bit
  void Chunk(unsigned d, unsigned k, bool crc_on) {
    const unsigned values = 1u << k;
    if (crc_on) {
      crc = static_cast<std::uint16_t>(
          ((crc << k) & 0x7FFF) ^
          kChunkTables.crc_of[values - 2 + (((crc >> (15 - k)) ^ d) & (values - 1))]);
    }
    bits += k;
    const unsigned i = 8 * (values - 2) + state * values + d;
    stuffed += kChunkTables.stuffed[i];
    state = kChunkTables.next[i];
  }
  // `count` bits of `value`, MSB first.
  void Push(std::uint64_t value, unsigned count, bool crc_on) {
    unsigned i = count;
    if (i % 8 != 0) {
      i -= i % 8;
      Chunk(static_cast<unsigned>(value >> i) & ((1u << (count % 8)) - 1), count % 8, crc_on);
    }
    for (; i > 0; i -= 8) Chunk(static_cast<unsigned>(value >> (i - 8)) & 0xFFu, 8, crc_on);
  }
};

unsigned ExactBits(const bus::CanFrame& f) {
  TableStuffCounter b;
  // SOF (dominant): the first bit starts the first run, so the state is prev 0, run 1, and
  // the CRC register (init 0) stays 0.
  b.bits = 1;
  b.state = 0;
  const std::uint64_t rtr = f.rtr ? 1 : 0;
  if (f.extended) {
    // base id (11), SRR and IDE (recessive), extension (18), RTR, r1 r0 (dominant), DLC (4)
    const std::uint64_t h = static_cast<std::uint64_t>(f.id >> 18 & 0x7FFu) << 27 | 0x3u << 25 |
                            static_cast<std::uint64_t>(f.id & 0x3FFFFu) << 7 | rtr << 6 |
                            (f.len & 0xFu);
    b.Push(h, 38, true);
  } else {
    // id (11), RTR, IDE and r0 (dominant), DLC (4)
    const std::uint64_t h =
        static_cast<std::uint64_t>(f.id & 0x7FFu) << 7 | rtr << 6 | (f.len & 0xFu);
    b.Push(h, 18, true);
  }
  if (!f.rtr) {
    for (std::size_t i = 0; i < f.len; ++i) b.Chunk(f.data[i], 8, true);
  }
  b.Push(b.crc, 15, false);
  return b.bits + b.stuffed + kTrailerBits;
}

}  // namespace

unsigned CanFrameBits(const bus::CanFrame& f, StuffingMode mode) noexcept {
  if (f.fd || f.error || !f.IsValid()) return 0;
  const unsigned n = f.rtr ? 0u : f.len;  // data bytes on the wire
  switch (mode) {
    case StuffingMode::kNoStuffing:
      return (f.extended ? 67u : 47u) + 8u * n;
    case StuffingMode::kTindell:
      return ((f.extended ? 389u : 269u) + 48u * n) / 5u;
    case StuffingMode::kWorstCase:
      return (f.extended ? 67u : 47u) + 8u * n + ((f.extended ? 53u : 33u) + 8u * n) / 4u;
    case StuffingMode::kExact:
      return ExactBits(f);
  }
  return 0;
}

std::uint32_t ArbitrationKey(const bus::CanFrame& f) noexcept {
  if (f.extended) {
    return ((f.id >> 18) & 0x7FFu) << 21 | 1u << 20 | 1u << 19 | (f.id & 0x3FFFFu) << 1 |
           (f.rtr ? 1u : 0u);
  }
  return (f.id & 0x7FFu) << 21 | (f.rtr ? 1u : 0u) << 20;
}

CanBusModel::CanBusModel(const CanBusConfig& config) : config_(config) {
  if (config.bitrate_bps < 125'000 || config.bitrate_bps > 1'000'000) {
    throw std::invalid_argument(
        fmt::format("bus.bitrate_bps ({}) must be in 125000..1000000", config.bitrate_bps));
  }
  if (1'000'000'000 % config.bitrate_bps != 0) {
    throw std::invalid_argument(fmt::format(
        "bus.bitrate_bps ({}) must give a whole-ns bit time (e.g. 125k, 250k, 500k, 800k, 1M)",
        config.bitrate_bps));
  }
  bit_time_ns_ = 1'000'000'000 / config.bitrate_bps;
}

int CanBusModel::AddNode(std::string name, QueueOrder order, std::size_t max_queue) {
  nodes_.push_back(Node{std::move(name), order, max_queue, {}});
  return static_cast<int>(nodes_.size()) - 1;
}

bool CanBusModel::Enqueue(int node, const bus::CanFrame& frame, std::int64_t ready_ns) noexcept {
  if (node < 0 || static_cast<std::size_t>(node) >= nodes_.size() || ready_ns < now_ns_ ||
      CanFrameBits(frame, StuffingMode::kNoStuffing) == 0) {
    ++frames_dropped_;
    return false;
  }
  Node& n = nodes_[static_cast<std::size_t>(node)];
  if (n.queue.size() >= n.max_queue) {
    ++frames_dropped_;
    return false;
  }
  n.queue.push_back(Pending{frame, ready_ns, seq_++});
  return true;
}

std::ptrdiff_t CanBusModel::HeadAt(const Node& n, std::int64_t s) {
  if (n.queue.empty()) return -1;
  if (n.order == QueueOrder::kFifo) return n.queue.front().ready_ns <= s ? 0 : -1;
  std::ptrdiff_t best = -1;
  for (std::size_t i = 0; i < n.queue.size(); ++i) {
    const Pending& p = n.queue[i];
    if (p.ready_ns > s) continue;
    if (best < 0) {
      best = static_cast<std::ptrdiff_t>(i);
      continue;
    }
    const Pending& b = n.queue[static_cast<std::size_t>(best)];
    if (ArbitrationKey(p.frame) < ArbitrationKey(b.frame)) best = static_cast<std::ptrdiff_t>(i);
  }
  return best;
}

std::int64_t CanBusModel::EarliestReady(const Node& n) {
  if (n.queue.empty()) return std::numeric_limits<std::int64_t>::max();
  if (n.order == QueueOrder::kFifo) return n.queue.front().ready_ns;
  std::int64_t r = std::numeric_limits<std::int64_t>::max();
  for (const Pending& p : n.queue) r = std::min(r, p.ready_ns);
  return r;
}

void CanBusModel::Schedule(std::int64_t limit_ns) {
  for (;;) {
    // The next SOF is at bus_free_ns_ or later: nothing to arbitrate before limit_ns.
    if (bus_free_ns_ >= limit_ns) return;
    std::int64_t ready = std::numeric_limits<std::int64_t>::max();
    for (const Node& n : nodes_) ready = std::min(ready, EarliestReady(n));
    if (ready == std::numeric_limits<std::int64_t>::max()) return;
    const std::int64_t sof = std::max(bus_free_ns_, ready);
    if (sof >= limit_ns) return;
    // Arbitration among every node with a ready frame at this SOF instant.
    int winner = -1;
    std::ptrdiff_t winner_idx = -1;
    std::uint32_t winner_key = 0;
    for (std::size_t i = 0; i < nodes_.size(); ++i) {
      const std::ptrdiff_t idx = HeadAt(nodes_[i], sof);
      if (idx < 0) continue;
      const std::uint32_t key =
          ArbitrationKey(nodes_[i].queue[static_cast<std::size_t>(idx)].frame);
      if (winner < 0 || key < winner_key) {
        winner = static_cast<int>(i);
        winner_idx = idx;
        winner_key = key;
      }
    }
    Node& n = nodes_[static_cast<std::size_t>(winner)];
    const Pending p = n.queue[static_cast<std::size_t>(winner_idx)];
    if (winner_idx == 0) {
      n.queue.pop_front();  // a FIFO's head, and most of the time a priority queue's
    } else {
      n.queue.erase(n.queue.begin() + winner_idx);
    }
    WireFrame w;
    w.frame = p.frame;
    w.node = winner;
    w.ready_ns = p.ready_ns;
    w.start_ns = sof;
    w.bits = CanFrameBits(p.frame, config_.stuffing);
    w.complete_ns = sof + static_cast<std::int64_t>(w.bits - kIfsBits) * bit_time_ns_;
    const std::int64_t duration = static_cast<std::int64_t>(w.bits) * bit_time_ns_;
    bus_free_ns_ = sof + duration;
    busy_ns_total_ += duration;
    max_queue_delay_ns_ = std::max(max_queue_delay_ns_, sof - p.ready_ns);
    in_flight_.push_back(w);
  }
}

std::vector<WireFrame> CanBusModel::AdvanceTo(std::int64_t t_ns) {
  std::vector<WireFrame> done;
  AdvanceTo(t_ns, done);
  return done;
}

void CanBusModel::AdvanceTo(std::int64_t t_ns, std::vector<WireFrame>& done) {
  done.clear();
  if (t_ns < now_ns_) return;
  Schedule(t_ns);
  now_ns_ = t_ns;
  while (!in_flight_.empty() && in_flight_.front().complete_ns <= t_ns) {
    done.push_back(in_flight_.front());
    in_flight_.pop_front();
    ++frames_sent_;
  }
}

std::int64_t CanBusModel::NextEventNs() const {
  // A frame in flight completes before the bus is free again, and no SOF comes before that.
  if (!in_flight_.empty()) return in_flight_.front().complete_ns;
  // Schedule(t) starts nothing while max(bus free, earliest ready) >= t.
  std::int64_t ready = std::numeric_limits<std::int64_t>::max();
  for (const Node& n : nodes_) ready = std::min(ready, EarliestReady(n));
  const std::int64_t sof =
      ready == std::numeric_limits<std::int64_t>::max() ? ready : std::max(bus_free_ns_, ready);
  return sof;
}

std::vector<WireFrame> CanBusModel::Drain() {
  Schedule(std::numeric_limits<std::int64_t>::max());
  std::int64_t end = now_ns_;
  if (!in_flight_.empty()) end = std::max(end, bus_free_ns_);
  return AdvanceTo(end);
}

std::int64_t CanBusModel::busy_ns() const {
  return busy_ns_total_ - std::max<std::int64_t>(0, bus_free_ns_ - now_ns_);
}

double CanBusModel::BusLoad() const {
  if (now_ns_ <= 0) return 0.0;
  return static_cast<double>(busy_ns()) / static_cast<double>(now_ns_);
}

}  // namespace wheelhil::emulator
