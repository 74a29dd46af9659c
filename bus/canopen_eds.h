#pragma once
/// A CANopen device description (CiA 306 EDS, or a DCF: an EDS with the values of one
/// configured device) as its vendor ships it. Reads the INI sections real files have:
/// [FileInfo], [DeviceInfo] (vendor and product names and numbers, NrOfRXPDO/NrOfTXPDO),
/// [DeviceComissioning] (DCF: NodeID), the object lists [MandatoryObjects], [OptionalObjects],
/// [ManufacturerObjects] (every listed object must have its section), and per object [1018] and
/// [1018sub2]: ParameterName, ObjectType (0x7 VAR, 0x8 ARRAY, 0x9 RECORD), DataType, AccessType
/// (ro, wo, rw, rwr, rww, const), DefaultValue, ParameterValue (DCF), LowLimit, HighLimit,
/// PDOMapping, SubNumber. Integer values are decimal, 0x hexadecimal or 0-prefixed octal, and may
/// add or subtract $NODEID ("$NODEID+0x180"), which is resolved with the node id given when the
/// value is read. CompactSubObj and [DynamicChannels] are refused as not supported; comments
/// (';') and unknown keys are skipped, so is a leading UTF-8 byte-order mark. The value of an
/// integer object must be inside its DataType's range (UNSIGNED16: 0..65535), with a node id of
/// 1 when the file is read and with the node's when Integer() reads it. Errors throw
/// std::invalid_argument "file:line: [section] key: problem". Immutable once loaded; thread-safe
/// to share.

#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace wheelhil::bus {

/// One object or sub-object ([1017] is sub 0 of 0x1017; [1018sub2] sub 2 of 0x1018).
struct EdsEntry {
  std::uint16_t index = 0;
  std::uint8_t sub = 0;
  std::string name;
  std::uint8_t object_type = 0x7;
  std::uint16_t data_type = 0;
  std::string access;         ///< Lower case: ro, wo, rw, rwr, rww, const.
  std::string default_value;  ///< As written (ParameterValue of a DCF wins).
  std::string value_key = "DefaultValue";  ///< Or "ParameterValue": which one gave it.
  int value_line = 0;                      ///< Of that key (its section's when absent).
  bool pdo_mapping = false;
  int line = 0;  ///< Of its section header.

  bool writable() const {
    return access == "rw" || access == "wo" || access == "rwr" || access == "rww";
  }
};

class EdsFile {
 public:
  /// Largest file LoadFile reads (a device's EDS is at most a few MiB).
  static constexpr std::size_t kMaxFileBytes = std::size_t{16} << 20;
  /// Reads and parses `path`: a regular file ("path:0: is a directory, not an EDS file", "... is
  /// not a regular file (a device or a pipe?)") of at most kMaxFileBytes.
  static EdsFile LoadFile(const std::string& path);
  static EdsFile Parse(std::string_view text, const std::string& source_name);

  const std::string& source() const { return source_; }
  /// [DeviceInfo] keys as written (VendorName, ProductNumber, ...).
  const std::map<std::string, std::string, std::less<>>& device_info() const { return info_; }
  /// [DeviceComissioning] NodeID (DCF), if given.
  std::optional<int> node_id() const { return node_id_; }
  /// The node id a device built from this file has: `configured`, or the DCF's when 0. Throws
  /// std::invalid_argument when a DCF names another node ("... the <device> is node N") or
  /// neither gives one.
  std::uint8_t NodeIdFor(std::uint8_t configured, std::string_view device) const;
  /// Every VAR (or sub-object of an ARRAY/RECORD) with its value, by (index, sub).
  const std::map<std::pair<std::uint16_t, std::uint8_t>, EdsEntry>& entries() const {
    return entries_;
  }
  const EdsEntry* Find(std::uint16_t index, std::uint8_t sub) const;

  /// The entry's integer value with $NODEID = node_id (a negative one of a signed type as its
  /// two's complement); throws std::invalid_argument "file:line: [section] DefaultValue:
  /// problem" for a value that is not an integer or is outside its DataType's range ("'$NODEID+
  /// 0xFFFF' is 65540 with node id 5, outside UNSIGNED16's range 0..65535"), or a missing
  /// entry ("object 0x1017 sub 0 is not in the file").
  std::uint64_t Integer(std::uint16_t index, std::uint8_t sub, int node_id) const;
  /// Bytes of an integer data type (BOOLEAN .. UNSIGNED64), 0 for the others.
  static int IntegerSize(std::uint16_t data_type);

 private:
  std::string source_;
  std::map<std::string, std::string, std::less<>> info_;
  std::optional<int> node_id_;
  std::map<std::pair<std::uint16_t, std::uint8_t>, EdsEntry> entries_;
};

}  // namespace wheelhil::bus
