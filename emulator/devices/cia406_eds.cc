#include "emulator/devices/cia406_eds.h"

#include <stdexcept>

#include <fmt/format.h>

namespace wheelhil::emulator {

namespace {

bool BuiltIn(std::uint16_t index) {
  switch (index) {
    case 0x1000:
    case 0x1001:
    case 0x1017:
    case 0x1018:
    case 0x1800:
    case 0x1A00:
    case 0x6000:
    case 0x6004:
    case 0x6030:
    case 0x6200:
      return true;
    default:
      return false;
  }
}

[[noreturn]] void Fail(const bus::EdsFile& eds, const bus::EdsEntry& e, const std::string& what) {
  throw std::invalid_argument(fmt::format("{}:{}: [{:04X}{}] {}", eds.source(), e.line, e.index,
                                          e.sub != 0 ? fmt::format("sub{}", e.sub) : "", what));
}

}  // namespace

void SetCia406Object(Cia406NodeConfig& node, std::uint16_t index, std::uint8_t sub,
                     std::uint32_t value) {
  auto key = [&](std::uint16_t i, std::uint8_t s) { return index == i && sub == s; };
  if (key(0x1000, 0)) {
    node.device_type = value;
  } else if (key(0x1017, 0)) {
    node.heartbeat_ms = static_cast<std::uint16_t>(value);
  } else if (index == 0x1018 && sub >= 1 && sub <= 4) {
    (sub == 1   ? node.vendor_id
     : sub == 2 ? node.product_code
     : sub == 3 ? node.revision
                : node.serial) = value;
  } else if (key(0x1800, 2)) {
    node.tpdo1_transmission_type = static_cast<std::uint8_t>(value);
  } else if (key(0x1800, 5) || key(0x6200, 0)) {
    node.cyclic_timer_ms = static_cast<std::uint16_t>(value);
  } else if (key(0x6000, 0)) {
    node.operating_parameters = static_cast<std::uint16_t>(value);
  } else {
    for (auto& x : node.extra_objects) {
      if (x.index == index && x.sub == sub) {
        x.value = value;
        return;
      }
    }
    throw std::invalid_argument(fmt::format(
        "object 0x{:04X} sub {} is not in the node's dictionary (nor in its EDS)", index, sub));
  }
}

Cia406EdsValues ApplyCia406Eds(const bus::EdsFile& eds, Cia406NodeConfig& node) {
  Cia406EdsValues out;
  node.node_id = eds.NodeIdFor(node.node_id, "device");
  const int id = node.node_id;
  for (const auto& [key, e] : eds.entries()) {
    const int size = bus::EdsFile::IntegerSize(e.data_type);
    if (e.default_value.empty() || size == 0) continue;
    const std::uint64_t v = eds.Integer(e.index, e.sub, id);
    if (e.index == 0x1800 && e.sub == 1 && (v & 0x7FF) != 0x180u + static_cast<unsigned>(id)) {
      Fail(eds, e, fmt::format("TPDO1 COB-ID 0x{:X}: this node sends TPDO1 on 0x180 + node id", v));
    }
    if (e.index == 0x1A00 && e.sub >= 1) {
      const std::uint32_t want = e.sub == 1 ? 0x60040020u : 0x60300110u;
      if (e.sub > 2 || v != want) {
        Fail(eds, e,
             fmt::format("TPDO1 mapping 0x{:08X}: this node maps 0x6004 (position) and "
                         "0x6030:1 (speed)",
                         v));
      }
      continue;
    }
    if (e.index == 0x6001 && e.sub == 0) {
      if (v == 0 || v > 0xFFFFFFFFu) Fail(eds, e, "measuring units per revolution must be > 0");
      out.counts_per_rev = static_cast<std::uint32_t>(v);
    }
    if (size > 4) continue;  // no 64-bit object fits an expedited transfer
    if (BuiltIn(e.index)) {
      try {
        SetCia406Object(node, e.index, e.sub, static_cast<std::uint32_t>(v));
      } catch (const std::invalid_argument&) {
        // A sub-index of a built-in object the node computes itself (0x1018:0, 0x1800:0, ...).
      }
      continue;
    }
    node.extra_objects.push_back({e.index, e.sub, static_cast<std::uint32_t>(v),
                                  static_cast<std::uint8_t>(size), e.writable()});
  }
  return out;
}

}  // namespace wheelhil::emulator
