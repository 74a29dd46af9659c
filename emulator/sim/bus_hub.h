#pragma once
/// The run's CAN bus: the bus timing model (CanBusModel, every frame's completion instant),
/// the bus-level faults around it (FaultyCanBus: error bursts, bus-off, floods), the frame
/// faults on each device's output (FrameFaultFilter), can.log, and the distribution of every
/// frame that completes on the wire: to the firmware (its link), to a BusObserver (the run's
/// firmware bus watch) and to every device but its sender. A device's frames take the path
///   device -> its device faults (in the device) -> frame faults -> bus-off -> bus model.
/// The SYNC producer's and the firmware's frames enter the bus model directly.
/// Inside a step the bus advances in 20 us slices while frames are in flight, so the answers
/// to frames completing inside the step are queued at (about) their own instants; slices in
/// which nothing starts or completes are skipped. Thread-compatible (the run's thread).

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bus/candump_log.h"
#include "emulator/devices/can_bus_model.h"
#include "emulator/devices/device.h"
#include "emulator/faults/bus_faults.h"
#include "emulator/faults/frame_faults.h"
#include "emulator/sim/run_context.h"

namespace wheelhil::emulator::sim {

class BackgroundCandump;

/// Who else sees the wire: the run's watch of what the firmware answers.
class BusObserver {
 public:
  virtual ~BusObserver() = default;
  /// A frame from the emulator's side (a device or the SYNC producer) completed on the wire.
  /// `device`: the sending device's index, -1 for the SYNC producer, -2 for injected traffic.
  virtual void OnEmulatorFrame(const WireFrame& w, int device) = 0;
};

/// Where frames for the firmware go (its bus link); false: the frame could not be handed over.
using FirmwareSend = std::function<bool(const bus::CanFrame&)>;

class BusHub {
 public:
  /// Owns nothing of the devices: `devices` must outlive the hub. Bus nodes are added in this
  /// order: "emulator" (SYNC producer), "firmware", then one per device.
  BusHub(const CanBusConfig& config, std::vector<std::unique_ptr<Device>>& devices,
         RunContext& run);
  ~BusHub();
  BusHub(const BusHub&) = delete;
  BusHub& operator=(const BusHub&) = delete;

  /// A copy of this bus as it is now (bus model, bus faults, frame faults, counters) around
  /// `devices` (copies of the devices, Device::Clone) and `run`, for a forecast: it writes no
  /// can.log, has no observer and hands the firmware's frames to `firmware_send`.
  std::unique_ptr<BusHub> CopyForForecast(std::vector<std::unique_ptr<Device>>& devices,
                                          RunContext& run, FirmwareSend firmware_send) const;

  /// can.log, written as frames complete (kBuffered).
  void OpenLog(const std::string& path, std::string interface);
  /// From here can.log lines are formatted on a thread of their own on `cpus` (nullptr: any).
  void StartBackgroundLog(const cpu_set_t* cpus);
  void StopBackgroundLog();
  void SetFirmwareSend(FirmwareSend send) { firmware_send_ = std::move(send); }
  void SetObserver(BusObserver* observer) { observer_ = observer; }
  /// Every frame that completes on the wire, first (a forecast's record of the bus).
  void SetWireTap(std::function<void(const WireFrame&)> tap) { wire_tap_ = std::move(tap); }

  /// Fault wiring at the motion start: frame faults on a device's output, bus faults.
  void SetFrameFaults(std::size_t device, std::unique_ptr<FrameFaultFilter> filter);
  void SetBusFaults(std::vector<BusFault> faults, FaultEventLog* log);

  /// A device's frames (through its frame faults) into the bus model.
  void SubmitFromDevice(std::size_t device, std::vector<NodeFrame> frames, bool from_poll);
  /// The frame faults release delayed frames (and copies) due by now.
  void ReleaseDelayed();
  /// SYNC from the emulator at t_ns.
  void EnqueueSync(const bus::CanFrame& sync, std::int64_t t_ns);
  /// A frame the firmware sent, at the bus model's current instant.
  void EnqueueFromFirmware(const bus::CanFrame& frame);
  /// Moves the bus to t_ns; every frame completing on the way is distributed.
  void AdvanceTo(std::int64_t t_ns);
  /// Completes everything still queued (end of the run) into can.log only.
  void DrainToLog();
  void CloseLog();

  std::int64_t now_ns() const { return bus_.now_ns(); }
  std::int64_t bit_time_ns() const { return bus_.bit_time_ns(); }
  DevicePort& port(std::size_t device);
  int bus_node(std::size_t device) const { return first_device_node_ + static_cast<int>(device); }
  const FaultyCanBus* faulty_bus() const { return faulty_bus_.get(); }
  const std::map<int, std::unique_ptr<FrameFaultFilter>>& frame_filters() const {
    return frame_filters_;
  }

  /// report.json's "bus" block.
  nlohmann::json Metrics() const;

 private:
  class Port;
  BusHub(const BusHub& other, std::vector<std::unique_ptr<Device>>& devices, RunContext& run);
  // The device that owns bus node `node`, -1 for the SYNC producer, -2 for anyone else (the
  // firmware, injected traffic).
  int DeviceOf(int node) const;
  bool Enqueue(int bus_node, const bus::CanFrame& f, std::int64_t ready_ns);
  void OnWire(const WireFrame& w);

  CanBusModel bus_;
  std::vector<std::unique_ptr<Device>>& devices_;
  RunContext& run_;
  int emulator_node_ = 0, firmware_node_ = 0;
  int first_device_node_ = 0;  // devices are the nodes first_device_node_ + index
  std::vector<std::unique_ptr<Port>> ports_;
  std::unique_ptr<FaultyCanBus> faulty_bus_;
  std::map<int, std::unique_ptr<FrameFaultFilter>> frame_filters_;  // by bus node
  FirmwareSend firmware_send_;
  BusObserver* observer_ = nullptr;
  std::function<void(const WireFrame&)> wire_tap_;
  std::string iface_;
  std::unique_ptr<bus::CandumpWriter> log_;
  // Declared after log_: stopped, its queue written, before log_ goes.
  std::unique_ptr<BackgroundCandump> background_log_;
  std::vector<WireFrame> wire_scratch_;  // AdvanceTo: the frames of one slice
  std::uint64_t enqueued_ = 0, completed_ = 0, silenced_ = 0, enqueue_failures_ = 0;
  std::uint64_t firmware_frames_ = 0;
};

}  // namespace wheelhil::emulator::sim
