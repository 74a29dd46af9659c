#pragma once
/// The firmware's view of the bus protocol: the DBC files of bus/dbc/ bound, once at start, to
/// the fields the firmware reads and writes. Every frame in or out goes through the DBC codec
/// (bus/dbc_codec.h); nothing is hand-packed.
///
/// Binding rules (checked at load, errors throw std::invalid_argument "file: problem"):
///  - CANopen (cia406_encoder.dbc): messages by their CiA 301 identifier (NMT 0x000, SYNC 0x080,
///    EMCY 0x080+id, TPDO1 0x180+id, SDO 0x580+id / 0x600+id, NMT error control 0x700+id);
///    fields by their CiA 301 position (e.g. TPDO1 position = the Intel signal at bit 0, 32 bits),
///    so the firmware does not depend on how the DBC names its signals. A node id the DBC does
///    not list explicitly uses the layout of another node's message of the same function.
///  - IMU (bosch_mm5_10.dbc): the yaw-rate message by the configured id; yaw rate = the signal
///    at bit 0 (16 bits); its unit (deg/s, °/s or rad/s) is converted to rad/s.
///  - Accelerometers (wheelhil_accel4.dbc): the configured message; a1..a4 = its four
///    acceleration signals (unit m/s^2 or g) in start-bit order.
///  - Outputs (wheelhil_fw.dbc): messages by name (FW_Pose, FW_PoseRaw, FW_SlipStatus,
///    FW_Velocity, FW_VelocityOdom, FW_VelocityAccel, FW_Status); signals by name (see
///    ClassifyOutputSignal). Unknown signals of an output message are sent as raw 0.
/// Immutable after Load; decode/encode calls are noexcept and allocation-free; thread-safe.

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "bus/can_frame.h"
#include "bus/dbc.h"

namespace wheelhil::fw {

/// One expedited SDO frame's fields (CiA 301: command byte, index, subindex, data bytes 4..7).
struct SdoFrame {
  std::uint8_t command = 0;
  std::uint16_t index = 0;
  std::uint8_t subindex = 0;
  std::uint32_t data = 0;
  bool operator==(const SdoFrame&) const = default;
};

/// What a received frame is, by identifier.
enum class FrameKind : std::uint8_t {
  kUnknown,
  kNmt,           ///< 0x000 (another master's command).
  kSync,          ///< 0x080.
  kEmcy,          ///< 0x081..0x0FF.
  kTpdo1,         ///< 0x181..0x1FF.
  kSdoResponse,   ///< 0x581..0x5FF.
  kSdoRequest,    ///< 0x601..0x67F (another client's).
  kErrorControl,  ///< 0x701..0x77F: boot-up (state 0) or heartbeat.
  kImuYaw,
  kImuOther,  ///< Other messages of the IMU DBC (roll/pitch, accelerations): not used.
  kAccel,
  kOwnOutput,  ///< A wheelhil_fw.dbc frame (e.g. a second firmware, or our own echo).
};

/// Output quantities a wheelhil_fw.dbc signal can carry.
enum class OutField : std::uint8_t {
  kNone,
  kCycle,
  kX,
  kY,
  kTheta,
  kSlipLeft,
  kSlipRight,
  kSlipUnattributed,
  kOutOfBand,
  kCalibrated,
  kResidual,
  kBandLow,
  kBandHigh,
  kVx,
  kVy,
  kOmega,
  kHeartbeat,
  kState,
  kFaults,
  kFaultBootTimeout,
  kFaultNodeLost,
  kFaultEmcy,
  kFaultSdo,
  kFaultBadFrame,
  kFaultCycleIncomplete,
  kFaultLateFrame,
  kFaultEstimator,
  kFaultConfig,
  kNodesLost,
  kNodeLostEnc1,
  kNodeLostEnc2,
  kNodeLostEnc3,
  kNodeLostEnc4,  ///< By CANopen node id.
  kNodeLostEnc5,
  kNodeLostEnc6,
  kNodeLostEnc7,
  kNodeLostEnc8,
  kNodeLostImu,
  kNodeLostAccel,
  kEmcyNodeId,
  kBadFrameCount,
  kCount,
};

/// kNodeLostEnc<node_id> for node ids 1..8, kNone otherwise.
OutField NodeLostField(int node_id) noexcept;

/// Classifies a wheelhil_fw.dbc signal by its name, case and '_' ignored, with or without its
/// message prefix (`Pose_X`, `Vel_Vx`, `Slip_BandLower`, `Status_NodeLostEnc3`): e.g. `X` ->
/// kX, `Cycle` -> kCycle, `FaultEmcy` -> kFaultEmcy. kNone when not recognised.
OutField ClassifyOutputSignal(const std::string& name) noexcept;

enum class OutMessage : std::uint8_t {
  kPose,
  kPoseRaw,
  kSlipStatus,
  kVelocity,
  kVelocityOdom,
  kVelocityAccel,
  kStatus,
  kCount
};
const char* OutMessageName(OutMessage m) noexcept;

/// Values for one output frame; fields not set are sent as 0.
struct OutValues {
  std::array<double, static_cast<std::size_t>(OutField::kCount)> v{};
  void Set(OutField f, double value) { v[static_cast<std::size_t>(f)] = value; }
  double Get(OutField f) const { return v[static_cast<std::size_t>(f)]; }
};

class FwProtocol {
 public:
  struct Sources {
    std::shared_ptr<const bus::DbcDatabase> cia406;  ///< Required.
    std::shared_ptr<const bus::DbcDatabase> imu;     ///< Required when imu_yaw_id != 0.
    std::shared_ptr<const bus::DbcDatabase> accel;   ///< Required when accel_id != 0.
    std::shared_ptr<const bus::DbcDatabase> fw;      ///< Required.
    std::string cia406_name = "cia406_encoder.dbc", imu_name = "bosch_mm5_10.dbc",
                accel_name = "wheelhil_accel4.dbc", fw_name = "wheelhil_fw.dbc";
  };

