#include "firmware_stub/canopen_master.h"

#include <fmt/format.h>

#include <algorithm>
#include <limits>
#include <set>
#include <stdexcept>

#include "bus/canopen.h"

namespace wheelhil::fw {
namespace {

namespace canopen = bus::canopen;
namespace od = bus::canopen::od;
using canopen::nmt_state::kBootUp;
using canopen::nmt_state::kPreOperational;

constexpr std::int64_t kNever = std::numeric_limits<std::int64_t>::max();

}  // namespace

CanopenMaster::CanopenMaster(const CanopenMasterConfig& config, const FwProtocol& protocol)
    : config_(config), protocol_(protocol) {
  std::set<std::uint8_t> seen;
  for (std::uint8_t id : config_.node_ids) {
    if (!canopen::IsValidNodeId(id)) {
      throw std::invalid_argument(fmt::format("node_id ({}) must be in [1, 127]", id));
    }
    if (!seen.insert(id).second) {
      throw std::invalid_argument(fmt::format("node_id {} is used twice", id));
    }
  }
  for (const NodeSdoWrite& w : config_.node_writes) {
    if (!seen.count(w.node_id)) {
      throw std::invalid_argument(
          fmt::format("SDO write to node {}, which is not supervised", w.node_id));
    }
    if (w.size < 1 || w.size > 4) {
      throw std::invalid_argument(fmt::format("SDO write of {} bytes (1..4)", w.size));
    }
  }
  if (config_.node_ids.size() > 32) {
    throw std::invalid_argument("at most 32 CANopen nodes are supervised");
  }
  if (config_.boot_timeout_ns <= 0) throw std::invalid_argument("boot_timeout_s must be > 0");
  if (config_.sdo_timeout_ns <= 0) throw std::invalid_argument("sdo_timeout_s must be > 0");
  if (config_.produce_sync && config_.sync_period_ns <= 0) {
    throw std::invalid_argument("sync period_s must be > 0");
  }
  if (config_.heartbeat_timeout_ns < 0) {
    throw std::invalid_argument("heartbeat_timeout_s must be >= 0");
  }
  for (std::uint8_t id : config_.node_ids) {
    NodeStatus s;
    s.node_id = id;
    nodes_.push_back(s);
    NodeRun r;
    if (config_.tpdo_transmission_type != 0) {
      r.steps.push_back(
          {od::kTpdo1Communication, od::kPdoTransmissionType, config_.tpdo_transmission_type, 1});
    }
    if (config_.heartbeat_producer_ms != 0) {
      r.steps.push_back({od::kProducerHeartbeatTime, 0, config_.heartbeat_producer_ms, 2});
    }
    for (const NodeSdoWrite& w : config_.node_writes) {
      if (w.node_id == id) r.steps.push_back({w.index, w.subindex, w.value, w.size});
    }
    runs_.push_back(r);
  }
}

void CanopenMaster::Start(std::int64_t t_ns) {
  running_ = true;
  start_ns_ = t_ns;
  reset_pending_ = config_.reset_communication_at_start;
}

int CanopenMaster::IndexOf(std::uint8_t node_id) const {
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    if (nodes_[i].node_id == node_id) return static_cast<int>(i);
  }
  return -1;
}

void CanopenMaster::Boot(std::size_t i, std::int64_t t_ns) {
  NodeStatus& s = nodes_[i];
  NodeRun& r = runs_[i];
  ++s.boot_count;
  s.lost = false;
  s.last_heartbeat_ns = t_ns;  // The boot-up restarts the consumer timer.
  s.last_heartbeat_state = kPreOperational;
  r.next_step = 0;
  r.sdo_pending = false;
  r.sdo_attempts = 0;
  r.start_now = false;
  if (r.steps.empty()) {
    s.state = NodeState::kOperational;
    r.start_now = true;
  } else {
    s.state = NodeState::kConfiguring;
    r.send_now = true;
  }
}

