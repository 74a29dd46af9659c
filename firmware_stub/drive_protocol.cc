#include "firmware_stub/drive_protocol.h"

#include <fmt/format.h>

#include <filesystem>
#include <stdexcept>

#include "bus/canopen.h"
#include "bus/dbc_codec.h"
#include "firmware_stub/dbc_binding.h"

namespace wheelhil::fw {

namespace canopen = bus::canopen;
using canopen::Function;

DriveProtocol::DriveProtocol(std::shared_ptr<const bus::DbcDatabase> db, std::string source_name,
                             const std::vector<int>& node_ids)
    : db_(std::move(db)) {
  if (!db_) throw std::invalid_argument(fmt::format("{}: not loaded", source_name));
  auto bind = [&](Layout& l, Function f, const char* what, int a_start, int a_len,
                  const char* a_what, int b_start, int b_len, const char* b_what) {
    l.msg = FindFunction(*db_, f, node_ids);
    if (!l.msg) {
      throw std::invalid_argument(fmt::format("{}: no {} message (0x{:03X}+id)", source_name, what,
                                              canopen::FunctionCode(f)));
    }
    auto need = [&](int start, int len, const char* field) {
      const bus::DbcSignal* s = SignalAt(*l.msg, start, len);
      if (!s) {
        throw std::invalid_argument(fmt::format(
            "{}: message {} (0x{:03X}) has no {} signal at bit {} ({} bits, Intel, integer)",
            source_name, l.msg->name, l.msg->id, field, start, len));
      }
      return s;
    };
    l.a = need(a_start, a_len, a_what);
    l.b = need(b_start, b_len, b_what);
  };
  bind(rpdo1_, Function::kRpdo1, "RPDO1", 0, 16, "controlword 0x6040", 16, 32,
       "target velocity 0x60FF");
  bind(tpdo1_, Function::kTpdo1, "TPDO1", 0, 16, "statusword 0x6041", 16, 32,
       "velocity actual 0x606C");
  bind(tpdo2_, Function::kTpdo2, "TPDO2", 0, 32, "position actual 0x6064", 32, 16,
       "torque actual 0x6077");
}

DriveProtocol DriveProtocol::LoadDir(const std::string& dir, const std::vector<int>& node_ids) {
  const std::filesystem::path p = std::filesystem::path(dir) / kDefaultFile;
  if (!std::filesystem::exists(p)) {
    throw std::invalid_argument(fmt::format("{}: DBC file not found", p.string()));
  }
  return DriveProtocol(
      std::make_shared<const bus::DbcDatabase>(bus::DbcDatabase::LoadFile(p.string())), p.string(),
      node_ids);
}

bool DriveProtocol::EncodeRpdo1(std::uint8_t node_id, std::uint16_t controlword,
                                std::int32_t target_velocity, bus::CanFrame& out) const noexcept {
  if (!canopen::IsValidNodeId(node_id)) return false;
  out = BlankFrame(canopen::CobId(Function::kRpdo1, node_id), *rpdo1_.msg);
  return bus::InsertRaw(*rpdo1_.a, controlword, out.data) &&
         bus::InsertRaw(*rpdo1_.b, static_cast<std::uint32_t>(target_velocity), out.data);
}

int DriveProtocol::TpdoOf(const bus::CanFrame& f, std::uint8_t& node_id) const noexcept {
  node_id = 0;
  if (f.error || f.extended || f.rtr || f.fd) return 0;
  const std::uint8_t node = canopen::NodeOf(f.id);
  if (node == 0) return 0;
  if (canopen::Is(Function::kTpdo1, f.id)) {
    node_id = node;
    return 1;
  }
  if (canopen::Is(Function::kTpdo2, f.id)) {
    node_id = node;
    return 2;
  }
  return 0;
}

bool DriveProtocol::DecodeTpdo1(const bus::CanFrame& f, std::uint16_t& statusword,
                                std::int32_t& velocity_actual) const noexcept {
  if (f.len != tpdo1_.msg->length) return false;
  std::uint64_t sw = 0;
  std::int64_t v = 0;
  if (!bus::ExtractRaw(*tpdo1_.a, f.payload(), sw) ||
      !bus::ExtractRawSigned(*tpdo1_.b, f.payload(), v)) {
    return false;
  }
  statusword = static_cast<std::uint16_t>(sw);
  velocity_actual = static_cast<std::int32_t>(v);
  return true;
}

bool DriveProtocol::DecodeTpdo2(const bus::CanFrame& f, std::int32_t& position_actual,
                                std::int16_t& torque_actual) const noexcept {
  if (f.len != tpdo2_.msg->length) return false;
  std::int64_t p = 0, t = 0;
  if (!bus::ExtractRawSigned(*tpdo2_.a, f.payload(), p) ||
      !bus::ExtractRawSigned(*tpdo2_.b, f.payload(), t)) {
    return false;
  }
  position_actual = static_cast<std::int32_t>(p);
  torque_actual = static_cast<std::int16_t>(t);
  return true;
}

}  // namespace wheelhil::fw
