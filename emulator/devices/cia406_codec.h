#pragma once
/// The frames a CANopen CiA 406 encoder node sends and understands, as fields. The node never
/// packs bytes itself: an implementation of this interface turns fields into frames and back
/// through the DBC description in bus/dbc/cia406_encoder.dbc (see DbcCia406Codec).
/// Implementations return false for a frame they cannot decode or a value they cannot encode.
/// Implementations must be usable from one thread at a time (thread-compatible).

#include <cstdint>

#include "bus/can_frame.h"

namespace wheelhil::emulator {

/// One SDO frame's fields (CiA 301 layout: command byte, index, subindex, 4 data bytes).
struct SdoFields {
  std::uint8_t command = 0;
  std::uint16_t index = 0;
  std::uint8_t subindex = 0;
  std::uint32_t data = 0;  ///< Little-endian bytes 4..7 (expedited data or abort code).
  bool operator==(const SdoFields&) const = default;
};

class Cia406Codec {
 public:
  virtual ~Cia406Codec() = default;

  /// True when the codec can build every frame of this node id.
  virtual bool SupportsNode(std::uint8_t node_id) const = 0;

  /// NMT error-control frame on 0x700 + node_id: boot-up (state 0) or heartbeat.
  virtual bool EncodeNmtState(std::uint8_t node_id, std::uint8_t state,
                              bus::CanFrame& out) const = 0;
  /// TPDO1 of node_id: position value 0x6004 (u32 counts) and speed value 0x6030.1 (int16),
  /// sent on cob_id (11 bit; 0x180 + node_id unless reconfigured through 0x1800:1).
  virtual bool EncodeTpdo1(std::uint8_t node_id, std::uint32_t cob_id, std::uint32_t position,
                           std::int16_t speed, bus::CanFrame& out) const = 0;
  /// EMCY on 0x080 + node_id: error code, error register (0x1001), manufacturer field zero.
  virtual bool EncodeEmcy(std::uint8_t node_id, std::uint16_t error_code,
                          std::uint8_t error_register, bus::CanFrame& out) const = 0;
  /// SDO server response on 0x580 + node_id.
  virtual bool EncodeSdoResponse(std::uint8_t node_id, const SdoFields& sdo,
                                 bus::CanFrame& out) const = 0;

  /// NMT module control frame (id 0x000): command specifier and addressed node (0 = all).
  virtual bool DecodeNmt(const bus::CanFrame& frame, std::uint8_t& command,
                         std::uint8_t& node_id) const = 0;
  /// SDO client request (0x600 + node_id, 8 bytes).
  virtual bool DecodeSdoRequest(const bus::CanFrame& frame, SdoFields& sdo) const = 0;
};

}  // namespace wheelhil::emulator