void CanopenMaster::NextStep(std::size_t i) {
  NodeRun& r = runs_[i];
  r.sdo_pending = false;
  r.sdo_attempts = 0;
  ++r.next_step;
  if (r.next_step >= r.steps.size()) {
    nodes_[i].state = NodeState::kOperational;
    r.start_now = true;
  } else {
    r.send_now = true;
  }
}

void CanopenMaster::SendStep(std::size_t i, std::vector<bus::CanFrame>& out) {
  NodeRun& r = runs_[i];
  const SdoStep& step = r.steps[r.next_step];
  SdoFrame sdo;
  sdo.command = canopen::sdo::ExpeditedDownloadRequest(step.size);
  sdo.index = step.index;
  sdo.subindex = step.subindex;
  sdo.data = step.value;
  bus::CanFrame f;
  if (protocol_.EncodeSdoRequest(nodes_[i].node_id, sdo, f)) out.push_back(f);
  r.sdo_pending = true;
  ++r.sdo_attempts;
  r.send_now = false;
}

bool CanopenMaster::OnFrame(const bus::CanFrame& frame, std::int64_t t_ns) {
  std::uint8_t node = 0;
  const FrameKind kind = protocol_.Classify(frame, node);
  if (kind != FrameKind::kErrorControl && kind != FrameKind::kEmcy &&
      kind != FrameKind::kSdoResponse) {
    return false;
  }
  const int idx = IndexOf(node);
  if (idx < 0) return false;  // Another master's node: not ours to judge.
  const std::size_t i = static_cast<std::size_t>(idx);
  NodeStatus& s = nodes_[i];
  NodeRun& r = runs_[i];
  switch (kind) {
    case FrameKind::kErrorControl: {
      std::uint8_t state = 0;
      if (!protocol_.DecodeErrorControl(frame, state)) {
        ++bad_frames_;
        return true;
      }
      if (state == kBootUp) {
        Boot(i, t_ns);
        return true;
      }
      s.last_heartbeat_ns = t_ns;
      s.last_heartbeat_state = state;
      s.lost = false;
      if (s.state == NodeState::kWaitBoot || s.state == NodeState::kMissing) {
        // Booted before we listened: configure it now (a heartbeat proves it is there).
        Boot(i, t_ns);
        s.last_heartbeat_state = state;
      } else if (s.state == NodeState::kOperational && state == kPreOperational && !r.start_now) {
        r.start_now = true;  // It fell back to pre-operational: start it again.
      }
      return true;
    }
    case FrameKind::kEmcy: {
      std::uint16_t code = 0;
      std::uint8_t reg = 0;
      if (!protocol_.DecodeEmcy(frame, code, reg)) {
        ++bad_frames_;
        return true;
      }
      s.last_emcy_code = code;
      s.emcy_active = code != 0;
      return true;
    }
    case FrameKind::kSdoResponse: {
      SdoFrame sdo;
      if (!protocol_.DecodeSdoResponse(frame, sdo)) {
        ++bad_frames_;
        return true;
      }
      if (!r.sdo_pending || r.next_step >= r.steps.size()) return true;  // Stale answer.
      const SdoStep& step = r.steps[r.next_step];
      if (sdo.index != step.index || sdo.subindex != step.subindex) return true;
      if (sdo.command == canopen::sdo::kAbort) {
        ++s.sdo_failures;
        sdo_fault_ = true;
        NextStep(i);
      } else if (sdo.command == canopen::sdo::kDownloadResponse) {
        NextStep(i);
      }
      return true;
    }
    default:
      return false;
  }
}

