#include "emulator/faults/bus_faults.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <fmt/format.h>

namespace wheelhil::emulator {

namespace {

bus::CanFrame FloodFrame(const BusFault& f) {
  bus::CanFrame fr;
  fr.id = f.flood_id;
  fr.len = f.flood_len;
  for (std::size_t i = 0; i < fr.len; ++i) fr.data[i] = 0xAA;
  return fr;
}

bus::CanFrame BlockerFrame() { return bus::CanFrame{}; }  // id 0x000, standard, len 0

}  // namespace

std::optional<BusFaultKind> ParseBusFaultKind(std::string_view name) noexcept {
  for (auto k : {BusFaultKind::kErrorBurst, BusFaultKind::kBusOff, BusFaultKind::kFlood}) {
    if (BusFaultKindName(k) == name) return k;
  }
  return std::nullopt;
}

std::string_view BusFaultKindName(BusFaultKind kind) noexcept {
  switch (kind) {
    case BusFaultKind::kErrorBurst:
      return "error_burst";
    case BusFaultKind::kBusOff:
      return "bus_off";
    case BusFaultKind::kFlood:
      return "flood";
  }
  return "?";
}

FaultyCanBus::FaultyCanBus(const FaultyCanBus& other, CanBusModel& bus)
    : bus_(bus),
      states_(other.states_),
      log_(other.log_),
      flood_node_(other.flood_node_),
      error_node_(other.error_node_),
      dropped_bus_off_(other.dropped_bus_off_),
      flood_frames_(other.flood_frames_),
      error_frames_(other.error_frames_) {}

FaultyCanBus::FaultyCanBus(CanBusModel& bus, std::vector<BusFault> faults, StuffingMode stuffing,
                           FaultEventLog* log)
    : bus_(bus), log_(log) {
  for (std::size_t i = 0; i < faults.size(); ++i) {
    const BusFault& f = faults[i];
    const std::string field = fmt::format("bus_faults[{}]", i);
    auto fail = [&](std::string_view what) {
      throw std::invalid_argument(fmt::format("{}.{}", field, what));
    };
    if (!f.window.IsValid()) fail("window: must have 0 <= t0 < t1");
    State s{f, {}, 0, f.window.t0_ns, ""};
    switch (f.kind) {
      case BusFaultKind::kErrorBurst:
        if (f.error_frames < 1 || f.error_frames > 1000) fail("error_frames: must be 1..1000");
        if (error_node_ < 0) {
          error_node_ = bus_.AddNode("fault:error_burst", CanBusModel::QueueOrder::kFifo, 1000);
        }
        s.target = "bus";
        break;
      case BusFaultKind::kBusOff:
        if (f.node < 0) fail("node: a bus node index is required");
        s.target = f.node_name.empty() ? fmt::format("node {}", f.node) : f.node_name;
        break;
      case BusFaultKind::kFlood: {
        if (!(f.load > 0.0 && f.load <= 1.0)) fail("load: must be in (0, 1]");
        if (f.flood_id > bus::CanFrame::kMaxStandardId) fail("flood_id: must be a standard id");
        if (f.flood_len > 8) fail("flood_len: must be 0..8");
        const unsigned bits = CanFrameBits(FloodFrame(f), stuffing);
        s.period_ns = static_cast<std::int64_t>(std::ceil(
            static_cast<double>(bits) * static_cast<double>(bus_.bit_time_ns()) / f.load));
        if (flood_node_ < 0) {
          flood_node_ = bus_.AddNode("fault:flood", CanBusModel::QueueOrder::kFifo, 4096);
        }
        s.target = fmt::format("id 0x{:03X}", f.flood_id);
        break;
      }
    }
    states_.push_back(std::move(s));
  }
}

bool FaultyCanBus::Enqueue(int node, const bus::CanFrame& frame, std::int64_t ready_ns) noexcept {
  for (const State& s : states_) {
    if (s.fault.kind == BusFaultKind::kBusOff && s.fault.node == node &&
        s.fault.window.Contains(ready_ns)) {
      ++dropped_bus_off_;
      return false;
    }
  }
  return bus_.Enqueue(node, frame, ready_ns);
}

void FaultyCanBus::Generate(std::int64_t t_ns) {
  constexpr std::int64_t kNever = std::numeric_limits<std::int64_t>::max();
  for (State& s : states_) {
    if (s.phase.Pending(t_ns, s.fault.window)) {
      std::string detail;
      if (s.fault.kind == BusFaultKind::kFlood) {
        detail = fmt::format("load={} period_ns={}", s.fault.load, s.period_ns);
      } else if (s.fault.kind == BusFaultKind::kErrorBurst) {
        detail = fmt::format("error_frames={}", s.fault.error_frames);
      }
      s.phase.Advance(t_ns, s.fault.window, log_, "bus", BusFaultKindName(s.fault.kind), s.target,
                      detail);
    }
    if (s.fault.kind == BusFaultKind::kFlood) {
      const std::int64_t end = std::min(t_ns, s.fault.window.t1_ns);
      for (; s.next_ns < end; s.next_ns += s.period_ns) {
        const std::int64_t ready = std::max(s.next_ns, bus_.now_ns());
        if (bus_.Enqueue(flood_node_, FloodFrame(s.fault), ready)) ++flood_frames_;
      }
    } else if (s.fault.kind == BusFaultKind::kErrorBurst && s.next_ns != kNever &&
               s.next_ns < t_ns) {
      const std::int64_t ready = std::max(s.next_ns, bus_.now_ns());
      for (int i = 0; i < s.fault.error_frames; ++i) {
        if (!bus_.Enqueue(error_node_, BlockerFrame(), ready)) break;
      }
      s.next_ns = kNever;
    }
  }
}

std::vector<WireFrame> FaultyCanBus::AdvanceTo(std::int64_t t_ns) {
  Generate(t_ns);
  std::vector<WireFrame> out = bus_.AdvanceTo(t_ns);
  for (WireFrame& w : out) {
    if (w.node != error_node_ || error_node_ < 0) continue;
    bus::CanFrame e;
    e.error = true;
    e.id = kCanErrProt | kCanErrBusError;
    e.len = 8;
    w.frame = e;
    ++error_frames_;
  }
  return out;
}

}  // namespace wheelhil::emulator
