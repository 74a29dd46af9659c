#pragma once
/// A CANopen rotary encoder node after CiA 301 (communication) and CiA 406 (encoder profile),
/// as a pure state machine in virtual time (integer ns). No threads, no I/O: the caller feeds
/// frames off the bus with OnFrame, the current encoder reading with SetMeasurement, and calls
/// Poll to collect the frames the node sends; every output carries the instant it is due.
///
/// NMT: power-on -> (power_on_delay) boot-up `0x700+id` [00] -> pre-operational. NMT module
/// control on 0x000 [cs, node] (node 0 = all): 0x01 start -> operational, 0x02 stop -> stopped,
/// 0x80 -> pre-operational, 0x81 reset node (application + communication parameters back to
/// their configured values), 0x82 reset communication (0x1000..0x1FFF only) -> boot-up again
/// after reset_delay. Frames addressed to other nodes are ignored.
/// Heartbeat producer (0x1017, ms; 0 = off) on 0x700+id: 0x7F pre-operational, 0x05
/// operational, 0x04 stopped; the first heartbeat follows the boot-up by one period; writing
/// 0x1017 restarts the period from the SDO response (new values take effect when the node
/// answers).
/// TPDO1 (COB-ID 0x1800:1, default 0x180+id; bit 31 = not valid) maps 0x6004 position value (u32
/// counts) and 0x6030:1 speed value (int16, saturating), only in operational:
///   transmission type 1..240: on every n-th SYNC (0x080) counted from entering operational;
///   type 0: on a SYNC when the position changed since the last TPDO;
///   types 254/255: every 0x6200 cyclic timer ms (alias of the TPDO1 event timer 0x1800:5; 0 =
///   off), the first one period after entering operational (or after the timer was written).
/// SDO server on 0x600+id -> 0x580+id, expedited transfers only (every object here fits 4
/// bytes); segmented/block transfers and unknown command specifiers abort with 0x05040001.
/// Object dictionary: 0x1000 device type (ro), 0x1001 error register (ro), 0x1017 heartbeat
/// (rw u16), 0x1018 identity sub 0..4 (ro), 0x1800 TPDO1 communication sub 0, 1 (rw u32), 2 (rw
/// u8), 5 (rw u16), 0x1A00 TPDO1 mapping sub 0..2 (ro: fixed mapping 0x60040020, 0x60300110),
/// 0x6000 operating parameters (rw u16; bit 0 code sequence = count direction inverted),
/// 0x6004 position value (ro u32), 0x6030 speed value sub 0 (ro, 1) and 1 (ro int16), 0x6200
/// cyclic timer (rw u16 ms), and Cia406NodeConfig::extra_objects. Aborts: 0x06020000 no object, 0x06090011 no subindex,
/// 0x06010002 read-only, 0x06070010 length mismatch, 0x06090030 bad value, 0x05040001 bad
/// command. SDO requests are served in pre-operational and operational, not in stopped.
/// EMCY on 0x080+id when a device fault is raised (error code, error register 0x1001) and an
/// error-reset EMCY (code 0x0000) when it clears; not sent in stopped.
/// Responses to SYNC and SDO requests are due response_delay_ns after the request.
/// Frames are built and read by a Cia406Codec: DbcCia406Codec, over bus/dbc/cia406_encoder.dbc.
/// Thread-compatible.

#include <cstdint>
#include <memory>
#include <vector>

#include "bus/can_frame.h"
#include "bus/canopen.h"
#include "emulator/devices/cia406_codec.h"

namespace wheelhil::emulator {

struct Cia406NodeConfig {
  std::uint8_t node_id = 1;                      ///< 1..127.
  std::int64_t power_on_delay_ns = 100'000'000;  ///< Power-on to boot-up message.
  std::int64_t reset_delay_ns = 10'000'000;      ///< NMT reset command to boot-up message.
  std::int64_t response_delay_ns = 0;            ///< SYNC/SDO request to the node's answer.
  std::uint16_t heartbeat_ms = 0;                ///< 0x1017 default.
  std::uint8_t tpdo1_transmission_type = 254;    ///< 0x1800:2 default (0..240, 254, 255).
  std::uint16_t cyclic_timer_ms = 0;             ///< 0x6200 (= 0x1800:5) default.
  std::uint16_t operating_parameters = 0;        ///< 0x6000 default.
  std::uint32_t device_type = 0x00020196;        ///< 0x1000: profile 406, multi-turn encoder.
  std::uint32_t vendor_id = 0;                   ///< 0x1018:1.
  std::uint32_t product_code = 0;                ///< 0x1018:2.
  std::uint32_t revision = 0;                    ///< 0x1018:3.
  std::uint32_t serial = 0;                      ///< 0x1018:4.
  /// Speed value 0x6030:1 unit: counts per speed_time_base_s (1.0 = counts/s, 0.001 = /ms).
  double speed_time_base_s = 1.0;
  /// Objects beyond the built-in dictionary (from the vendor's EDS: 0x1008.., 0x6001, 0x2000..),
  /// expedited: up to 4 bytes. Uploads read their value; downloads to writable ones keep the
  /// value (length checked) until the reset of their area (communication 0x1000..0x1FFF,
  /// application the rest).
  struct ExtraObject {
    std::uint16_t index = 0;
    std::uint8_t sub = 0;
    std::uint32_t value = 0;
    std::uint8_t size = 4;
    bool writable = false;
  };
  std::vector<ExtraObject> extra_objects{};
};

/// A frame the node sends and the virtual instant it is due on the bus.
struct NodeFrame {
  bus::CanFrame frame;
  std::int64_t due_ns = 0;
};

class CanopenEncoderNode {
 public:
  enum class NmtState : std::uint8_t {
    kOff = 0xFF,  ///< Powered, not yet booted (or resetting); never reported on the bus.
    kPreOperational = bus::canopen::nmt_state::kPreOperational,
    kOperational = bus::canopen::nmt_state::kOperational,
    kStopped = bus::canopen::nmt_state::kStopped,
  };

