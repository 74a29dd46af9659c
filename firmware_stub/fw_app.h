#pragma once
/// The reference firmware without its sockets: CANopen master + cycle assembler + the estimator
/// the config selects + the output frames of bus/dbc/wheelhil_fw.dbc. Frames in (OnFrame), frames
/// out (appended to `out`), time in integer ns of any monotonic clock; the program
/// (wheelhil_fw_main.cc) adds only the SocketCAN transport and the clock, so tests drive exactly
/// what runs on the bus.
///
/// Per closed cycle (cycle_assembler.h) the app steps the estimator once and sends, in this
/// order, the estimate frames of the estimator (paper000: FW_Pose, FW_PoseRaw, FW_SlipStatus,
/// FW_Velocity; paper001: FW_Pose, FW_Velocity; paper002: FW_Pose, FW_Velocity,
/// FW_VelocityOdom, FW_VelocityAccel), then FW_Status last; all carry the cycle counter
/// (mod 256). While the SYNC-producing firmware waits for its nodes (before the first cycle),
/// FW_Status (state WaitingForNodes, cycle 0) goes out every sync period. Time steps are the
/// configured SYNC period times the SYNC intervals a step spans (not receive times), so the
/// output depends only on the frames, never on scheduling.
/// Clocks: `t_ns` everywhere is the host's monotonic clock (frame arrival, SYNC production, the
/// cycle deadline). The CANopen master's timers (heartbeat consumer, SDO, boot timeout) run on
/// it only while the app produces SYNC. While it follows SYNC (sync.produce false) they run on
/// *bus time*: sync.period_s per SYNC received, standing still between SYNCs, so a timeout
/// depends on the frame sequence, not on how fast the frames come (a lockstep emulator runs
/// 20-200x faster than real time; docs/firmware.md). Fallback for a bus without SYNC (dead
/// producer, or one that waits for the nodes): after SyncSilenceNs() of host time with no SYNC
/// (also counted from Start), bus time runs on with the host clock from there (sync_silent(),
/// FwAppStats::sync_silences) until SYNC returns; it never runs backwards.
/// Degrading, not dying: a cycle with an encoder missing skips the estimator step (the next
/// complete cycle spans the gap: counters are absolute, gyro and accelerometer samples carry
/// over); paper 002 instead steps its fusion every cycle of the gap without odometry (the
/// accelerometers carry the velocity) and takes the catch-up displacement into the observers'
/// position, not their velocity (see VelocityFusion); a source silent for lost_after_cycles
/// cycles is flagged lost; bad frames are counted. Every cycle with an input missing sets
/// Status_FaultCycleIncomplete (state Degraded).
/// Closed loop (a `drives` section): the drives are CANopen nodes of the master too (their
/// start-up writes 0x6060 mode, 0x6007 abort connection option and 0x1016:1, the consumer of
/// the firmware's own heartbeat, which goes out as node master_node_id every
/// ceil(master_heartbeat_s / period) cycles). Per cycle, after the estimator step and before the
/// estimate frames, the app gives the path follower (path_follower.h) its pose estimate, turns
/// the body velocity into wheel speeds and sends each drive's RPDO1 (cia402_drives.h). The path
/// starts once every drive is in Operation enabled and the estimator is ready (paper000:
/// calibrated); a drive fault, EMCY or lost node (drive or encoder) stops every drive, latched,
/// and the state becomes Fault.
/// Thread-compatible.

#include <array>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <vector>

#include "bus/can_frame.h"
#include "firmware_stub/canopen_master.h"
#include "firmware_stub/cia402_drives.h"
#include "firmware_stub/cycle_assembler.h"
#include "firmware_stub/encoder_counter.h"
#include "firmware_stub/fw_config.h"
#include "firmware_stub/fw_protocol.h"
#include "firmware_stub/paper000_slip_estimator.h"
#include "firmware_stub/paper001_follower_odometry.h"
#include "firmware_stub/paper002_velocity_fusion.h"
#include "firmware_stub/path_follower.h"

