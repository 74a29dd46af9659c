#pragma once
/// A checksum as scenario files write it (a `dbc` device's checksum signal, a firmware output's
/// `checksum` check): `{type, data_id, data_id_mode, data_id_list}`; the last three only for the
/// E2E profiles (frame_checksum.h): e2e_p11 needs `data_id` (0..0xFFFF) and takes
/// `data_id_mode: both | nibble` (both by default), e2e_p22 needs `data_id_list` (16 bytes, by
/// counter value); `crc` needs `width` (1..32) and `poly` and takes `init`, `reflect_in`,
/// `reflect_out`, `xor_out` (0, false, false, 0), the Rocksoft model's parameters as reveng's
/// catalogue gives them. Fails through the reader ("file:line:col: field: problem").

#include <set>
#include <string>

#include <yaml-cpp/yaml.h>

#include "bus/yaml_fields.h"
#include "emulator/devices/frame_checksum.h"

namespace wheelhil::emulator {

/// The keys ReadChecksumSpec reads from a mapping, to allow in its CheckKeys.
const std::set<std::string>& ChecksumSpecKeys();
/// Reads them from the mapping `n` (whose field is `field`).
ChecksumSpec ReadChecksumSpec(const bus::yaml::FieldReader& r, const YAML::Node& n,
                              const std::string& field);

}  // namespace wheelhil::emulator