  /// Powers the node on at power_on_ns. Throws std::invalid_argument on a bad configuration
  /// (node id, transmission type, delays) or a null codec.
  CanopenEncoderNode(const Cia406NodeConfig& config, std::shared_ptr<const Cia406Codec> codec,
                     std::int64_t power_on_ns = 0);

  /// The encoder reading the next TPDO and SDO uploads report: raw counter value and speed.
  void SetMeasurement(std::uint32_t position_counts, double speed_counts_per_s) noexcept;

  /// Handles one frame off the bus at instant t_ns (SYNC, NMT, SDO requests for this node;
  /// anything else is ignored). Returns the frames the node answers with. Timed events due at
  /// or before t_ns happen first (call Poll(t_ns) before OnFrame to collect them in order;
  /// otherwise the next Poll returns them). Never throws.
  std::vector<NodeFrame> OnFrame(const bus::CanFrame& frame, std::int64_t t_ns);
  /// OnFrame acts on standard frames with this id: NMT, SYNC, its own SDO requests.
  bool ReadsFrame(std::uint32_t id) const;

  /// Returns every timed frame (boot-up, heartbeat, cyclic TPDO, pending EMCY) due at or before
  /// t_ns, in due order, each with its own due instant. t_ns must not go backwards.
  std::vector<NodeFrame> Poll(std::int64_t t_ns);

  /// The next instant Poll would produce something (INT64_MAX if none).
  std::int64_t NextEventNs() const;

  /// Device fault (e.g. 0x7305 incremental sensor 1 fault, error register bit 0x01 generic /
  /// 0x80 manufacturer): sets 0x1001 and sends EMCY at t_ns. ClearFault sends the error reset.
  void RaiseFault(std::uint16_t error_code, std::uint8_t error_register, std::int64_t t_ns);
  void ClearFault(std::int64_t t_ns);

  NmtState state() const { return state_; }
  /// Frames rejected by the codec (malformed SDO / NMT frames) so far.
  std::uint64_t rejected_frames() const { return rejected_frames_; }

 private:
  struct SdoResult {
    std::uint32_t abort = 0;
    std::uint32_t value = 0;
    std::uint8_t size = 0;  ///< Bytes of the object (1, 2, 4) for uploads.
  };

  void ResetApplication();
  void ResetCommunication();
  void ResetExtraObjects(bool communication);
  void ScheduleBoot(std::int64_t t_ns);
  void EnterOperational(std::int64_t t_ns);
  void HandleNmt(std::uint8_t command, std::int64_t t_ns);
  void HandleSync(std::int64_t t_ns, std::vector<NodeFrame>& out);
  void HandleSdo(const SdoFields& request, std::int64_t t_ns, std::vector<NodeFrame>& out);
  SdoResult Read(std::uint16_t index, std::uint8_t sub) const;
  std::uint32_t Write(std::uint16_t index, std::uint8_t sub, std::uint32_t value, std::uint8_t size,
                      std::int64_t t_ns);
  std::uint32_t ReportedPosition() const;
  std::int16_t ReportedSpeed() const;
  void EmitTpdo(std::int64_t due_ns, std::vector<NodeFrame>& out);
  void Emit(bool ok, const bus::CanFrame& frame, std::int64_t due_ns, std::vector<NodeFrame>& out);

  Cia406NodeConfig config_;
  std::shared_ptr<const Cia406Codec> codec_;
  NmtState state_ = NmtState::kOff;
  std::int64_t now_ns_ = 0;
  std::int64_t boot_due_ns_;        ///< Pending boot-up instant, or INT64_MAX.
  std::int64_t next_heartbeat_ns_;  ///< INT64_MAX when off.
  std::int64_t next_tpdo_ns_;       ///< Cyclic TPDO, INT64_MAX when off.
  std::vector<NodeFrame> pending_;  ///< EMCY waiting for Poll.
  // Communication parameters.
  std::uint16_t heartbeat_ms_ = 0;
  std::uint32_t tpdo1_cob_id_ = 0;
  std::uint8_t tpdo1_type_ = 254;
  std::uint16_t cyclic_timer_ms_ = 0;
  // Application parameters.
  std::uint16_t operating_parameters_ = 0;
  std::uint8_t error_register_ = 0;
  // Inputs and counters.
  std::uint32_t position_counts_ = 0;
  double speed_counts_per_s_ = 0.0;
  unsigned sync_count_ = 0;
  bool have_last_tpdo_position_ = false;
  std::uint32_t last_tpdo_position_ = 0;
  std::uint64_t rejected_frames_ = 0;
  std::vector<Cia406NodeConfig::ExtraObject> extra_;  ///< Current values.
};

}  // namespace wheelhil::emulator