namespace wheelhil::fw {

/// Status_State values (VAL_ of FW_Status in wheelhil_fw.dbc).
enum class FwState : std::uint8_t {
  kBoot = 0,
  kWaitingForNodes = 1,
  kCalibrating = 2,
  kRunning = 3,
  kDegraded = 4,
  kFault = 5
};

struct FwAppStats {
  std::uint64_t frames_in = 0;
  std::uint64_t bad_frames = 0;      ///< Wrong DLC / checksum / undecodable known frames.
  std::uint64_t unknown_frames = 0;  ///< Ids the protocol does not know (also bad_frames).
  std::uint64_t foreign_frames = 0;  ///< Valid CANopen traffic of nodes we do not use.
  std::uint64_t cycles = 0;          ///< Cycles closed.
  std::uint64_t steps = 0;           ///< Estimator steps done.
  std::uint64_t skipped_steps = 0;   ///< Cycles without a step (inputs missing).
  std::uint64_t frames_out = 0;
  std::uint64_t accel_duplicates = 0;  ///< Accel frames repeating the previous counter.
  std::uint64_t accel_gaps = 0;        ///< Accel samples lost (counter jumps).
  /// Times the followed SYNC stayed away for SyncSilenceNs() of host time (bus dead?).
  std::uint64_t sync_silences = 0;
};

class FwApp {
 public:
  /// Cycles without a sample after which the IMU / accelerometer is reported lost.
  static constexpr int kLostAfterCycles = 3;

  /// Builds the estimator; throws std::invalid_argument "config-file: section: problem" when
  /// the estimator rejects the configuration. `protocol` must outlive the app.
  /// `drives`: the drives' binding, required when the config has a drives section.
  FwApp(const FwConfig& config, const FwProtocol& protocol, const DriveProtocol* drives = nullptr);

  void Start(std::int64_t t_ns, std::vector<bus::CanFrame>& out);
  /// One frame off the bus (never throws on its content).
  void OnFrame(const bus::CanFrame& frame, std::int64_t t_ns, std::vector<bus::CanFrame>& out);
  /// A frame that reached the interface at `arrival_ns` (its receive timestamp on the app's
  /// clock), handled whenever the program gets to it: first the timed work due before it
  /// arrived (Poll: a cycle whose deadline passed before the frame came closes without it),
  /// then the frame. So "in time" means arrived in time, not read in time (a preempted or busy
  /// program does not turn a late frame into a timely one). `arrival_ns` is clamped to the last
  /// time the app saw (the app's time never runs backwards).
  void OnFrameArrived(const bus::CanFrame& frame, std::int64_t arrival_ns,
                      std::vector<bus::CanFrame>& out);
  /// Timed work (master timers, SYNC production, cycle deadlines).
  void Poll(std::int64_t t_ns, std::vector<bus::CanFrame>& out);
  /// Next host instant Poll has something to do (INT64_MAX if nothing).
  std::int64_t NextEventNs() const;

  /// Following SYNC: host time without SYNC after which the master's timers fall back to the
  /// host clock: max(kSyncSilenceMinNs, kSyncSilencePeriods x sync period).
  static constexpr std::int64_t kSyncSilenceMinNs = 2'000'000'000;
  static constexpr std::int64_t kSyncSilencePeriods = 10;
  std::int64_t SyncSilenceNs() const { return sync_silence_ns_; }
  /// Following SYNC: the master's clock [ns] at host time t_ns (>= every value it gave before
  /// for an earlier t_ns). Producing SYNC: t_ns.
  std::int64_t MasterClockNs(std::int64_t t_ns) const;
  /// Following SYNC and none came for SyncSilenceNs() (host clock fallback active).
  bool sync_silent() const { return sync_silent_; }

  const CanopenMaster& master() const { return master_; }
  const CycleAssembler& assembler() const { return assembler_; }
  const FwAppStats& stats() const { return stats_; }
  /// The drives (nullptr without a drives section) and the path follower (without a path).
  const Cia402Drives* drives() const { return drives_ ? &*drives_ : nullptr; }
  const PathFollower* path() const { return follower_ ? &*follower_ : nullptr; }
  FwState state() const { return state_; }
  /// OR of FaultBit of the last status frame.
  std::uint32_t last_faults() const { return last_faults_; }

