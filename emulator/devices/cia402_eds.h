#pragma once
/// A CiA 402 drive configured from its vendor's EDS or DCF (bus/canopen_eds.h): the defaults of
/// Cia402DriveNode's dictionary come from the file - 0x1000 device type, 0x1016:1 consumer
/// heartbeat, 0x1017 producer heartbeat, 0x1018 identity, the four PDOs' communication (0x1400,
/// 0x1401, 0x1800, 0x1801: COB-ID with $NODEID, transmission type, event timer) and mapping
/// records (0x1600.., 0x1A00..), 0x6007, 0x605A, 0x605E option codes, 0x6060 mode, 0x606D,
/// 0x606F, 0x6075, 0x6076, 0x607E, 0x6080, 0x6083, 0x6084, 0x6085 - and every other integer
/// object of up to 4 bytes outside what the drive computes itself becomes one it serves by
/// SDO. A mapping the drive cannot carry (an object it does not have or cannot map) fails when
/// the node is built. Throws std::invalid_argument "file:line: [index] problem". Stateless.

#include <cstdint>

#include "bus/canopen_eds.h"
#include "emulator/devices/cia402_drive_node.h"

namespace wheelhil::emulator {

/// Writes the file's values into `config` (node_id set, or taken from the DCF when 0).
void ApplyCia402Eds(const bus::EdsFile& eds, Cia402DriveConfig& config);

/// Sets object (index, sub) to `value` in `config`: a built-in object's default, or an extra
/// object's; throws std::invalid_argument naming it when the drive has no such object.
void SetCia402Object(Cia402DriveConfig& config, std::uint16_t index, std::uint8_t sub,
                     std::uint32_t value);

}  // namespace wheelhil::emulator
