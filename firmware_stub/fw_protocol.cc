#include "firmware_stub/fw_protocol.h"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <stdexcept>

#include "bus/canopen.h"
#include "bus/dbc_codec.h"
#include "bus/install_paths.h"
#include "firmware_stub/dbc_binding.h"

namespace wheelhil::fw {
namespace {

using bus::CanFrame;
using bus::DbcDatabase;
using bus::DbcMessage;
using bus::DbcSignal;
namespace canopen = bus::canopen;
using canopen::Function;

constexpr double kPi = 3.14159265358979323846;
constexpr double kStandardGravity = 9.80665;

std::string Lower(std::string s) {
  std::string out;
  for (char c : s) {
    if (std::isalnum(static_cast<unsigned char>(c))) {
      out += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    }
  }
  return out;
}

bool Has(const std::string& s, const char* part) { return s.find(part) != std::string::npos; }
bool Starts(const std::string& s, const char* part) { return s.rfind(part, 0) == 0; }

/// Multiplier from a rate signal's unit to rad/s; 0 when the unit is not a rate.
double RateScale(const std::string& unit) {
  const std::string u = Lower(unit);
  if (u == "rads" || u == "rad/s") return 1.0;
  if (u == "degs" || u == "s" || Has(unit, "deg") || Has(unit, "\xC2\xB0")) return kPi / 180.0;
  return 0.0;
}

/// Multiplier from an acceleration signal's unit to m/s^2; 0 when not an acceleration.
double AccelScale(const std::string& unit) {
  const std::string u = Lower(unit);
  if (u == "g") return kStandardGravity;
  if (u == "mg") return kStandardGravity * 1e-3;
  if (u == "ms2" || u == "ms" || Has(unit, "m/s")) return 1.0;
  return 0.0;
}

bool Decode(const DbcSignal* s, const CanFrame& f, double& v) {
  v = bus::DecodeSignal(*s, f.payload());
  return std::isfinite(v);
}

std::uint64_t RawOf(const DbcSignal* s, const CanFrame& f) {
  std::uint64_t raw = 0;
  if (!bus::ExtractRaw(*s, f.payload(), raw)) return 0;
  return raw;
}

/// Fields sent as raw bits: counters wrap, masks are truncated to the signal's width.
bool IsRawField(OutField f) {
  return f == OutField::kCycle || f == OutField::kHeartbeat || f == OutField::kFaults ||
         f == OutField::kNodesLost;
}

}  // namespace

const char* OutMessageName(OutMessage m) noexcept {
  switch (m) {
    case OutMessage::kPose:
      return "FW_Pose";
    case OutMessage::kPoseRaw:
      return "FW_PoseRaw";
    case OutMessage::kSlipStatus:
      return "FW_SlipStatus";
    case OutMessage::kVelocity:
      return "FW_Velocity";
    case OutMessage::kVelocityOdom:
      return "FW_VelocityOdom";
    case OutMessage::kVelocityAccel:
      return "FW_VelocityAccel";
    case OutMessage::kStatus:
      return "FW_Status";
    case OutMessage::kCount:
      break;
  }
  return "?";
}

OutField NodeLostField(int node_id) noexcept {
  if (node_id < 1 || node_id > 8) return OutField::kNone;
  return static_cast<OutField>(static_cast<int>(OutField::kNodeLostEnc1) + node_id - 1);
}

namespace {

OutField ClassifyNormalised(const std::string& n) {
  if (n.empty()) return OutField::kNone;
  if (Has(n, "heartbeat") || Has(n, "alive") || Starts(n, "hb")) return OutField::kHeartbeat;
  if (Has(n, "badframecount") || Has(n, "badframes")) return OutField::kBadFrameCount;
  if (Has(n, "emcynode")) return OutField::kEmcyNodeId;
  if (Starts(n, "nodelost") || Starts(n, "lost")) {
    std::string rest = n.substr(Starts(n, "nodelost") ? 8 : 4);
    if (Starts(rest, "enc")) rest = rest.substr(3);
    if (rest == "imu") return OutField::kNodeLostImu;
    if (rest == "accel" || rest == "acc") return OutField::kNodeLostAccel;
    if (rest.size() == 1 && rest[0] >= '1' && rest[0] <= '8') return NodeLostField(rest[0] - '0');
    if (rest.empty() || rest == "mask" || rest == "nodes") return OutField::kNodesLost;
    return OutField::kNone;
  }
  if (Has(n, "nodeslost") || Has(n, "lostnodes")) return OutField::kNodesLost;
  if (Has(n, "fault") || Starts(n, "err")) {
    if (Has(n, "boot")) return OutField::kFaultBootTimeout;
    if (Has(n, "lost")) return OutField::kFaultNodeLost;
    if (Has(n, "emcy") || Has(n, "emergency")) return OutField::kFaultEmcy;
    if (Has(n, "sdo")) return OutField::kFaultSdo;
    if (Has(n, "badframe") || Has(n, "dlc") || Has(n, "traffic") || Has(n, "garbage")) {
      return OutField::kFaultBadFrame;
    }
    if (Has(n, "incomplete") || Has(n, "missing")) return OutField::kFaultCycleIncomplete;
    if (Has(n, "late") || Has(n, "dup")) return OutField::kFaultLateFrame;
    if (Has(n, "estim") || Has(n, "reject")) return OutField::kFaultEstimator;
    if (Has(n, "config")) return OutField::kFaultConfig;
    return OutField::kFaults;
  }
  if (Has(n, "cycle") || n == "counter" || n == "seq" || n == "sequence") return OutField::kCycle;
  if (n == "state" || n == "fwstate" || n == "mode") return OutField::kState;
  if (Has(n, "unattributed")) return OutField::kSlipUnattributed;
  if (n == "left" || n == "slipleft" || n == "leftslip") return OutField::kSlipLeft;
  if (n == "right" || n == "slipright" || n == "rightslip") return OutField::kSlipRight;
  if (Has(n, "outofband") || n == "slip" || n == "detected" || n == "slipdetected") {
    return OutField::kOutOfBand;
  }
  if (Has(n, "calibrated")) return OutField::kCalibrated;
  if (Has(n, "residual")) return OutField::kResidual;
  if (Has(n, "bandlow") || Has(n, "bandlo") || n == "lower" || Has(n, "bandmin")) {
    return OutField::kBandLow;
  }
  if (Has(n, "bandhigh") || Has(n, "bandup") || Has(n, "bandhi") || n == "upper" ||
      Has(n, "bandmax")) {
    return OutField::kBandHigh;
  }
  if (n == "vx" || n == "vxms") return OutField::kVx;
  if (n == "vy" || n == "vyms") return OutField::kVy;
  if (n == "omega" || n == "omegarads" || n == "yawrate" || n == "wz") return OutField::kOmega;
  if (n == "theta" || n == "thetarad" || n == "heading" || n == "yaw") return OutField::kTheta;
  if (n == "x" || n == "xm" || n == "posx") return OutField::kX;
  if (n == "y" || n == "ym" || n == "posy") return OutField::kY;
  return OutField::kNone;
}

}  // namespace

OutField ClassifyOutputSignal(const std::string& name) noexcept {
  const OutField whole = ClassifyNormalised(Lower(name));
  if (whole != OutField::kNone) return whole;
  // Without the message prefix: `Pose_X` -> `X`.
  const auto us = name.find('_');
  if (us == std::string::npos) return OutField::kNone;
  return ClassifyNormalised(Lower(name.substr(us + 1)));
}

FwProtocol::FwProtocol(Sources sources, const std::vector<int>& node_ids, std::uint32_t imu_yaw_id,
                       std::uint32_t accel_id)
    : src_(std::move(sources)), imu_yaw_id_(imu_yaw_id), accel_id_(accel_id) {
  if (!src_.cia406 || !src_.fw) throw std::invalid_argument("protocol: missing DBC database");
  const DbcDatabase& co = *src_.cia406;
  const std::string& cn = src_.cia406_name;
  auto need_msg = [&](const DbcMessage* m, const char* what) {
    if (!m) throw std::invalid_argument(fmt::format("{}: no {} message", cn, what));
    return m;
  };
  auto need_sig = [&](Layout& l, int slot, int start, int len, const char* what) {
    l.sig[slot] = SignalAt(*l.msg, start, len);
    if (!l.sig[slot]) {
      throw std::invalid_argument(fmt::format(
          "{}: message {} (0x{:03X}) has no {} signal at bit {} ({} bits, Intel, integer)", cn,
          l.msg->name, l.msg->id, what, start, len));
    }
  };
  nmt_.msg = need_msg(co.FindMessage(canopen::kNmtCobId, false), "NMT module control (0x000)");
  need_sig(nmt_, 0, 0, 8, "command specifier");
  need_sig(nmt_, 1, 8, 8, "node id");
  sync_.msg = need_msg(co.FindMessage(canopen::kSyncCobId, false), "SYNC (0x080)");
  emcy_.msg = need_msg(FindFunction(co, Function::kEmcy, node_ids), "EMCY (0x080+id)");
  need_sig(emcy_, 0, 0, 16, "EMCY error code");
  need_sig(emcy_, 1, 16, 8, "EMCY error register");
  tpdo_.msg = need_msg(FindFunction(co, Function::kTpdo1, node_ids), "TPDO1 (0x180+id)");
  need_sig(tpdo_, 0, 0, 32, "position value 0x6004");
  need_sig(tpdo_, 1, 32, 16, "speed value 0x6030");
  for (Layout* l : {&sdo_rx_, &sdo_tx_}) {
    const bool response = l == &sdo_rx_;
    l->msg = need_msg(
        FindFunction(co, response ? Function::kSdoResponse : Function::kSdoRequest, node_ids),
        response ? "SDO response (0x580+id)" : "SDO request (0x600+id)");
    need_sig(*l, 0, 0, 8, "SDO command");
    need_sig(*l, 1, 8, 16, "SDO index");
    need_sig(*l, 2, 24, 8, "SDO subindex");
    need_sig(*l, 3, 32, 32, "SDO data");
  }
  errctl_.msg =
      need_msg(FindFunction(co, Function::kErrorControl, node_ids), "NMT error control (0x700+id)");
  need_sig(errctl_, 0, 0, 8, "NMT state");

  if (imu_yaw_id_ != 0) {
    if (!src_.imu) throw std::invalid_argument(fmt::format("{}: not loaded", src_.imu_name));
    imu_db_ = src_.imu.get();
    imu_yaw_.msg = imu_db_->FindMessage(imu_yaw_id_, false);
    if (!imu_yaw_.msg) {
      throw std::invalid_argument(fmt::format("{}: no message with id 0x{:03X} (imu.yaw_frame_id)",
                                              src_.imu_name, imu_yaw_id_));
    }
    imu_yaw_.sig[0] = SignalAt(*imu_yaw_.msg, 0, 16);
    if (!imu_yaw_.sig[0] || RateScale(imu_yaw_.sig[0]->unit) == 0.0) {
      throw std::invalid_argument(fmt::format(
          "{}: message {} has no yaw-rate signal at bit 0 (16 bits, unit deg/s or rad/s)",
          src_.imu_name, imu_yaw_.msg->name));
    }
    yaw_scale_ = RateScale(imu_yaw_.sig[0]->unit);
  }
  if (accel_id_ != 0) {
    if (!src_.accel) throw std::invalid_argument(fmt::format("{}: not loaded", src_.accel_name));
    accel_.msg = src_.accel->FindMessage(accel_id_, false);
    if (!accel_.msg) {
      throw std::invalid_argument(fmt::format("{}: no message with id 0x{:03X} (accel.frame_id)",
                                              src_.accel_name, accel_id_));
    }
    std::vector<const DbcSignal*> acc;
    for (const auto& s : accel_.msg->signals) {
      if (!s.multiplex_value && AccelScale(s.unit) != 0.0) acc.push_back(&s);
    }
    std::sort(acc.begin(), acc.end(),
              [](const DbcSignal* a, const DbcSignal* b) { return a->start_bit < b->start_bit; });
    if (acc.size() != 4) {
      throw std::invalid_argument(fmt::format(
          "{}: message {} has {} acceleration signals (unit m/s^2 or g), need exactly 4",
          src_.accel_name, accel_.msg->name, acc.size()));
    }
    for (int i = 0; i < 4; ++i) {
      accel_.sig[i] = acc[i];
      accel_scale_[i] = AccelScale(acc[i]->unit);
    }
    for (const auto& s : accel_.msg->signals) {
      const std::string n = Lower(s.name);
      if (Has(n, "counter")) accel_counter_ = &s;
      if (Has(n, "checksum") && s.little_endian && s.start_bit == 60 && s.length == 4) {
        accel_checksum_ = &s;
      }
    }
  }

  for (std::size_t i = 0; i < outputs_.size(); ++i) {
    const char* name = OutMessageName(static_cast<OutMessage>(i));
    const DbcMessage* m = src_.fw->FindMessage(name);
    if (!m) continue;
    outputs_[i].msg = m;
    for (const auto& s : m->signals) {
      const OutField f = ClassifyOutputSignal(s.name);
      if (f == OutField::kNone) {
        unbound_.push_back(fmt::format("{}.{}", m->name, s.name));
      } else {
        outputs_[i].fields.emplace_back(&s, f);
      }
    }
  }
  for (OutMessage m : {OutMessage::kPose, OutMessage::kStatus}) {
    if (!HasOutput(m)) {
      throw std::invalid_argument(
          fmt::format("{}: no message {} (required)", src_.fw_name, OutMessageName(m)));
    }
  }
}

FwProtocol FwProtocol::LoadDir(const std::string& dir, const std::vector<int>& node_ids,
                               std::uint32_t imu_yaw_id, std::uint32_t accel_id) {
  namespace fs = std::filesystem;
  Sources s;
  auto load = [&](const std::string& name) {
    const fs::path p = fs::path(dir) / name;
    std::error_code ec;
    if (!fs::exists(p, ec)) {
      throw std::invalid_argument(fmt::format("{}: DBC file not found", p.string()));
    }
    return std::make_shared<const DbcDatabase>(DbcDatabase::LoadFile(p.string()));
  };
  s.cia406 = load(s.cia406_name);
  s.fw = load(s.fw_name);
  if (imu_yaw_id != 0) s.imu = load(s.imu_name);
  if (accel_id != 0) s.accel = load(s.accel_name);
  s.cia406_name = (fs::path(dir) / s.cia406_name).string();
  s.fw_name = (fs::path(dir) / s.fw_name).string();
  s.imu_name = (fs::path(dir) / s.imu_name).string();
  s.accel_name = (fs::path(dir) / s.accel_name).string();
  return FwProtocol(std::move(s), node_ids, imu_yaw_id, accel_id);
}

std::string FwProtocol::FindDbcDir(const std::string& configured, const std::string& exe_dir) {
  if (!configured.empty()) return configured;
  if (const char* env = std::getenv("WHEELHIL_DBC_DIR"); env && *env) return env;
  return bus::FindShippedDbcDir(exe_dir);
}

FrameKind FwProtocol::Classify(const CanFrame& f, std::uint8_t& node_id) const noexcept {
  node_id = 0;
  if (f.error || f.extended || f.rtr || f.fd) return FrameKind::kUnknown;
  const std::uint32_t id = f.id;
  if (imu_yaw_id_ != 0 && id == imu_yaw_id_) return FrameKind::kImuYaw;
  if (accel_id_ != 0 && id == accel_id_) return FrameKind::kAccel;
  if (imu_db_ && imu_db_->FindMessage(id, false)) return FrameKind::kImuOther;
  for (const auto& o : outputs_) {
    if (o.msg && o.msg->id == id) return FrameKind::kOwnOutput;
  }
  const std::uint8_t node = canopen::NodeOf(id);
  if (id == canopen::kNmtCobId) return FrameKind::kNmt;
  if (id == canopen::kSyncCobId) return FrameKind::kSync;
  if (node == 0) return FrameKind::kUnknown;
  node_id = node;
  switch (static_cast<Function>(canopen::FunctionCodeOf(id))) {
    case Function::kEmcy:
      return FrameKind::kEmcy;
    case Function::kTpdo1:
      return FrameKind::kTpdo1;
    case Function::kSdoResponse:
      return FrameKind::kSdoResponse;
    case Function::kSdoRequest:
      return FrameKind::kSdoRequest;
    case Function::kErrorControl:
      return FrameKind::kErrorControl;
    default:
      break;
  }
  node_id = 0;
  return FrameKind::kUnknown;
}

bool FwProtocol::EncodeNmt(std::uint8_t command, std::uint8_t node_id,
                           CanFrame& out) const noexcept {
  out = BlankFrame(canopen::kNmtCobId, *nmt_.msg);
  return bus::InsertRaw(*nmt_.sig[0], command, out.data) &&
         bus::InsertRaw(*nmt_.sig[1], node_id, out.data);
}

bool FwProtocol::EncodeSync(CanFrame& out) const noexcept {
  out = BlankFrame(canopen::kSyncCobId, *sync_.msg);
  out.len = 0;  // SYNC without counter (CiA 301 0x1019 = 0).
  return true;
}

bool FwProtocol::EncodeSdoRequest(std::uint8_t node_id, const SdoFrame& sdo,
                                  CanFrame& out) const noexcept {
  out = BlankFrame(canopen::CobId(Function::kSdoRequest, node_id), *sdo_tx_.msg);
  return bus::InsertRaw(*sdo_tx_.sig[0], sdo.command, out.data) &&
         bus::InsertRaw(*sdo_tx_.sig[1], sdo.index, out.data) &&
         bus::InsertRaw(*sdo_tx_.sig[2], sdo.subindex, out.data) &&
         bus::InsertRaw(*sdo_tx_.sig[3], sdo.data, out.data);
}

bool FwProtocol::EncodeHeartbeat(std::uint8_t node_id, std::uint8_t state,
                                 CanFrame& out) const noexcept {
  if (!canopen::IsValidNodeId(node_id)) return false;
  out = BlankFrame(canopen::CobId(Function::kErrorControl, node_id), *errctl_.msg);
  return bus::InsertRaw(*errctl_.sig[0], state, out.data);
}

bool FwProtocol::DecodeErrorControl(const CanFrame& f, std::uint8_t& state) const noexcept {
  if (f.len != errctl_.msg->length) return false;
  state = static_cast<std::uint8_t>(RawOf(errctl_.sig[0], f));
  return true;
}

bool FwProtocol::DecodeEmcy(const CanFrame& f, std::uint16_t& code,
                            std::uint8_t& error_register) const noexcept {
  if (f.len != emcy_.msg->length) return false;
  code = static_cast<std::uint16_t>(RawOf(emcy_.sig[0], f));
  error_register = static_cast<std::uint8_t>(RawOf(emcy_.sig[1], f));
  return true;
}

bool FwProtocol::DecodeTpdo1(const CanFrame& f, std::uint32_t& position,
                             std::int16_t& speed) const noexcept {
  if (f.len != tpdo_.msg->length) return false;
  position = static_cast<std::uint32_t>(RawOf(tpdo_.sig[0], f));
  speed = static_cast<std::int16_t>(static_cast<std::uint16_t>(RawOf(tpdo_.sig[1], f)));
  return true;
}

bool FwProtocol::DecodeSdoResponse(const CanFrame& f, SdoFrame& sdo) const noexcept {
  if (f.len != sdo_rx_.msg->length) return false;
  sdo.command = static_cast<std::uint8_t>(RawOf(sdo_rx_.sig[0], f));
  sdo.index = static_cast<std::uint16_t>(RawOf(sdo_rx_.sig[1], f));
  sdo.subindex = static_cast<std::uint8_t>(RawOf(sdo_rx_.sig[2], f));
  sdo.data = static_cast<std::uint32_t>(RawOf(sdo_rx_.sig[3], f));
  return true;
}

bool FwProtocol::DecodeYawRate(const CanFrame& f, double& rate_rad_s) const noexcept {
  if (!imu_yaw_.msg || f.len != imu_yaw_.msg->length) return false;
  double v = 0.0;
  if (!Decode(imu_yaw_.sig[0], f, v)) return false;
  rate_rad_s = v * yaw_scale_;
  return true;
}

bool FwProtocol::DecodeAccel(const CanFrame& f, std::array<double, 4>& a_m_s2,
                             int& counter) const noexcept {
  if (!accel_.msg || f.len != accel_.msg->length) return false;
  if (accel_checksum_ && f.len == 8) {
    std::uint8_t x = static_cast<std::uint8_t>(f.data[7] & 0x0F);
    for (int i = 0; i < 7; ++i)
      x ^= static_cast<std::uint8_t>((f.data[i] & 0x0F) ^ (f.data[i] >> 4));
    if (x != RawOf(accel_checksum_, f)) return false;
  }
  counter = accel_counter_ ? static_cast<int>(RawOf(accel_counter_, f)) : -1;
  for (int i = 0; i < 4; ++i) {
    double v = 0.0;
    if (!Decode(accel_.sig[i], f, v)) return false;
    a_m_s2[i] = v * accel_scale_[i];
  }
  return true;
}

std::vector<OutField> FwProtocol::OutputFields(OutMessage m) const {
  std::vector<OutField> out;
  for (const auto& [sig, field] : outputs_[static_cast<std::size_t>(m)].fields) {
    out.push_back(field);
  }
  return out;
}

bool FwProtocol::EncodeOutput(OutMessage m, const OutValues& values, CanFrame& out) const noexcept {
  const Output& o = outputs_[static_cast<std::size_t>(m)];
  if (!o.msg) return false;
  out = BlankFrame(o.msg->id, *o.msg);
  bool ok = true;
  for (const auto& [sig, field] : o.fields) {
    const double v = values.Get(field);
    if (IsRawField(field)) {
      // Counters wrap and bit masks are truncated to the signal's width: raw bits, no scaling.
      const std::uint64_t raw = v > 0 ? static_cast<std::uint64_t>(v) : 0;
      ok = bus::InsertRaw(*sig, raw, out.data) && ok;
    } else {
      ok = bus::EncodeSignal(*sig, v, out.data) && ok;
    }
  }
  return ok;
}

bool FwProtocol::DecodeOutput(OutMessage m, const CanFrame& f, OutValues& values) const noexcept {
  const Output& o = outputs_[static_cast<std::size_t>(m)];
  if (!o.msg || f.id != o.msg->id || f.len != o.msg->length) return false;
  for (const auto& [sig, field] : o.fields) {
    if (IsRawField(field)) {
      values.Set(field, static_cast<double>(RawOf(sig, f)));
    } else {
      values.Set(field, bus::DecodeSignal(*sig, f.payload()));
    }
  }
  return true;
}

}  // namespace wheelhil::fw
