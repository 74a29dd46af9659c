#include "emulator/devices/canopen_encoder_node.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "bus/canopen.h"

namespace wheelhil::emulator {
namespace {

namespace canopen = bus::canopen;
namespace sdo = bus::canopen::sdo;
namespace od = bus::canopen::od;

constexpr std::int64_t kNever = std::numeric_limits<std::int64_t>::max();
constexpr std::int64_t kNsPerMs = 1'000'000;

// Fixed TPDO1 mapping entries: index << 16 | sub << 8 | bit length.
constexpr std::uint32_t kMapPosition = 0x60040020;
constexpr std::uint32_t kMapSpeed = 0x60300110;

bool ValidTransmissionType(std::uint32_t t) { return t <= 240 || t == 254 || t == 255; }

}  // namespace

CanopenEncoderNode::CanopenEncoderNode(const Cia406NodeConfig& config,
                                       std::shared_ptr<const Cia406Codec> codec,
                                       std::int64_t power_on_ns)
    : config_(config), codec_(std::move(codec)), now_ns_(power_on_ns) {
  if (!canopen::IsValidNodeId(config.node_id)) {
    throw std::invalid_argument(
        fmt::format("encoder_node.node_id ({}) must be in 1..127", config.node_id));
  }
  if (!ValidTransmissionType(config.tpdo1_transmission_type)) {
    throw std::invalid_argument(
        fmt::format("encoder_node.tpdo1_transmission_type ({}) must be 0..240, 254 or 255",
                    config.tpdo1_transmission_type));
  }
  if (config.power_on_delay_ns < 0 || config.reset_delay_ns < 0 || config.response_delay_ns < 0) {
    throw std::invalid_argument("encoder_node: power_on/reset/response delays must be >= 0");
  }
  if (!(config.speed_time_base_s > 0.0) || !std::isfinite(config.speed_time_base_s)) {
    throw std::invalid_argument(fmt::format(
        "encoder_node.speed_time_base_s ({}) must be finite and > 0", config.speed_time_base_s));
  }
  if (!codec_) throw std::invalid_argument("encoder_node: a frame codec is required");
  if (!codec_->SupportsNode(config.node_id)) {
    throw std::invalid_argument(fmt::format(
        "encoder_node.node_id ({}): the frame codec (DBC) has no messages for this node",
        config.node_id));
  }
  ResetApplication();
  ResetCommunication();
  ScheduleBoot(power_on_ns + config.power_on_delay_ns);
}

void CanopenEncoderNode::ResetApplication() {
  operating_parameters_ = config_.operating_parameters;
  error_register_ = 0;
  ResetExtraObjects(false);
}

void CanopenEncoderNode::ResetExtraObjects(bool communication) {
  if (extra_.size() != config_.extra_objects.size()) extra_ = config_.extra_objects;
  for (std::size_t i = 0; i < extra_.size(); ++i) {
    const bool comm_area = extra_[i].index >= 0x1000 && extra_[i].index < 0x2000;
    if (comm_area == communication) extra_[i].value = config_.extra_objects[i].value;
  }
}

void CanopenEncoderNode::ResetCommunication() {
  ResetExtraObjects(true);
  heartbeat_ms_ = config_.heartbeat_ms;
  tpdo1_cob_id_ = canopen::CobId(canopen::Function::kTpdo1, config_.node_id);
  tpdo1_type_ = config_.tpdo1_transmission_type;
  cyclic_timer_ms_ = config_.cyclic_timer_ms;
}

void CanopenEncoderNode::ScheduleBoot(std::int64_t t_ns) {
  state_ = NmtState::kOff;
  boot_due_ns_ = t_ns;
  next_heartbeat_ns_ = kNever;
  next_tpdo_ns_ = kNever;
  sync_count_ = 0;
}

void CanopenEncoderNode::EnterOperational(std::int64_t t_ns) {
  state_ = NmtState::kOperational;
  sync_count_ = 0;
  have_last_tpdo_position_ = false;
  const bool cyclic = tpdo1_type_ >= 254 && cyclic_timer_ms_ > 0;
  next_tpdo_ns_ = cyclic ? t_ns + cyclic_timer_ms_ * kNsPerMs : kNever;
}

void CanopenEncoderNode::SetMeasurement(std::uint32_t position_counts,
                                        double speed_counts_per_s) noexcept {
  position_counts_ = position_counts;
  speed_counts_per_s_ = speed_counts_per_s;
}

std::uint32_t CanopenEncoderNode::ReportedPosition() const {
  // 0x6000 bit 0 (code sequence): counting direction inverted.
  if (operating_parameters_ & 0x0001) return 0u - position_counts_;
  return position_counts_;
}

std::int16_t CanopenEncoderNode::ReportedSpeed() const {
  double v = speed_counts_per_s_ * config_.speed_time_base_s;
  if (operating_parameters_ & 0x0001) v = -v;
  if (std::isnan(v)) return 0;
  v = std::round(v);
  v = std::clamp(v, -32768.0, 32767.0);
  return static_cast<std::int16_t>(v);
}

void CanopenEncoderNode::Emit(bool ok, const bus::CanFrame& frame, std::int64_t due_ns,
                              std::vector<NodeFrame>& out) {
  if (ok) out.push_back(NodeFrame{frame, due_ns});
}

void CanopenEncoderNode::EmitTpdo(std::int64_t due_ns, std::vector<NodeFrame>& out) {
  if (tpdo1_cob_id_ & canopen::kPdoCobIdInvalid) return;
  bus::CanFrame f;
  const std::uint32_t position = ReportedPosition();
  Emit(codec_->EncodeTpdo1(config_.node_id, tpdo1_cob_id_ & 0x7FF, position, ReportedSpeed(), f), f,
       due_ns, out);
  have_last_tpdo_position_ = true;
  last_tpdo_position_ = position;
}

std::vector<NodeFrame> CanopenEncoderNode::OnFrame(const bus::CanFrame& frame, std::int64_t t_ns) {
  std::vector<NodeFrame> out;
  if (frame.extended || frame.rtr || frame.error || frame.fd) return out;
  if (t_ns > now_ns_) {
    // Timed events up to the frame's arrival happen first; the caller collects them by Poll.
    std::vector<NodeFrame> timed = Poll(t_ns);
    pending_.insert(pending_.begin(), timed.begin(), timed.end());
  }
  if (frame.id == canopen::kNmtCobId) {
    std::uint8_t command = 0, node = 0;
    if (!codec_->DecodeNmt(frame, command, node)) {
      ++rejected_frames_;
      return out;
    }
    if (node == 0 || node == config_.node_id) HandleNmt(command, t_ns);
  } else if (frame.id == canopen::kSyncCobId) {
    HandleSync(t_ns, out);
  } else if (frame.id == canopen::CobId(canopen::Function::kSdoRequest, config_.node_id)) {
    if (state_ != NmtState::kPreOperational && state_ != NmtState::kOperational) return out;
    SdoFields request;
    if (!codec_->DecodeSdoRequest(frame, request)) {
      ++rejected_frames_;
      return out;
    }
    HandleSdo(request, t_ns, out);
  }
  return out;
}

bool CanopenEncoderNode::ReadsFrame(std::uint32_t id) const {
  return id == canopen::kNmtCobId || id == canopen::kSyncCobId ||
         id == canopen::CobId(canopen::Function::kSdoRequest, config_.node_id);
}

void CanopenEncoderNode::HandleNmt(std::uint8_t command, std::int64_t t_ns) {
  if (state_ == NmtState::kOff) return;  // still initialising
  switch (command) {
    case canopen::nmt::kStart:
      if (state_ != NmtState::kOperational) EnterOperational(t_ns);
      break;
    case canopen::nmt::kStop:
      state_ = NmtState::kStopped;
      next_tpdo_ns_ = kNever;
      break;
    case canopen::nmt::kEnterPreOperational:
      state_ = NmtState::kPreOperational;
      next_tpdo_ns_ = kNever;
      break;
    case canopen::nmt::kResetNode:
      ResetApplication();
      ResetCommunication();
      ScheduleBoot(t_ns + config_.reset_delay_ns);
      break;
    case canopen::nmt::kResetCommunication:
      ResetCommunication();
      ScheduleBoot(t_ns + config_.reset_delay_ns);
      break;
    default:
      break;  // unknown command specifier: ignored, as CiA 301 nodes do
  }
}

void CanopenEncoderNode::HandleSync(std::int64_t t_ns, std::vector<NodeFrame>& out) {
  if (state_ != NmtState::kOperational) return;
  if (tpdo1_type_ == 0) {
    if (!have_last_tpdo_position_ || last_tpdo_position_ != ReportedPosition()) {
      EmitTpdo(t_ns + config_.response_delay_ns, out);
    }
    return;
  }
  if (tpdo1_type_ > 240) return;
  if (++sync_count_ >= tpdo1_type_) {
    sync_count_ = 0;
    EmitTpdo(t_ns + config_.response_delay_ns, out);
  }
}

void CanopenEncoderNode::HandleSdo(const SdoFields& request, std::int64_t t_ns,
                                   std::vector<NodeFrame>& out) {
  const std::uint8_t ccs = sdo::CommandSpecifier(request.command);
  SdoFields response;
  response.index = request.index;
  response.subindex = request.subindex;
  std::uint32_t abort = 0;
  if (ccs == sdo::kCsAbort) return;  // client abort: nothing to answer
  if (ccs == sdo::kCcsInitiateUpload) {
    const SdoResult r = Read(request.index, request.subindex);
    abort = r.abort;
    if (!abort) {
      response.command = sdo::ExpeditedUploadResponse(r.size);
      response.data = r.value;
    }
  } else if (ccs == sdo::kCcsInitiateDownload && (request.command & sdo::kExpedited)) {
    // With s = 1, n (bits 3..2) counts the unused bytes; with s = 0 the size is unspecified.
    const bool sized = request.command & sdo::kSizeIndicated;
    const std::uint8_t size = sized ? sdo::ExpeditedSize(request.command) : std::uint8_t{0};
    std::uint32_t value = request.data;
    if (sized && size < 4) value &= (1u << (8 * size)) - 1u;
    // The new value takes effect when the node answers (timers restart from there).
    abort = Write(request.index, request.subindex, value, size, t_ns + config_.response_delay_ns);
    if (!abort) response.command = sdo::kDownloadResponse;
  } else {
    abort = sdo::kAbortCommand;  // segmented/block transfers and unknown specifiers
  }
  if (abort) {
    response.command = sdo::kAbort;
    response.data = abort;
  }
  bus::CanFrame f;
  Emit(codec_->EncodeSdoResponse(config_.node_id, response, f), f, t_ns + config_.response_delay_ns,
       out);
}

CanopenEncoderNode::SdoResult CanopenEncoderNode::Read(std::uint16_t index,
                                                       std::uint8_t sub) const {
  auto value = [](std::uint32_t v, std::uint8_t size) { return SdoResult{0, v, size}; };
  auto no_sub = SdoResult{sdo::kAbortNoSubindex, 0, 0};
  switch (index) {
    case od::kDeviceType:
      return sub == 0 ? value(config_.device_type, 4) : no_sub;
    case od::kErrorRegister:
      return sub == 0 ? value(error_register_, 1) : no_sub;
    case od::kProducerHeartbeatTime:
      return sub == 0 ? value(heartbeat_ms_, 2) : no_sub;
    case od::kIdentity:
      switch (sub) {
        case 0:
          return value(4, 1);
        case 1:
          return value(config_.vendor_id, 4);
        case 2:
          return value(config_.product_code, 4);
        case 3:
          return value(config_.revision, 4);
        case 4:
          return value(config_.serial, 4);
        default:
          return no_sub;
      }
    case od::kTpdo1Communication:
      switch (sub) {
        case 0:
          return value(5, 1);
        case od::kPdoCobId:
          return value(tpdo1_cob_id_, 4);
        case od::kPdoTransmissionType:
          return value(tpdo1_type_, 1);
        case od::kPdoEventTimer:
          return value(cyclic_timer_ms_, 2);
        default:
          return no_sub;
      }
    case od::kTpdo1Mapping:
      switch (sub) {
        case 0:
          return value(2, 1);
        case 1:
          return value(kMapPosition, 4);
        case 2:
          return value(kMapSpeed, 4);
        default:
          return no_sub;
      }
    case 0x6000:
      return sub == 0 ? value(operating_parameters_, 2) : no_sub;
    case 0x6004:
      return sub == 0 ? value(ReportedPosition(), 4) : no_sub;
    case 0x6030:
      if (sub == 0) return value(1, 1);
      if (sub == 1) return value(static_cast<std::uint16_t>(ReportedSpeed()), 2);
      return no_sub;
    case 0x6200:
      return sub == 0 ? value(cyclic_timer_ms_, 2) : no_sub;
    default: {
      bool index_known = false;
      for (const auto& x : extra_) {
        if (x.index != index) continue;
        index_known = true;
        if (x.sub == sub) return value(x.value, x.size);
      }
      return SdoResult{index_known ? sdo::kAbortNoSubindex : sdo::kAbortNoObject, 0, 0};
    }
  }
}

std::uint32_t CanopenEncoderNode::Write(std::uint16_t index, std::uint8_t sub, std::uint32_t value,
                                        std::uint8_t size, std::int64_t t_ns) {
  // Existence, then access rights, then the length of the data.
  const SdoResult exists = Read(index, sub);
  if (exists.abort) return exists.abort;
  const bool writable =
      (index == od::kProducerHeartbeatTime && sub == 0) ||
      (index == od::kTpdo1Communication &&
       (sub == od::kPdoCobId || sub == od::kPdoTransmissionType || sub == od::kPdoEventTimer)) ||
      (index == 0x6000 && sub == 0) || (index == 0x6200 && sub == 0);
  Cia406NodeConfig::ExtraObject* extra = nullptr;
  for (auto& x : extra_) {
    if (x.index == index && x.sub == sub) extra = &x;
  }
  if (!writable && (extra == nullptr || !extra->writable)) return sdo::kAbortReadOnly;
  if (extra != nullptr) {
    if (size != 0 && size != extra->size) return sdo::kAbortLength;
    extra->value = value;
    return 0;
  }
  if (size != 0 && size != exists.size) return sdo::kAbortLength;
  auto restart_cyclic = [&] {
    const bool cyclic =
        state_ == NmtState::kOperational && tpdo1_type_ >= 254 && cyclic_timer_ms_ > 0;
    next_tpdo_ns_ = cyclic ? t_ns + cyclic_timer_ms_ * kNsPerMs : kNever;
  };
  switch (index) {
    case od::kProducerHeartbeatTime:
      heartbeat_ms_ = static_cast<std::uint16_t>(value);
      if (state_ != NmtState::kOff) {
        next_heartbeat_ns_ = heartbeat_ms_ > 0 ? t_ns + heartbeat_ms_ * kNsPerMs : kNever;
      }
      return 0;
    case od::kTpdo1Communication:
      if (sub == od::kPdoCobId) {
        // CiA 301: the CAN-ID of a valid PDO cannot change; set bit 31 first. 29-bit ids and
        // RTR (bit 30 clear = RTR allowed) are accepted as values but only the 11-bit id is used.
        const bool was_valid = !(tpdo1_cob_id_ & canopen::kPdoCobIdInvalid);
        const bool stays_valid = !(value & canopen::kPdoCobIdInvalid);
        if (was_valid && stays_valid && (value & 0x7FF) != (tpdo1_cob_id_ & 0x7FF)) {
          return sdo::kAbortValue;
        }
        if (value & canopen::kPdoCobIdExtended) return sdo::kAbortValue;  // 29-bit: not supported
        tpdo1_cob_id_ = value;
        return 0;
      }
      if (sub == od::kPdoTransmissionType) {
        if (!ValidTransmissionType(value)) return sdo::kAbortValue;
        tpdo1_type_ = static_cast<std::uint8_t>(value);
        sync_count_ = 0;
        restart_cyclic();
        return 0;
      }
      if (sub == od::kPdoEventTimer) {
        cyclic_timer_ms_ = static_cast<std::uint16_t>(value);
        restart_cyclic();
        return 0;
      }
      return sdo::kAbortReadOnly;
    case 0x6000:
      operating_parameters_ = static_cast<std::uint16_t>(value);
      return 0;
    case 0x6200:
      cyclic_timer_ms_ = static_cast<std::uint16_t>(value);
      restart_cyclic();
      return 0;
    default:
      return sdo::kAbortReadOnly;
  }
}

std::vector<NodeFrame> CanopenEncoderNode::Poll(std::int64_t t_ns) {
  std::vector<NodeFrame> out;
  out.swap(pending_);
  if (t_ns < now_ns_) t_ns = now_ns_;
  for (;;) {
    const std::int64_t next = std::min({boot_due_ns_, next_heartbeat_ns_, next_tpdo_ns_});
    if (next > t_ns) break;
    bus::CanFrame f;
    if (next == boot_due_ns_) {
      boot_due_ns_ = kNever;
      state_ = NmtState::kPreOperational;
      Emit(codec_->EncodeNmtState(config_.node_id, canopen::nmt_state::kBootUp, f), f, next, out);
      next_heartbeat_ns_ = heartbeat_ms_ > 0 ? next + heartbeat_ms_ * kNsPerMs : kNever;
    } else if (next == next_heartbeat_ns_) {
      Emit(codec_->EncodeNmtState(config_.node_id, static_cast<std::uint8_t>(state_), f), f, next,
           out);
      next_heartbeat_ns_ = heartbeat_ms_ > 0 ? next + heartbeat_ms_ * kNsPerMs : kNever;
    } else {
      EmitTpdo(next, out);
      next_tpdo_ns_ = cyclic_timer_ms_ > 0 ? next + cyclic_timer_ms_ * kNsPerMs : kNever;
    }
  }
  now_ns_ = t_ns;
  std::stable_sort(out.begin(), out.end(),
                   [](const NodeFrame& a, const NodeFrame& b) { return a.due_ns < b.due_ns; });
  return out;
}

std::int64_t CanopenEncoderNode::NextEventNs() const {
  if (!pending_.empty()) return now_ns_;
  return std::min({boot_due_ns_, next_heartbeat_ns_, next_tpdo_ns_});
}

void CanopenEncoderNode::RaiseFault(std::uint16_t error_code, std::uint8_t error_register,
                                    std::int64_t t_ns) {
  error_register_ = static_cast<std::uint8_t>(error_register | canopen::kErrorRegisterGeneric);
  if (state_ != NmtState::kPreOperational && state_ != NmtState::kOperational) return;
  bus::CanFrame f;
  Emit(codec_->EncodeEmcy(config_.node_id, error_code, error_register_, f), f, t_ns, pending_);
}

void CanopenEncoderNode::ClearFault(std::int64_t t_ns) {
  error_register_ = 0;
  if (state_ != NmtState::kPreOperational && state_ != NmtState::kOperational) return;
  bus::CanFrame f;
  Emit(codec_->EncodeEmcy(config_.node_id, canopen::kEmcyErrorReset, 0, f), f, t_ns, pending_);
}

}  // namespace wheelhil::emulator
