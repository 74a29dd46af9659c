#include "emulator/scenario/fault_plan.h"

#include <map>

#include <fmt/format.h>

#include "bus/dbc.h"
#include "emulator/faults/device_faults.h"
#include "emulator/faults/frame_faults.h"
#include "emulator/faults/sensor_faults.h"

namespace wheelhil::emulator::scenario {

namespace {

using nlohmann::json;
using Devices = std::vector<std::unique_ptr<Device>>;

int DeviceOf(const FaultSpec& f, const Devices& devices) {
  for (std::size_t i = 0; i < devices.size(); ++i) {
    const Device& d = *devices[i];
    if (!f.node.empty() ? d.fault_name() == f.node : d.canopen_node_id() == f.node_id) {
      return static_cast<int>(i);
    }
  }
  return -1;
}

}  // namespace

FaultPlan::FaultPlan(const Scenario& scenario, std::uint64_t seed, std::string dbc_dir)
    : s_(scenario), seed_(seed), dbc_dir_(std::move(dbc_dir)) {}

void FaultPlan::Arm(std::int64_t t0, Devices& devices, sim::BusHub& hub) {
  motion0_ns_ = t0;
  auto shift = [&](FaultWindow w) {
    w.t0_ns += t0;
    if (w.t1_ns != FaultWindow::kForever) w.t1_ns += t0;
    return w;
  };
  std::vector<FrameFault> frame;
  std::vector<BusFault> bus;
  std::map<int, std::vector<DeviceFault>> device;  // by device index
  std::map<int, std::vector<DriveFault>> drive;    // by device index
  std::map<std::string, std::vector<SensorFault>> sensor;  // by channel
  for (const auto& f : s_.faults) {
    switch (f.kind) {
      case FaultSpec::Kind::kFrame: {
        FrameFault x = f.frame;
        x.window = shift(x.window);
        frame.push_back(std::move(x));
        break;
      }
      case FaultSpec::Kind::kBus: {
        BusFault x = f.bus;
        x.window = shift(x.window);
        if (x.kind == BusFaultKind::kBusOff) {
          const int d = DeviceOf(f, devices);
          x.node = d >= 0 ? hub.bus_node(static_cast<std::size_t>(d)) : -1;
          x.node_name = f.node.empty() ? fmt::format("encoder{}", f.node_id) : f.node;
        }
        bus.push_back(std::move(x));
        break;
      }
      case FaultSpec::Kind::kDevice: {
        DeviceFault x = f.device;
        x.window = shift(x.window);
        device[DeviceOf(f, devices)].push_back(x);
        break;
      }
      case FaultSpec::Kind::kDrive: {
        DriveFault x = f.drive;
        x.t0_ns += t0;
        if (x.t1_ns != std::numeric_limits<std::int64_t>::max()) x.t1_ns += t0;
        drive[DeviceOf(f, devices)].push_back(x);
        break;
      }
      case FaultSpec::Kind::kSensor: {
        SensorFault x = f.sensor;
        x.window = shift(x.window);
        if (f.sensor_name == "accel4" && f.channel == 0) {
          for (int c = 1; c <= 4; ++c) sensor[fmt::format("accel4.{}", c)].push_back(x);
        } else if (f.sensor_name == "accel4") {
          sensor[fmt::format("accel4.{}", f.channel)].push_back(x);
        } else if (f.sensor_name == "encoder") {
          sensor["encoder." + f.wheel].push_back(x);
        } else {
          sensor[f.sensor_name].push_back(x);
        }
        break;
      }
      default:
        break;
    }
  }
  library_faults_ = !(frame.empty() && bus.empty() && device.empty() && sensor.empty());
  // Seeds: one stream per injector, from the run seed, in this order.
  std::uint64_t k = 0;
  auto next_seed = [&] { return (seed_ ^ 0xFA017F00D5EEDull) * 6364136223846793005ull + (++k); };
  if (!frame.empty()) {
    // Every emulated device's output (not the SYNC producer, not the firmware's frames: those
    // reach the firmware outside the model). Each filter sees every window pass, so the first
    // one alone records the start/end events: one pair per fault, not one per device.
    auto dbc = std::make_shared<const bus::DbcDatabase>(
        bus::DbcDatabase::LoadFile(dbc_dir_ + "/wheelhil_accel4.dbc"));
    FaultEventLog* log = &log_;
    for (std::size_t d = 0; d < devices.size(); ++d) {
      hub.SetFrameFaults(d, std::make_unique<FrameFaultFilter>(frame, dbc, next_seed(), log));
      log = nullptr;
    }
  }
  if (!bus.empty()) hub.SetBusFaults(std::move(bus), &log_);
  std::vector<DeviceFaults> per_device(devices.size());
  for (auto& [d, faults] : device) {
    if (d < 0) continue;
    const Device& dev = *devices[static_cast<std::size_t>(d)];
    const std::uint8_t id = dev.canopen_node_id() != 0 ? dev.canopen_node_id() : 0x7F;
    per_device[static_cast<std::size_t>(d)].device =
        std::make_unique<DeviceFaultInjector>(dev.fault_name(), id, faults, &log_);
  }
  for (auto& [d, faults] : drive) {
    if (d >= 0) per_device[static_cast<std::size_t>(d)].drive = std::move(faults);
  }
  for (auto& [channel, faults] : sensor) {
    bool owned = false;
    for (std::size_t d = 0; d < devices.size(); ++d) {
      const auto channels = devices[d]->sensor_channels();
      if (std::find(channels.begin(), channels.end(), channel) == channels.end()) continue;
      owned = true;
      per_device[d].sensors.emplace_back(
          channel, std::make_unique<SensorFaultInjector>(
                       devices[d]->channel_label(channel), faults,
                       devices[d]->channel_noise_std(channel), next_seed(), &log_));
    }
    // A sensor of the IMU or the accelerometers keeps its stream even when nothing owns it, so
    // the streams after it do not move.
    if (!owned && !channel.starts_with("encoder.")) (void)next_seed();
  }
  for (std::size_t d = 0; d < devices.size(); ++d) devices[d]->ArmFaults(std::move(per_device[d]));
}

void FaultPlan::StepNodeFaults(std::int64_t t_ns, std::int64_t step_ns, Devices& devices,
                               sim::RunContext& run) {
  const double t_now = static_cast<double>(t_ns) * 1e-9;
  for (const auto& f : s_.faults) {
    if (f.kind != FaultSpec::Kind::kEncoderEmcy && f.kind != FaultSpec::Kind::kEncoderSilent) {
      continue;
    }
    const double t_start = run.motion0_s + f.start_s, t_end = run.motion0_s + f.end_s;
    for (auto& d : devices) {
      if (d->canopen_node_id() != f.node_id) continue;
      const bool on = t_now >= t_start && t_now < t_end;
      const bool was = t_now - static_cast<double>(step_ns) * 1e-9 >= t_start &&
                       t_now - static_cast<double>(step_ns) * 1e-9 < t_end;
      if (on == was) continue;
      run.events.push_back(json{
          {"t_s", t_now - run.motion0_s},
          {"event", on ? "fault_start" : "fault_end"},
          {"fault", f.kind == FaultSpec::Kind::kEncoderEmcy ? "encoder_emcy" : "encoder_silent"},
          {"node_id", f.node_id}});
      if (f.kind == FaultSpec::Kind::kEncoderEmcy) {
        if (on) {
          d->RaiseFault(f.error_code, t_ns);
        } else {
          d->ClearFault(t_ns);
        }
      } else {
        d->SetSilent(on);
      }
    }
  }
}

void FaultPlan::FlushEvents(sim::RunContext& run) {
  for (const auto& e : log_.events()) {
    run.events.push_back(json{{"t_s", static_cast<double>(e.t_ns - motion0_ns_) * 1e-9},
                              {"event", "fault_" + e.phase},
                              {"category", e.category},
                              {"fault", e.kind},
                              {"target", e.target},
                              {"detail", e.detail}});
  }
  log_.Clear();
}

std::optional<json> FaultPlan::Metrics(const Devices& devices, const sim::BusHub& hub) const {
  if (!library_faults_) return std::nullopt;
  const FaultyCanBus* fb = hub.faulty_bus();
  json fj{{"bus_off_dropped", fb ? fb->dropped_bus_off() : 0},
          {"flood_frames", fb ? fb->flood_frames() : 0},
          {"error_frames", fb ? fb->error_frames() : 0}};
  std::uint64_t affected = 0, unapplied = 0, suppressed = 0;
  std::int64_t missed = 0;
  // Frame faults in list order (the filters' fault indices), totals per kind.
  std::vector<FrameFaultKind> frame_kinds;
  for (const auto& f : s_.faults) {
    if (f.kind == FaultSpec::Kind::kFrame) frame_kinds.push_back(f.frame.kind);
  }
  std::map<std::string, std::uint64_t> by_kind;
  for (const auto& [node, filter] : hub.frame_filters()) {
    for (std::size_t i = 0; i < frame_kinds.size(); ++i) {
      affected += filter->affected(i);
      by_kind[std::string(FrameFaultKindName(frame_kinds[i]))] += filter->affected(i);
    }
    unapplied += filter->unapplied();
  }
  for (const auto& [kind, n] : by_kind) fj["frames_" + kind] = n;
  for (const auto& d : devices) {
    suppressed += d->suppressed_frames();
    missed += d->missed_counts();
  }
  fj["frames_affected"] = affected;
  fj["frames_unapplied"] = unapplied;
  fj["device_suppressed_frames"] = suppressed;
  fj["missed_counts"] = missed;
  return fj;
}

}  // namespace wheelhil::emulator::scenario
