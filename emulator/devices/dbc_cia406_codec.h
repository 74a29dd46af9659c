#pragma once
/// Cia406Codec over a DBC database (bus/dbc/cia406_encoder.dbc): every frame of a CiA 406
/// encoder node is built from and read through the DBC messages and signals, never packed by
/// hand. Messages are found by their CiA 301 pre-defined COB-IDs (NMT 0x000, EMCY 0x080+id,
/// TPDO1 0x180+id, SDO 0x580+id / 0x600+id, heartbeat 0x700+id), signals by name
/// (NMT_CommandSpecifier, NMT_NodeId, EMCY_ErrorCode, EMCY_ErrorRegister, EMCY_Manufacturer,
/// PositionValue, SpeedValue, SDO_Command, SDO_Index, SDO_SubIndex, SDO_Data, NMT_State).
/// A TPDO1 whose COB-ID was reconfigured keeps the layout of the node's TPDO1 message and only
/// changes the identifier. Decoding rejects frames whose length differs from the DBC's.
/// Immutable after construction; safe to share between threads.

#include <array>
#include <memory>
#include <string>

#include "bus/dbc.h"
#include "emulator/devices/cia406_codec.h"

namespace wheelhil::emulator {

class DbcCia406Codec final : public Cia406Codec {
 public:
  /// Throws std::invalid_argument when the NMT message or its signals are missing.
  explicit DbcCia406Codec(bus::DbcDatabase database);
  /// Loads the DBC file (normally <source>/bus/dbc/cia406_encoder.dbc); throws
  /// std::invalid_argument ("file:line: problem") on a bad file.
  static std::shared_ptr<const DbcCia406Codec> FromFile(const std::string& path);

  /// True when EMCY, TPDO1, both SDO and the heartbeat messages of node_id exist with their
  /// signals.
  bool SupportsNode(std::uint8_t node_id) const override;

  bool EncodeNmtState(std::uint8_t node_id, std::uint8_t state, bus::CanFrame& out) const override;
  bool EncodeTpdo1(std::uint8_t node_id, std::uint32_t cob_id, std::uint32_t position,
                   std::int16_t speed, bus::CanFrame& out) const override;
  bool EncodeEmcy(std::uint8_t node_id, std::uint16_t error_code, std::uint8_t error_register,
                  bus::CanFrame& out) const override;
  bool EncodeSdoResponse(std::uint8_t node_id, const SdoFields& sdo,
                         bus::CanFrame& out) const override;
  bool DecodeNmt(const bus::CanFrame& frame, std::uint8_t& command,
                 std::uint8_t& node_id) const override;
  bool DecodeSdoRequest(const bus::CanFrame& frame, SdoFields& sdo) const override;

  const bus::DbcDatabase& database() const { return database_; }

 private:
  /// A message with up to four signals resolved by name; message == nullptr when the message
  /// or one of its signals is missing.
  struct Layout {
    const bus::DbcMessage* message = nullptr;
    std::array<const bus::DbcSignal*, 4> signals{};
  };
  struct NodeLayouts {
    Layout emcy, tpdo1, sdo_tx, sdo_rx, heartbeat;
  };
  Layout Resolve(std::uint32_t id, std::initializer_list<const char*> names) const;
  /// Builds the message's frame (id, DBC length, zero payload) with the signals' physical
  /// values; false when a value does not fit its signal exactly.
  static bool Encode(const Layout& layout, std::initializer_list<double> physical,
                     bus::CanFrame& out);
  /// Physical values of the signals; false on a length mismatch.
  static bool Decode(const Layout& layout, const bus::CanFrame& frame,
                     std::array<double, 4>& physical);

  bus::DbcDatabase database_;
  Layout nmt_;
  std::array<NodeLayouts, 128> nodes_{};  ///< By node id; index 0 unused.
};

}  // namespace wheelhil::emulator
