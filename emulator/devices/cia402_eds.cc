#include "emulator/devices/cia402_eds.h"

#include <stdexcept>

#include <fmt/format.h>

#include "bus/canopen.h"

namespace wheelhil::emulator {

namespace {

// Objects the drive computes or keeps itself: their EDS defaults are not configuration.
bool Computed(std::uint16_t index) {
  switch (index) {
    case 0x1001:
    case 0x603F:
    case 0x6040:
    case 0x6041:
    case 0x6061:
    case 0x6064:
    case 0x606C:
    case 0x6072:
    case 0x6077:
    case 0x6078:
    case 0x60FF:
    case 0x6502:
      return true;
    default:
      return false;
  }
}

bool IsPdoRecord(std::uint16_t index) {
  return index == 0x1400 || index == 0x1401 || index == 0x1600 || index == 0x1601 ||
         index == 0x1800 || index == 0x1801 || index == 0x1A00 || index == 0x1A01;
}

}  // namespace

void SetCia402Object(Cia402DriveConfig& c, std::uint16_t index, std::uint8_t sub,
                     std::uint32_t value) {
  const auto bad = [&] {
    throw std::invalid_argument(fmt::format(
        "object 0x{:04X} sub {} is not a setting of the drive (nor in its EDS)", index, sub));
  };
  const auto s16 = [&] { return static_cast<std::int16_t>(static_cast<std::uint16_t>(value)); };
  if (IsPdoRecord(index)) {
    const bool rpdo = index < 0x1800;
    auto& pdo = (rpdo ? c.rpdo : c.tpdo)[index & 1];
    const bool mapping = (index & 0x0200) != 0;
    if (mapping) {
      if (sub == 0) {
        if (value > 8) bad();
        pdo.map.resize(value, 0);
      } else if (sub <= 8) {
        if (pdo.map.size() < sub) pdo.map.resize(sub, 0);
        pdo.map[sub - 1] = value;
      } else {
        bad();
      }
      return;
    }
    if (sub == 1) {
      pdo.valid = (value & bus::canopen::kPdoCobIdInvalid) == 0;
      pdo.cob_id = value & 0x7FF;
    } else if (sub == 2) {
      pdo.type = static_cast<std::uint8_t>(value);
    } else if (sub == 5) {
      pdo.event_ms = static_cast<std::uint16_t>(value);
    } else if (sub != 0) {
      bad();
    }
    return;
  }
  const auto key = [&](std::uint16_t i, std::uint8_t s = 0) { return index == i && sub == s; };
  if (key(0x1000))
    c.device_type = value;
  else if (key(0x1016, 1))
    c.consumer_heartbeat = value;
  else if (key(0x1017))
    c.heartbeat_ms = static_cast<std::uint16_t>(value);
  else if (index == 0x1018 && sub >= 1 && sub <= 4)
    (sub == 1 ? c.vendor_id : sub == 2 ? c.product_code : sub == 3 ? c.revision : c.serial) = value;
  else if (key(0x6007))
    c.abort_connection_option = s16();
  else if (key(0x605A))
    c.quick_stop_option = s16();
  else if (key(0x605E))
    c.fault_reaction_option = s16();
  else if (key(0x6060))
    c.default_mode = static_cast<std::int8_t>(static_cast<std::uint8_t>(value));
  else if (key(0x606D))
    c.velocity_window = static_cast<std::uint16_t>(value);
  else if (key(0x606F))
    c.velocity_threshold = static_cast<std::uint16_t>(value);
  else if (key(0x6075))
    c.rated_current_ma = value;
  else if (key(0x6076))
    c.rated_torque_mnm = value;
  else if (key(0x607E))
    c.polarity = static_cast<std::uint8_t>(value & 0xC0);
  else if (key(0x6080))
    c.max_motor_speed = value;
  else if (key(0x6083))
    c.profile_acceleration = value;
  else if (key(0x6084))
    c.profile_deceleration = value;
  else if (key(0x6085))
    c.quick_stop_deceleration = value;
  else {
    for (auto& x : c.extra_objects) {
      if (x.index == index && x.sub == sub) {
        x.value = value;
        return;
      }
    }
    bad();
  }
}

void ApplyCia402Eds(const bus::EdsFile& eds, Cia402DriveConfig& c) {
  c.node_id = eds.NodeIdFor(c.node_id, "drive");
  const int id = c.node_id;
  // A mapping record in the file replaces the default mapping as a whole.
  for (std::uint16_t rec : {0x1600, 0x1601, 0x1A00, 0x1A01}) {
    if (eds.Find(rec, 0) != nullptr) ((rec < 0x1800 ? c.rpdo : c.tpdo)[rec & 1]).map.clear();
  }
  for (const auto& [key, e] : eds.entries()) {
    const int size = bus::EdsFile::IntegerSize(e.data_type);
    if (e.default_value.empty() || size == 0 || size > 4) continue;
    if (Computed(e.index)) continue;
    const std::uint64_t v = eds.Integer(e.index, e.sub, id);
    try {
      if (IsPdoRecord(e.index) || e.index < 0x2000 || (e.index >= 0x6000 && e.index < 0x6100)) {
        if (e.index == 0x1018 && e.sub == 0) continue;
        if (e.index == 0x1016 && e.sub != 1) continue;
        SetCia402Object(c, e.index, e.sub, static_cast<std::uint32_t>(v));
        continue;
      }
    } catch (const std::invalid_argument&) {
      // Not one of the drive's settings: served as the file describes it, below.
    }
    c.extra_objects.push_back({e.index, e.sub, static_cast<std::uint32_t>(v),
                               static_cast<std::uint8_t>(size), e.writable()});
  }
}

}  // namespace wheelhil::emulator