CanopenMaster::PollResult CanopenMaster::Poll(std::int64_t t_ns) {
  PollResult out;
  if (!running_) return out;
  if (reset_pending_) {
    bus::CanFrame f;
    if (protocol_.EncodeNmt(canopen::nmt::kResetCommunication, 0, f)) out.frames.push_back(f);
    reset_pending_ = false;
  }
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    NodeStatus& s = nodes_[i];
    NodeRun& r = runs_[i];
    if (s.state == NodeState::kWaitBoot && t_ns - start_ns_ >= config_.boot_timeout_ns) {
      s.state = NodeState::kMissing;
    }
    if (s.state == NodeState::kConfiguring) {
      if (r.sdo_pending && t_ns >= r.sdo_deadline_ns) {
        if (r.sdo_attempts > config_.sdo_retries) {
          ++s.sdo_failures;
          sdo_fault_ = true;
          NextStep(i);
        } else {
          r.send_now = true;
        }
      }
      if (s.state == NodeState::kConfiguring && r.send_now) {
        SendStep(i, out.frames);
        r.sdo_deadline_ns = t_ns + config_.sdo_timeout_ns;
      }
    }
    if (r.start_now) {
      bus::CanFrame f;
      if (protocol_.EncodeNmt(canopen::nmt::kStart, s.node_id, f)) out.frames.push_back(f);
      r.start_now = false;
    }
    if (config_.heartbeat_timeout_ns > 0 && s.state == NodeState::kOperational && !s.lost &&
        t_ns - s.last_heartbeat_ns > config_.heartbeat_timeout_ns) {
      s.lost = true;
    }
  }
  if (config_.produce_sync && started()) {
    if (!sync_started_) {
      // The first SYNC one period after start-up, so the nodes are operational by then.
      sync_started_ = true;
      next_sync_ns_ = t_ns + config_.sync_period_ns;
    }
    if (t_ns >= next_sync_ns_) {
      bus::CanFrame f;
      if (protocol_.EncodeSync(f)) {
        out.frames.push_back(f);
        out.sync_sent = true;
        ++syncs_sent_;
      }
      // Keep the grid; skip the SYNCs a late Poll missed rather than bursting them.
      next_sync_ns_ += config_.sync_period_ns;
      if (next_sync_ns_ <= t_ns) {
        const std::int64_t behind = (t_ns - next_sync_ns_) / config_.sync_period_ns + 1;
        next_sync_ns_ += behind * config_.sync_period_ns;
      }
    }
  }
  return out;
}

std::int64_t CanopenMaster::NextEventNs() const {
  if (!running_) return kNever;
  std::int64_t next = kNever;
  if (reset_pending_) return start_ns_;
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    const NodeStatus& s = nodes_[i];
    const NodeRun& r = runs_[i];
    if (r.send_now || r.start_now) return start_ns_;  // Due now.
    if (s.state == NodeState::kWaitBoot) {
      next = std::min(next, start_ns_ + config_.boot_timeout_ns);
    }
    if (s.state == NodeState::kConfiguring && r.sdo_pending) {
      next = std::min(next, r.sdo_deadline_ns);
    }
    if (config_.heartbeat_timeout_ns > 0 && s.state == NodeState::kOperational && !s.lost) {
      next = std::min(next, s.last_heartbeat_ns + config_.heartbeat_timeout_ns + 1);
    }
  }
  if (config_.produce_sync && started()) {
    next = std::min(next, sync_started_ ? next_sync_ns_ : start_ns_);  // Not started: due now.
  }
  return next;
}

bool CanopenMaster::started() const {
  for (const auto& s : nodes_) {
    if (s.state == NodeState::kWaitBoot || s.state == NodeState::kConfiguring) return false;
  }
  return true;
}

std::uint32_t CanopenMaster::faults() const {
  std::uint32_t f = sdo_fault_ ? kFaultSdo : 0u;
  for (const auto& s : nodes_) {
    if (s.state == NodeState::kMissing) f |= kFaultBootTimeout;
    if (s.lost) f |= kFaultNodeLost;
    if (s.emcy_active) f |= kFaultEmcy;
  }
  if (bad_frames_ > 0) f |= kFaultBadFrame;
  return f;
}

std::uint32_t CanopenMaster::nodes_lost_mask() const {
  std::uint32_t m = 0;
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    if (nodes_[i].lost || nodes_[i].state == NodeState::kMissing) m |= 1u << i;
  }
  return m;
}

}  // namespace wheelhil::fw
