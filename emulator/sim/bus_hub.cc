#include "emulator/sim/bus_hub.h"

#include <algorithm>

#include "emulator/sim/background_candump.h"

namespace wheelhil::emulator::sim {

// A device's DevicePort: its frames into the hub, its events into the run.
class BusHub::Port final : public DevicePort {
 public:
  Port(BusHub& hub, std::size_t device) : hub_(hub), device_(device) {}
  void Send(std::vector<NodeFrame> frames, bool from_poll) override {
    hub_.SubmitFromDevice(device_, std::move(frames), from_poll);
  }
  void CountSilenced(std::size_t frames) override { hub_.silenced_ += frames; }
  void Event(nlohmann::json event) override { hub_.run_.events.push_back(std::move(event)); }
  double MotionSeconds(std::int64_t t_ns) const override { return hub_.run_.MotionSeconds(t_ns); }
  void Fail(std::string why) override { hub_.run_.Fail(std::move(why)); }

 private:
  BusHub& hub_;
  std::size_t device_;
};

BusHub::BusHub(const CanBusConfig& config, std::vector<std::unique_ptr<Device>>& devices,
               RunContext& run)
    : bus_(config), devices_(devices), run_(run) {
  emulator_node_ = bus_.AddNode("emulator");
  firmware_node_ = bus_.AddNode("firmware", CanBusModel::QueueOrder::kFifo, 4096);
  first_device_node_ = firmware_node_ + 1;
  for (std::size_t i = 0; i < devices_.size(); ++i) {
    (void)bus_.AddNode(devices_[i]->name());
    ports_.push_back(std::make_unique<Port>(*this, i));
  }
}

BusHub::~BusHub() = default;

BusHub::BusHub(const BusHub& other, std::vector<std::unique_ptr<Device>>& devices, RunContext& run)
    : bus_(other.bus_),
      devices_(devices),
      run_(run),
      emulator_node_(other.emulator_node_),
      firmware_node_(other.firmware_node_),
      first_device_node_(other.first_device_node_),
      iface_(other.iface_),
      enqueued_(other.enqueued_),
      completed_(other.completed_),
      silenced_(other.silenced_),
      enqueue_failures_(other.enqueue_failures_),
      firmware_frames_(other.firmware_frames_) {
  for (std::size_t i = 0; i < devices_.size(); ++i) {
    ports_.push_back(std::make_unique<Port>(*this, i));
  }
  if (other.faulty_bus_) faulty_bus_ = std::make_unique<FaultyCanBus>(*other.faulty_bus_, bus_);
  for (const auto& [node, filter] : other.frame_filters_) {
    frame_filters_[node] = std::make_unique<FrameFaultFilter>(*filter);
  }
}

std::unique_ptr<BusHub> BusHub::CopyForForecast(std::vector<std::unique_ptr<Device>>& devices,
                                                RunContext& run, FirmwareSend firmware_send) const {
  std::unique_ptr<BusHub> copy(new BusHub(*this, devices, run));
  copy->firmware_send_ = std::move(firmware_send);
  return copy;
}

DevicePort& BusHub::port(std::size_t device) { return *ports_[device]; }

int BusHub::DeviceOf(int node) const {
  if (node >= first_device_node_ && node < first_device_node_ + static_cast<int>(devices_.size())) {
    return node - first_device_node_;
  }
  return node == emulator_node_ ? -1 : -2;
}

void BusHub::OpenLog(const std::string& path, std::string interface) {
  iface_ = std::move(interface);
  log_ = std::make_unique<bus::CandumpWriter>(path, bus::CandumpWriter::FlushPolicy::kBuffered);
}

void BusHub::StartBackgroundLog(const cpu_set_t* cpus) {
  if (log_) background_log_ = std::make_unique<BackgroundCandump>(*log_, iface_, cpus);
}

void BusHub::StopBackgroundLog() { background_log_.reset(); }

void BusHub::SetFrameFaults(std::size_t device, std::unique_ptr<FrameFaultFilter> filter) {
  frame_filters_[bus_node(device)] = std::move(filter);
}

void BusHub::SetBusFaults(std::vector<BusFault> faults, FaultEventLog* log) {
  faulty_bus_ = std::make_unique<FaultyCanBus>(bus_, std::move(faults), StuffingMode::kExact, log);
}

bool BusHub::Enqueue(int bus_node, const bus::CanFrame& f, std::int64_t ready_ns) {
  const std::uint64_t off0 = faulty_bus_ ? faulty_bus_->dropped_bus_off() : 0;
  const bool ok = faulty_bus_ ? faulty_bus_->Enqueue(bus_node, f, ready_ns)
                              : bus_.Enqueue(bus_node, f, ready_ns);
  if (ok) {
    ++enqueued_;
  } else if (!faulty_bus_ || faulty_bus_->dropped_bus_off() == off0) {
    // A bus-off discard is counted by FaultyCanBus (metrics.faults), not as a bus failure.
    ++enqueue_failures_;
  }
  return ok;
}

void BusHub::SubmitFromDevice(std::size_t device, std::vector<NodeFrame> frames,
                              bool from_poll) {
  const int node = bus_node(device);
  const auto filter = frame_filters_.find(node);
  // Nothing to send and no frame fault that may release a delayed frame: nothing to do.
  if (frames.empty() && filter == frame_filters_.end()) return;
  if (filter != frame_filters_.end()) {
    std::int64_t until = bus_.now_ns();
    if (from_poll) until = std::max(until, run_.now_ns);
    for (const auto& f : frames) until = std::max(until, f.due_ns);
    frames = filter->second->Process(frames, until);
  }
  for (const auto& nf : frames) (void)Enqueue(node, nf.frame, std::max(nf.due_ns, bus_.now_ns()));
}

void BusHub::ReleaseDelayed() {
  for (auto& [node, filter] : frame_filters_) {
    SubmitFromDevice(static_cast<std::size_t>(DeviceOf(node)), {}, true);
  }
}

void BusHub::EnqueueSync(const bus::CanFrame& sync, std::int64_t t_ns) {
  if (bus_.Enqueue(emulator_node_, sync, t_ns)) {
    ++enqueued_;
  } else {
    ++enqueue_failures_;
  }
}

void BusHub::EnqueueFromFirmware(const bus::CanFrame& f) {
  ++firmware_frames_;
  if (bus_.Enqueue(firmware_node_, f, bus_.now_ns())) {
    ++enqueued_;
  } else {
    ++enqueue_failures_;
  }
}

void BusHub::OnWire(const WireFrame& w) {
  if (wire_tap_) wire_tap_(w);
  const bool injected = faulty_bus_ && (w.node == faulty_bus_->flood_node() ||
                                        w.node == faulty_bus_->error_node() || w.frame.error);
  if (!injected) ++completed_;
  if (background_log_) {
    background_log_->Write(w.complete_ns, w.frame);
  } else if (log_) {
    (void)log_->Write(w.complete_ns, iface_, w.frame);
  }
  if (w.frame.error) return;  // an error burst: in can.log only (nothing to deliver)
  const int device = DeviceOf(w.node);
  if (w.node != firmware_node_) {
    if (firmware_send_ && !firmware_send_(w.frame)) ++enqueue_failures_;
    if (observer_) observer_->OnEmulatorFrame(w, device);
  }
  // Every node hears every frame but its own.
  for (std::size_t i = 0; i < devices_.size(); ++i) {
    if (static_cast<int>(i) == device) continue;
    devices_[i]->OnFrame(w.frame, w.complete_ns, *ports_[i]);
  }
}

void BusHub::AdvanceTo(std::int64_t t_ns) {
  constexpr std::int64_t kSlice = 20'000;
  while (bus_.now_ns() < t_ns) {
    const bool busy = enqueued_ > completed_;
    std::int64_t to = busy ? std::min(t_ns, bus_.now_ns() + kSlice) : t_ns;
    if (faulty_bus_) {
      for (const auto& w : faulty_bus_->AdvanceTo(to)) OnWire(w);
      continue;
    }
    if (busy && to < t_ns) {
      // Slices that end before the bus's next event only move its clock (no frame reaches
      // OnWire, so nothing is enqueued in between and `busy` stays): go straight to the first
      // slice boundary at or after that event. The boundaries stay those of the slice-by-slice
      // walk, so the bus sees the same calls where anything happens.
      const std::int64_t until = std::min(t_ns, bus_.NextEventNs());
      if (until > to) to = std::min(t_ns, to + (until - to + kSlice - 1) / kSlice * kSlice);
    }
    bus_.AdvanceTo(to, wire_scratch_);
    if (wire_scratch_.empty()) continue;
    // OnWire enqueues into the bus model but never advances it: the buffer stays as it is.
    for (const auto& w : wire_scratch_) OnWire(w);
  }
}

void BusHub::DrainToLog() {
  background_log_.reset();  // its queue written: what follows goes to log_ directly, in order
  for (const auto& w : bus_.Drain()) {
    ++completed_;
    (void)log_->Write(w.complete_ns, iface_, w.frame);
  }
}

void BusHub::CloseLog() { log_.reset(); }

nlohmann::json BusHub::Metrics() const {
  return nlohmann::json{
      {"frames", bus_.frames_sent()},
      {"load", bus_.BusLoad()},
      {"drops", bus_.frames_dropped() + enqueue_failures_},
      {"silenced_frames", silenced_},
      {"firmware_frames", firmware_frames_},
      {"max_queue_delay_s", static_cast<double>(bus_.max_queue_delay_ns()) * 1e-9}};
}

}  // namespace wheelhil::emulator::sim