  /// Binds the databases. node_ids: the CANopen nodes used; imu_yaw_id / accel_id: 0 = none.
  FwProtocol(Sources sources, const std::vector<int>& node_ids, std::uint32_t imu_yaw_id,
             std::uint32_t accel_id);

  /// Loads the four files from `dir` and binds them.
  static FwProtocol LoadDir(const std::string& dir, const std::vector<int>& node_ids,
                            std::uint32_t imu_yaw_id, std::uint32_t accel_id);

  /// The DBC directory: `configured` if not empty; else $WHEELHIL_DBC_DIR; else the shipped
  /// files of a build tree or an install (bus/install_paths.h). Empty when none is found.
  static std::string FindDbcDir(const std::string& configured, const std::string& exe_dir);

  FrameKind Classify(const bus::CanFrame& frame, std::uint8_t& node_id) const noexcept;

  [[nodiscard]] bool EncodeNmt(std::uint8_t command, std::uint8_t node_id,
                               bus::CanFrame& out) const noexcept;
  [[nodiscard]] bool EncodeSync(bus::CanFrame& out) const noexcept;
  [[nodiscard]] bool EncodeSdoRequest(std::uint8_t node_id, const SdoFrame& sdo,
                                      bus::CanFrame& out) const noexcept;

  /// The NMT error-control frame of `node_id` (0x700+id) carrying `state` (a heartbeat the
  /// firmware produces as a node itself, e.g. 0x05 operational).
  [[nodiscard]] bool EncodeHeartbeat(std::uint8_t node_id, std::uint8_t state,
                                     bus::CanFrame& out) const noexcept;

  /// Decoders return false for a frame whose length differs from its DBC message's.
  [[nodiscard]] bool DecodeErrorControl(const bus::CanFrame& f, std::uint8_t& state) const noexcept;
  [[nodiscard]] bool DecodeEmcy(const bus::CanFrame& f, std::uint16_t& code,
                                std::uint8_t& error_register) const noexcept;
  [[nodiscard]] bool DecodeTpdo1(const bus::CanFrame& f, std::uint32_t& position,
                                 std::int16_t& speed) const noexcept;
  [[nodiscard]] bool DecodeSdoResponse(const bus::CanFrame& f, SdoFrame& sdo) const noexcept;
  [[nodiscard]] bool DecodeYawRate(const bus::CanFrame& f, double& rate_rad_s) const noexcept;
  /// The four channels; when the message has a rolling counter (`*Counter`) it goes to
  /// `counter` (else -1). With a 4-bit `*Checksum` at bits 60..63 the frame must carry the XOR
  /// of its other 15 nibbles (wheelhil_accel4.dbc), else it is rejected.
  [[nodiscard]] bool DecodeAccel(const bus::CanFrame& f, std::array<double, 4>& a_m_s2,
                                 int& counter) const noexcept;

  bool HasOutput(OutMessage m) const noexcept {
    return outputs_[static_cast<std::size_t>(m)].msg != nullptr;
  }
  /// Which fields the output message carries (for tests and the start-up report).
  std::vector<OutField> OutputFields(OutMessage m) const;
  /// Builds an output frame; the cycle counter and heartbeat are wrapped modulo their signal's
  /// range. False when the message is missing or a value had to be saturated (frame still built).
  bool EncodeOutput(OutMessage m, const OutValues& values, bus::CanFrame& out) const noexcept;
  /// Decodes an output frame back into fields (tests, determinism checks).
  bool DecodeOutput(OutMessage m, const bus::CanFrame& f, OutValues& values) const noexcept;
  /// Signals of output messages that matched no field (reported once at start).
  const std::vector<std::string>& unbound_output_signals() const { return unbound_; }

 private:
  struct Layout {  // One CANopen function's message and fields.
    const bus::DbcMessage* msg = nullptr;
    std::array<const bus::DbcSignal*, 4> sig{};
  };
  struct Output {
    const bus::DbcMessage* msg = nullptr;
    std::vector<std::pair<const bus::DbcSignal*, OutField>> fields;
  };

  Sources src_;
  Layout nmt_, sync_, emcy_, tpdo_, sdo_rx_, sdo_tx_, errctl_;
  Layout imu_yaw_;
  const bus::DbcDatabase* imu_db_ = nullptr;
  Layout accel_;
  std::uint32_t imu_yaw_id_ = 0, accel_id_ = 0;
  double yaw_scale_ = 1.0;  // signal unit -> rad/s
  std::array<double, 4> accel_scale_{1, 1, 1, 1};
  const bus::DbcSignal* accel_counter_ = nullptr;
  const bus::DbcSignal* accel_checksum_ = nullptr;
  std::array<Output, static_cast<std::size_t>(OutMessage::kCount)> outputs_{};
  std::vector<std::string> unbound_;
};

}  // namespace wheelhil::fw