 private:
  void OnCycle(const AssembledCycle& c, std::vector<bus::CanFrame>& out);
  void Send(OutMessage m, const OutValues& v, std::vector<bus::CanFrame>& out);
  void SendStatus(std::uint64_t cycle, std::vector<bus::CanFrame>& out);
  bool StartupStatusDue() const;
  void Step000(const AssembledCycle& c, double dt_s, std::vector<bus::CanFrame>& out);
  void Step001(const AssembledCycle& c, double dt_s, std::vector<bus::CanFrame>& out);
  void Step002(const AssembledCycle& c, double dt_s, std::vector<bus::CanFrame>& out);
  void Step002Unobserved();
  void CommandDrives(std::uint64_t cycle, std::vector<bus::CanFrame>& out);
  Pose2 SteeringPose() const;
  bool EstimateReady() const;
  void HandleMasterPoll(CanopenMaster::PollResult r, std::int64_t t_ns,
                        std::vector<bus::CanFrame>& out);

  FwConfig config_;
  const FwProtocol& protocol_;
  CanopenMaster master_;
  CycleAssembler assembler_;
  std::vector<EncoderNode> nodes_;
  std::int64_t period_ns_ = 0;

  // The master's clock while following SYNC (see MasterClockNs).
  bool bus_clock_ = false;              // Following SYNC: the master runs on bus time.
  std::int64_t sync_silence_ns_ = 0;    // Host time without SYNC before the fallback.
  std::int64_t bus_ns_ = 0;             // Master clock at the last SYNC (or fallback catch-up).
  std::int64_t last_sync_host_ns_ = 0;  // Host time of the last SYNC (or Start).
  bool sync_silent_ = false;

  std::optional<SlipCorrectingOdometry> p000_;
  std::optional<FollowerOdometry> p001_;
  std::optional<VelocityFusion> p002_;
  FollowerGeometry p002_geometry_;
  std::array<double, 3> p002_odometry_{};  // Accumulated body-frame displacement (x, y, th).
  Pose2 p002_pose_;
  std::array<double, 3> vel_{};  // Body velocity of the last step (x fwd, y left, yaw) [SI].

  // Inputs carried over cycles that could not be stepped.
  std::array<bool, AssembledCycle::kMaxNodes> primed_{};
  std::array<std::uint32_t, AssembledCycle::kMaxNodes> last_position_{};
  std::uint64_t last_step_cycle_ = 0;
  bool have_step_cycle_ = false;
  double carry_dth_gyro_rad_ = 0.0;
  double last_yaw_rate_rad_s_ = 0.0;
  std::array<double, 4> last_accel_m_s2_{};
  int last_accel_counter_ = -1;
  int imu_silent_cycles_ = 0;
  int accel_silent_cycles_ = 0;

  // Closed loop.
  std::optional<Cia402Drives> drives_;
  std::optional<PathFollower> follower_;
  std::uint64_t heartbeat_every_cycles_ = 0;  // 0: no master heartbeat.
  std::uint64_t enabled_cycles_ = 0;          // Cycles with every drive enabled and ready.

  // Per-status-frame event faults.
  std::uint32_t event_faults_ = 0;
  std::uint8_t last_emcy_node_ = 0;
  std::uint64_t heartbeat_ = 0;
  std::int64_t next_startup_status_ns_ = 0;
  std::uint32_t last_faults_ = 0;
  FwState state_ = FwState::kBoot;
  FwAppStats stats_;
  std::int64_t last_t_ns_ = std::numeric_limits<std::int64_t>::min();  // Latest time seen.
};

/// A kernel receive timestamp (CLOCK_REALTIME, SO_TIMESTAMPNS) on the monotonic clock the app
/// runs on: now_mono_ns minus the frame's age (now_real_ns - stamp_real_ns). A stamp from the
/// future or older than max_age_ns (the wall clock was stepped) gives now_mono_ns.
std::int64_t ArrivalOnMonotonicNs(std::int64_t stamp_real_ns, std::int64_t now_real_ns,
                                  std::int64_t now_mono_ns,
                                  std::int64_t max_age_ns = 1'000'000'000);

/// Master and assembler settings derived from a firmware config (also used by tests). Following
/// SYNC, the master's boot, SDO and heartbeat timeouts are one sync period longer (bus time is
/// known to one period).
CanopenMasterConfig MasterConfigFrom(const FwConfig& config);
CycleAssemblerConfig AssemblerConfigFrom(const FwConfig& config);
/// Closed loop: the firmware's heartbeat goes out every this many cycles (0: none).
std::uint64_t MasterHeartbeatCycles(const FwConfig& config);
/// The consumer time written to each drive's 0x1016:1 [s].
double DriveHeartbeatTimeoutS(const FwConfig& config);

}  // namespace wheelhil::fw
