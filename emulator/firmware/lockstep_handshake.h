#pragma once
/// What lockstep waits for, read off the bus. During start-up the firmware, as CANopen master,
/// reacts to every boot-up message (0x700+id [00]) and SDO response (0x580+id) of a node with
/// an SDO request or an NMT command: until it did, virtual time must not go on. In the motion
/// phase the reference firmware answers every SYNC cycle with FW_Status (wheelhil_fw.dbc:
/// Status_Cycle = SYNC number mod 256, Status_State): a cycle is waited for once its frames are
/// all on the wire (the SYNC and the sync-answering frame of every device that has one), and
/// closed by the next SYNC otherwise. Firmware state changes become "firmware_state" events.
/// Thread-compatible.

#include <cstdint>
#include <map>
#include <memory>
#include <set>
#include <vector>

#include "bus/dbc.h"
#include "emulator/sim/bus_hub.h"
#include "emulator/sim/run_context.h"

namespace wheelhil::emulator::firmware {

/// A frame a device sends in answer to each SYNC (a TPDO): its id and the length the firmware
/// accepts.
struct SyncAnswer {
  int device = 0;  ///< Device index on the hub.
  std::uint32_t id = 0;
  std::uint8_t len = 0;
};

class LockstepHandshake final : public sim::BusObserver {
 public:
  LockstepHandshake(std::shared_ptr<const bus::DbcDatabase> firmware_dbc, const sim::BusHub& hub,
                    sim::RunContext& run);

  /// The frames that complete a cycle on the bus (at most 32 devices), from the motion start.
  void ExpectSyncAnswers(std::vector<SyncAnswer> answers);

  void OnEmulatorFrame(const WireFrame& w, int device) override;
  /// A frame the firmware sent.
  void OnFirmwareFrame(const bus::CanFrame& f);
  /// A SYNC was enqueued.
  void OnSyncSent() { ++syncs_sent_; }

  /// Nodes whose boot-up / SDO answer the firmware has not reacted to yet.
  const std::set<int>& awaiting_nodes() const { return awaiting_nodes_; }
  bool StatusSeen(int cycle) const { return status_frames_ > 0 && last_status_cycle_ == cycle; }
  /// The latest SYNC is on the wire and every sync-answering device answered it.
  bool CycleCompleteOnBus() const {
    return syncs_on_wire_ == syncs_sent_ && answers_since_sync_ == all_answers_;
  }
  bool LatestSyncOnWire() const { return syncs_on_wire_ >= syncs_sent_; }
  std::uint64_t syncs_sent() const { return syncs_sent_; }

 private:
  std::shared_ptr<const bus::DbcDatabase> dbc_;
  const sim::BusHub& hub_;
  sim::RunContext& run_;
  const bus::DbcMessage* status_msg_ = nullptr;
  std::vector<const bus::DbcSignal*> status_cycle_, status_state_;
  std::set<int> awaiting_nodes_;
  std::uint64_t syncs_sent_ = 0, syncs_on_wire_ = 0;
  std::uint64_t status_frames_ = 0;
  int last_status_cycle_ = -1;
  int last_state_ = -1;
  std::vector<SyncAnswer> answers_;
  std::uint32_t answers_since_sync_ = 0, all_answers_ = 0;
};

}  // namespace wheelhil::emulator::firmware
