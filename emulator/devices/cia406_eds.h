#pragma once
/// A CiA 406 encoder node configured from its vendor's EDS or DCF (bus/canopen_eds.h): the
/// values of the built-in dictionary of CanopenEncoderNode come from the file (0x1000 device
/// type, 0x1017 heartbeat, 0x1018 identity, 0x1800:2 and :5 TPDO1 transmission type and event
/// timer, 0x6000 operating parameters, 0x6200 cyclic timer; 0x6001 measuring units per
/// revolution is the encoder's resolution), every other integer object of up to 4 bytes becomes
/// one the node answers by SDO (writable as its AccessType says). What this node cannot be is
/// refused: a TPDO1 COB-ID other than $NODEID+0x180, a TPDO1 mapping other than 0x6004 and
/// 0x6030:1, a DCF for another node id. Strings longer than 4 bytes (0x1008 device name, ...)
/// need segmented SDO, which the node does not serve: they are left out. Throws
/// std::invalid_argument "file:line: ..." naming the object. Stateless; thread-safe.

#include <cstdint>
#include <optional>

#include "bus/canopen_eds.h"
#include "emulator/devices/canopen_encoder_node.h"

namespace wheelhil::emulator {

struct Cia406EdsValues {
  std::optional<std::uint32_t> counts_per_rev;  ///< 0x6001, when the file gives it.
};

/// Writes the file's values into `node` (its node_id set, or taken from the DCF when 0).
Cia406EdsValues ApplyCia406Eds(const bus::EdsFile& eds, Cia406NodeConfig& node);

/// Sets object (index, sub) to `value` in `node`: a built-in one's configured value, or an
/// extra object's; throws std::invalid_argument naming it when the node has no such object.
void SetCia406Object(Cia406NodeConfig& node, std::uint16_t index, std::uint8_t sub,
                     std::uint32_t value);

}  // namespace wheelhil::emulator
