#include "emulator/faults/device_faults.h"

#include <algorithm>
#include <limits>
#include <stdexcept>

#include <fmt/format.h>

#include "bus/canopen.h"

namespace wheelhil::emulator {

std::optional<DeviceFaultKind> ParseDeviceFaultKind(std::string_view name) noexcept {
  for (auto k : {DeviceFaultKind::kSilent, DeviceFaultKind::kHeartbeatLost,
                 DeviceFaultKind::kReboot, DeviceFaultKind::kEmcy}) {
    if (DeviceFaultKindName(k) == name) return k;
  }
  return std::nullopt;
}

std::string_view DeviceFaultKindName(DeviceFaultKind kind) noexcept {
  switch (kind) {
    case DeviceFaultKind::kSilent:
      return "silent";
    case DeviceFaultKind::kHeartbeatLost:
      return "heartbeat_lost";
    case DeviceFaultKind::kReboot:
      return "reboot";
    case DeviceFaultKind::kEmcy:
      return "emcy";
  }
  return "?";
}

DeviceFaultInjector::DeviceFaultInjector(std::string node_name, std::uint8_t node_id,
                                         std::vector<DeviceFault> faults, FaultEventLog* log)
    : node_name_(std::move(node_name)), node_id_(node_id), log_(log) {
  if (!bus::canopen::IsValidNodeId(node_id)) {
    throw std::invalid_argument(
        fmt::format("{}: device_faults node_id ({}) must be in 1..127", node_name_, node_id));
  }
  for (std::size_t i = 0; i < faults.size(); ++i) {
    const DeviceFault& f = faults[i];
    if (!f.window.IsValid()) {
      throw std::invalid_argument(
          fmt::format("{}: device_faults[{}].window: [{}, {}) ns must have 0 <= t0 < t1",
                      node_name_, i, f.window.t0_ns, f.window.t1_ns));
    }
    if (f.kind == DeviceFaultKind::kReboot && f.window.t1_ns == FaultWindow::kForever) {
      throw std::invalid_argument(fmt::format(
          "{}: device_faults[{}].window: a reboot needs an end (power-on instant)", node_name_, i));
    }
    faults_.push_back({f, {}, false, false});
  }
}

void DeviceFaultInjector::Track(std::int64_t t_ns) {
  for (State& s : faults_) {
    if (!s.phase.Pending(t_ns, s.fault.window)) continue;
    std::string detail;
    if (s.fault.kind == DeviceFaultKind::kEmcy) {
      detail =
          fmt::format("code=0x{:04X} register=0x{:02X}", s.fault.emcy_code, s.fault.error_register);
    }
    s.phase.Advance(t_ns, s.fault.window, log_, "device", DeviceFaultKindName(s.fault.kind),
                    fmt::format("{} (node {})", node_name_, node_id_), detail);
  }
}

bool DeviceFaultInjector::SilentAt(std::int64_t t_ns) const {
  return std::any_of(faults_.begin(), faults_.end(), [&](const State& s) {
    return (s.fault.kind == DeviceFaultKind::kSilent || s.fault.kind == DeviceFaultKind::kReboot) &&
           s.fault.window.Contains(t_ns);
  });
}

void DeviceFaultInjector::FilterOutputs(std::vector<NodeFrame>& frames) {
  const std::uint32_t heartbeat_id =
      bus::canopen::CobId(bus::canopen::Function::kErrorControl, node_id_);
  auto suppressed = [&](const NodeFrame& f) {
    Track(f.due_ns);
    if (SilentAt(f.due_ns)) return true;
    const bool heartbeat = !f.frame.extended && f.frame.id == heartbeat_id && f.frame.len >= 1 &&
                           f.frame.data[0] != bus::canopen::nmt_state::kBootUp;
    return heartbeat && std::any_of(faults_.begin(), faults_.end(), [&](const State& s) {
             return s.fault.kind == DeviceFaultKind::kHeartbeatLost &&
                    s.fault.window.Contains(f.due_ns);
           });
  };
  const auto before = frames.size();
  frames.erase(std::remove_if(frames.begin(), frames.end(), suppressed), frames.end());
  suppressed_ += before - frames.size();
}

std::int64_t DeviceFaultInjector::NextActionNs() const {
  std::int64_t next = std::numeric_limits<std::int64_t>::max();
  for (const State& s : faults_) {
    if (s.fault.kind != DeviceFaultKind::kReboot && s.fault.kind != DeviceFaultKind::kEmcy) {
      continue;
    }
    if (!s.start_done) next = std::min(next, s.fault.window.t0_ns);
    if (!s.end_done && s.fault.window.t1_ns != FaultWindow::kForever) {
      next = std::min(next, s.fault.window.t1_ns);
    }
  }
  return next;
}

int DeviceFaultInjector::ApplyTo(CanopenEncoderNode& node, const Cia406NodeConfig& config,
                                 const std::shared_ptr<const Cia406Codec>& codec,
                                 std::int64_t t_ns) {
  Track(t_ns);
  int actions = 0;
  for (State& s : faults_) {
    const FaultWindow& w = s.fault.window;
    if (s.fault.kind == DeviceFaultKind::kReboot) {
      if (!s.start_done && t_ns >= w.t0_ns) {
        // Power off now, power on at t1: the rebuilt node stays off until t1 + power-on delay.
        s.start_done = true;
        node = CanopenEncoderNode(config, codec, w.t1_ns);
        ++actions;
      }
      if (!s.end_done && t_ns >= w.t1_ns) {
        s.end_done = true;
        ++actions;
      }
    } else if (s.fault.kind == DeviceFaultKind::kEmcy) {
      if (!s.start_done && t_ns >= w.t0_ns) {
        s.start_done = true;
        node.RaiseFault(s.fault.emcy_code, s.fault.error_register, w.t0_ns);
        ++actions;
      }
      if (!s.end_done && w.t1_ns != FaultWindow::kForever && t_ns >= w.t1_ns) {
        s.end_done = true;
        node.ClearFault(w.t1_ns);
        ++actions;
      }
    }
  }
  return actions;
}

}  // namespace wheelhil::emulator
