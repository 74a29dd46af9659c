#include "emulator/devices/dbc_cia406_codec.h"

#include <fmt/format.h>

#include <cmath>
#include <limits>
#include <stdexcept>
#include <utility>

#include "bus/canopen.h"
#include "bus/dbc_codec.h"

namespace wheelhil::emulator {
namespace {

namespace canopen = bus::canopen;
using canopen::Function;

constexpr std::initializer_list<const char*> kNmtSignals = {"NMT_CommandSpecifier", "NMT_NodeId"};
constexpr std::initializer_list<const char*> kEmcySignals = {"EMCY_ErrorCode", "EMCY_ErrorRegister",
                                                             "EMCY_Manufacturer"};
constexpr std::initializer_list<const char*> kTpdoSignals = {"PositionValue", "SpeedValue"};
constexpr std::initializer_list<const char*> kSdoSignals = {"SDO_Command", "SDO_Index",
                                                            "SDO_SubIndex", "SDO_Data"};
constexpr std::initializer_list<const char*> kHeartbeatSignals = {"NMT_State"};

// A decoded physical value as an unsigned integer field; false unless integral and in range.
template <typename T>
bool ToField(double v, T& out) {
  if (!(v >= 0.0) || v > static_cast<double>(std::numeric_limits<T>::max()) || std::floor(v) != v) {
    return false;
  }
  out = static_cast<T>(v);
  return true;
}

}  // namespace

DbcCia406Codec::DbcCia406Codec(bus::DbcDatabase database) : database_(std::move(database)) {
  nmt_ = Resolve(canopen::kNmtCobId, kNmtSignals);
  if (nmt_.message == nullptr) {
    throw std::invalid_argument(
        "cia406 DBC: message 0x000 with signals NMT_CommandSpecifier and NMT_NodeId is required");
  }
  for (std::size_t i = 1; i < nodes_.size(); ++i) {
    const auto id = static_cast<std::uint8_t>(i);
    nodes_[i] =
        NodeLayouts{Resolve(canopen::CobId(Function::kEmcy, id), kEmcySignals),
                    Resolve(canopen::CobId(Function::kTpdo1, id), kTpdoSignals),
                    Resolve(canopen::CobId(Function::kSdoResponse, id), kSdoSignals),
                    Resolve(canopen::CobId(Function::kSdoRequest, id), kSdoSignals),
                    Resolve(canopen::CobId(Function::kErrorControl, id), kHeartbeatSignals)};
  }
}

std::shared_ptr<const DbcCia406Codec> DbcCia406Codec::FromFile(const std::string& path) {
  return std::make_shared<const DbcCia406Codec>(bus::DbcDatabase::LoadFile(path));
}

DbcCia406Codec::Layout DbcCia406Codec::Resolve(std::uint32_t id,
                                               std::initializer_list<const char*> names) const {
  Layout layout;
  const bus::DbcMessage* msg = database_.FindMessage(id, /*extended=*/false);
  if (msg == nullptr || msg->length < 0 ||
      msg->length > static_cast<int>(bus::CanFrame::kMaxClassicLen)) {
    return layout;
  }
  std::size_t i = 0;
  for (const char* name : names) {
    const bus::DbcSignal* sig = msg->FindSignal(name);
    if (sig == nullptr) return layout;
    layout.signals[i++] = sig;
  }
  layout.message = msg;
  return layout;
}

bool DbcCia406Codec::SupportsNode(std::uint8_t node_id) const {
  if (node_id < 1 || node_id >= nodes_.size()) return false;
  const NodeLayouts& n = nodes_[node_id];
  return n.emcy.message && n.tpdo1.message && n.sdo_tx.message && n.sdo_rx.message &&
         n.heartbeat.message;
}

bool DbcCia406Codec::Encode(const Layout& layout, std::initializer_list<double> physical,
                            bus::CanFrame& out) {
  if (layout.message == nullptr) return false;
  const bus::DbcMessage& msg = *layout.message;
  out = bus::CanFrame{};
  out.id = msg.id;
  out.extended = msg.extended;
  out.len = static_cast<std::uint8_t>(msg.length);
  const std::span<std::uint8_t> payload(out.data.data(), out.len);
  std::size_t i = 0;
  for (double value : physical) {
    const bus::DbcSignal* sig = layout.signals[i++];
    if (sig == nullptr || !bus::EncodeSignal(*sig, value, payload)) return false;
  }
  return true;
}

bool DbcCia406Codec::Decode(const Layout& layout, const bus::CanFrame& frame,
                            std::array<double, 4>& physical) {
  if (layout.message == nullptr || frame.len != layout.message->length || frame.rtr || frame.fd ||
      frame.error) {
    return false;
  }
  const std::span<const std::uint8_t> payload(frame.data.data(), frame.len);
  for (std::size_t i = 0; i < physical.size(); ++i) {
    physical[i] = 0.0;
    if (layout.signals[i] == nullptr) continue;
    physical[i] = bus::DecodeSignal(*layout.signals[i], payload);
    if (std::isnan(physical[i])) return false;
  }
  return true;
}

bool DbcCia406Codec::EncodeNmtState(std::uint8_t node_id, std::uint8_t state,
                                    bus::CanFrame& out) const {
  if (!SupportsNode(node_id)) return false;
  return Encode(nodes_[node_id].heartbeat, {static_cast<double>(state)}, out);
}

bool DbcCia406Codec::EncodeTpdo1(std::uint8_t node_id, std::uint32_t cob_id, std::uint32_t position,
                                 std::int16_t speed, bus::CanFrame& out) const {
  if (!SupportsNode(node_id) || cob_id > bus::CanFrame::kMaxStandardId) return false;
  if (!Encode(nodes_[node_id].tpdo1, {static_cast<double>(position), static_cast<double>(speed)},
              out)) {
    return false;
  }
  out.id = cob_id;  // a COB-ID reconfigured through 0x1800:1 keeps the DBC layout
  return true;
}

bool DbcCia406Codec::EncodeEmcy(std::uint8_t node_id, std::uint16_t error_code,
                                std::uint8_t error_register, bus::CanFrame& out) const {
  if (!SupportsNode(node_id)) return false;
  return Encode(nodes_[node_id].emcy,
                {static_cast<double>(error_code), static_cast<double>(error_register), 0.0}, out);
}

bool DbcCia406Codec::EncodeSdoResponse(std::uint8_t node_id, const SdoFields& sdo,
                                       bus::CanFrame& out) const {
  if (!SupportsNode(node_id)) return false;
  return Encode(nodes_[node_id].sdo_tx,
                {static_cast<double>(sdo.command), static_cast<double>(sdo.index),
                 static_cast<double>(sdo.subindex), static_cast<double>(sdo.data)},
                out);
}

bool DbcCia406Codec::DecodeNmt(const bus::CanFrame& frame, std::uint8_t& command,
                               std::uint8_t& node_id) const {
  if (frame.id != canopen::kNmtCobId || frame.extended) return false;
  std::array<double, 4> v{};
  std::uint8_t cs = 0, node = 0;
  if (!Decode(nmt_, frame, v) || !ToField(v[0], cs) || !ToField(v[1], node)) return false;
  command = cs;
  node_id = node;
  return true;
}

bool DbcCia406Codec::DecodeSdoRequest(const bus::CanFrame& frame, SdoFields& sdo) const {
  if (frame.extended || !canopen::IsSdoRequest(frame.id)) return false;
  std::array<double, 4> v{};
  SdoFields s;
  if (!Decode(nodes_[canopen::NodeOf(frame.id)].sdo_rx, frame, v) || !ToField(v[0], s.command) ||
      !ToField(v[1], s.index) || !ToField(v[2], s.subindex) || !ToField(v[3], s.data)) {
    return false;
  }
  sdo = s;
  return true;
}

}  // namespace wheelhil::emulator
