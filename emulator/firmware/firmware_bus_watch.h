#pragma once
/// What the run reads off the bus of the firmware. During start-up the firmware, as CANopen
/// master, reacts to every boot-up message (0x700+id [00]) and SDO response (0x580+id) of a node
/// with an SDO request or an NMT command: the start-up goes on once none is left unanswered
/// (awaiting_nodes) and every node was started. SYNCs sent, by the emulator or the firmware,
/// number the cycles. The reference firmware's FW_Status (wheelhil_fw.dbc) is an output
/// nothing waits for: its state changes become "firmware_state" events. Thread-compatible.

#include <cstdint>
#include <memory>
#include <set>
#include <vector>

#include "bus/can_frame.h"
#include "bus/dbc.h"
#include "emulator/sim/bus_hub.h"
#include "emulator/sim/run_context.h"

namespace wheelhil::emulator::firmware {

class FirmwareBusWatch final : public sim::BusObserver {
 public:
  FirmwareBusWatch(std::shared_ptr<const bus::DbcDatabase> firmware_dbc, const sim::BusHub& hub,
                   sim::RunContext& run);

  void OnEmulatorFrame(const WireFrame& w, int device) override;
  /// A frame the firmware sent.
  void OnFirmwareFrame(const bus::CanFrame& f);
  /// A SYNC was sent.
  void OnSyncSent() { ++syncs_sent_; }

  /// Nodes whose boot-up / SDO answer the firmware has not reacted to yet.
  const std::set<int>& awaiting_nodes() const { return awaiting_nodes_; }
  std::uint64_t syncs_sent() const { return syncs_sent_; }

 private:
  std::shared_ptr<const bus::DbcDatabase> dbc_;
  const sim::BusHub& hub_;
  sim::RunContext& run_;
  const bus::DbcMessage* status_msg_ = nullptr;
  std::vector<const bus::DbcSignal*> status_state_;
  std::set<int> awaiting_nodes_;
  std::uint64_t syncs_sent_ = 0;
  int last_state_ = -1;
};

}  // namespace wheelhil::emulator::firmware
