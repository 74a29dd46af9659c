#pragma once
/// The firmware's view of its CiA 402 drives' process data, bound once from a DBC file
/// (bus/dbc/cia402_drive.dbc, or the customer's own) the way fw_protocol.h binds the encoders':
/// messages by their CiA 301 function (RPDO1 0x200+id, TPDO1 0x180+id, TPDO2 0x280+id; a node
/// the DBC does not list uses another node's message of the same function), fields by their
/// position in the default mappings of CiA 402 (RPDO1: controlword 0x6040 at bit 0, 16 bits,
/// target velocity 0x60FF at bit 16, 32 bits; TPDO1: statusword 0x6041 at bit 0, velocity
/// actual 0x606C at bit 16; TPDO2: position actual 0x6064 at bit 0, 32 bits, torque actual
/// 0x6077 at bit 32, 16 bits). Velocity and position are raw drive units (rpm or increments/s;
/// increments); torque per mille of the rated torque. Errors at load throw
/// std::invalid_argument "file: problem". Immutable after construction; calls are noexcept;
/// thread-safe.

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "bus/can_frame.h"
#include "bus/dbc.h"

namespace wheelhil::fw {

class DriveProtocol {
 public:
  static constexpr const char* kDefaultFile = "cia402_drive.dbc";

  /// Binds `db` (named `source_name` in messages) for the drives `node_ids`.
  DriveProtocol(std::shared_ptr<const bus::DbcDatabase> db, std::string source_name,
                const std::vector<int>& node_ids);
  /// Loads `dir`/cia402_drive.dbc and binds it.
  static DriveProtocol LoadDir(const std::string& dir, const std::vector<int>& node_ids);

  /// RPDO1 of `node_id`: controlword and target velocity.
  [[nodiscard]] bool EncodeRpdo1(std::uint8_t node_id, std::uint16_t controlword,
                                 std::int32_t target_velocity, bus::CanFrame& out) const noexcept;
  /// Function of a frame's identifier: 1 = TPDO1, 2 = TPDO2 of some node (node_id set), else 0.
  int TpdoOf(const bus::CanFrame& f, std::uint8_t& node_id) const noexcept;
  /// Decoders return false for a frame whose length differs from its DBC message's.
  [[nodiscard]] bool DecodeTpdo1(const bus::CanFrame& f, std::uint16_t& statusword,
                                 std::int32_t& velocity_actual) const noexcept;
  [[nodiscard]] bool DecodeTpdo2(const bus::CanFrame& f, std::int32_t& position_actual,
                                 std::int16_t& torque_actual) const noexcept;

 private:
  struct Layout {
    const bus::DbcMessage* msg = nullptr;
    const bus::DbcSignal* a = nullptr;
    const bus::DbcSignal* b = nullptr;
  };
  std::shared_ptr<const bus::DbcDatabase> db_;
  Layout rpdo1_, tpdo1_, tpdo2_;
};

}  // namespace wheelhil::fw
