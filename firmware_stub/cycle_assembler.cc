#include "firmware_stub/cycle_assembler.h"

#include <fmt/format.h>

#include <limits>
#include <set>
#include <stdexcept>

namespace wheelhil::fw {

CycleAssembler::CycleAssembler(const CycleAssemblerConfig& config) : config_(config) {
  if (config_.tpdo_nodes.size() > AssembledCycle::kMaxNodes) {
    throw std::invalid_argument(
        fmt::format("at most {} encoder nodes per cycle", AssembledCycle::kMaxNodes));
  }
  std::set<std::uint8_t> seen;
  for (std::uint8_t n : config_.tpdo_nodes) {
    if (!seen.insert(n).second) {
      throw std::invalid_argument(fmt::format("node_id {} is used twice", n));
    }
  }
  if (config_.deadline_ns < 0) throw std::invalid_argument("deadline_s must be >= 0");
  all_mask_ = config_.tpdo_nodes.empty()
                  ? 0u
                  : static_cast<std::uint32_t>((1ull << config_.tpdo_nodes.size()) - 1);
}

int CycleAssembler::Slot(std::uint8_t node_id) const {
  for (std::size_t i = 0; i < config_.tpdo_nodes.size(); ++i) {
    if (config_.tpdo_nodes[i] == node_id) return static_cast<int>(i);
  }
  return -1;
}

AssembledCycle CycleAssembler::Close(AssembledCycle::Close why) {
  open_ = false;
  std::uint32_t present = 0;
  for (std::size_t i = 0; i < config_.tpdo_nodes.size(); ++i) {
    if (cur_.encoders[i].present) present |= 1u << i;
  }
  cur_.missing_mask = all_mask_ & ~present;
  cur_.close = why;
  last_closed_present_ = present;
  ++closed_;
  if (cur_.missing_mask != 0) ++incomplete_;
  return cur_;
}

std::optional<AssembledCycle> CycleAssembler::OnSync(std::int64_t t_ns) {
  std::optional<AssembledCycle> closed;
  if (open_) closed = Close(AssembledCycle::Close::kNextSync);
  cur_ = AssembledCycle{};
  cur_.index = next_index_++;
  cur_.sync_ns = t_ns;
  cur_.interval_ns = any_sync_ ? t_ns - last_sync_ns_ : 0;
  cur_.yaw_samples = bucket_.yaw_samples;
  cur_.yaw_rate_sum_rad_s = bucket_.yaw_rate_sum_rad_s;
  cur_.accel_samples = bucket_.accel_samples;
  cur_.accel_sum_m_s2 = bucket_.accel_sum_m_s2;
  bucket_ = AssembledCycle{};
  any_sync_ = true;
  last_sync_ns_ = t_ns;
  open_ = true;
  if (all_mask_ == 0) {
    // Nothing synchronous to wait for: the SYNC itself completes the cycle.
    if (closed) {
      // Report the older one now; this one closes at the next event (deadline/Poll).
      return closed;
    }
    return Close(AssembledCycle::Close::kComplete);
  }
  return closed;
}

std::optional<AssembledCycle> CycleAssembler::OnTpdo(std::uint8_t node_id, std::uint32_t position,
                                                     std::int16_t speed, std::int64_t t_ns) {
  const int slot = Slot(node_id);
  if (slot < 0) {
    ++unexpected_;
    return std::nullopt;
  }
  if (!open_) {
    if (any_sync_ && (last_closed_present_ & (1u << slot))) {
      ++duplicates_;
    } else {
      ++late_;
    }
    return std::nullopt;
  }
  EncoderReading& r = cur_.encoders[static_cast<std::size_t>(slot)];
  if (r.present) {
    ++duplicates_;
    return std::nullopt;
  }
  r.present = true;
  r.position = position;
  r.speed = speed;
  r.t_ns = t_ns;
  for (std::size_t i = 0; i < config_.tpdo_nodes.size(); ++i) {
    if (!cur_.encoders[i].present) return std::nullopt;
  }
  return Close(AssembledCycle::Close::kComplete);
}

void CycleAssembler::OnYawRate(double rate_rad_s, std::int64_t /*t_ns*/) {
  ++bucket_.yaw_samples;
  bucket_.yaw_rate_sum_rad_s += rate_rad_s;
}

void CycleAssembler::OnAccel(const std::array<double, 4>& a_m_s2, std::int64_t /*t_ns*/) {
  ++bucket_.accel_samples;
  for (std::size_t i = 0; i < 4; ++i) bucket_.accel_sum_m_s2[i] += a_m_s2[i];
}

std::optional<AssembledCycle> CycleAssembler::Poll(std::int64_t t_ns) {
  if (open_ && config_.deadline_ns > 0 && t_ns >= cur_.sync_ns + config_.deadline_ns) {
    return Close(AssembledCycle::Close::kDeadline);
  }
  return std::nullopt;
}

std::int64_t CycleAssembler::NextDeadlineNs() const {
  if (!open_ || config_.deadline_ns == 0) return std::numeric_limits<std::int64_t>::max();
  return cur_.sync_ns + config_.deadline_ns;
}

}  // namespace wheelhil::fw
