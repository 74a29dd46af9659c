#pragma once
/// Helpers the firmware's protocol bindings share (fw_protocol.cc, drive_protocol.cc): finding
/// a CANopen function's message and a signal by its position in a DBC database, so the
/// firmware depends on where a CiA 301 / CiA 402 field sits, not on what the DBC names it.
/// Internal to firmware_stub/; thread-safe (pure functions).

#include <cstdint>
#include <vector>

#include "bus/can_frame.h"
#include "bus/canopen.h"
#include "bus/dbc.h"

namespace wheelhil::fw {

/// The Intel integer signal occupying exactly [start, start+len) of `m`, preferring one that is
/// not multiplexed. nullptr when none.
inline const bus::DbcSignal* SignalAt(const bus::DbcMessage& m, int start, int len) {
  const bus::DbcSignal* found = nullptr;
  for (const auto& s : m.signals) {
    if (!s.little_endian || s.start_bit != start || s.length != len ||
        s.value_type != bus::DbcValueType::kInteger) {
      continue;
    }
    if (!s.multiplex_value) return &s;
    if (!found) found = &s;
  }
  return found;
}

/// A message for the CANopen function `f`: the exact id of one of `nodes` if the DBC lists it,
/// else any message of that function for some node 1..127.
inline const bus::DbcMessage* FindFunction(const bus::DbcDatabase& db, bus::canopen::Function f,
                                           const std::vector<int>& nodes) {
  for (int n : nodes) {
    const std::uint32_t id = bus::canopen::FunctionCode(f) + static_cast<std::uint32_t>(n);
    if (const auto* m = db.FindMessage(id, false)) return m;
  }
  for (const auto& m : db.messages()) {
    if (!m.extended && bus::canopen::Is(f, m.id)) return &m;
  }
  return nullptr;
}

/// An all-zero frame with `id` and the length and format of `m`.
inline bus::CanFrame BlankFrame(std::uint32_t id, const bus::DbcMessage& m) {
  bus::CanFrame f;
  f.id = id;
  f.extended = m.extended;
  f.len = static_cast<std::uint8_t>(m.length);
  return f;
}

}  // namespace wheelhil::fw
