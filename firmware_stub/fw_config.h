#pragma once
/// Configuration of the reference estimator firmware (`wheelhil-fw --config FILE.yaml`), one file
/// per paper platform (scenarios/firmware/*.yaml; every field is documented in docs/firmware.md).
/// SI units, the unit in each key's suffix (`track_width_m`, `sync_period_s`); angles in the
/// file are degrees where the key says `_deg`. Loading throws std::invalid_argument reading
/// "file:line:col: field: problem" on bad input (unknown keys included, so typos are caught).
/// A value type; thread-compatible.

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "firmware_stub/planar_pose.h"

namespace wheelhil::fw {

enum class EstimatorKind { kPaper000SlipCorrection, kPaper001FollowerOdometry, kPaper002Fusion };

/// The CANopen master's start-up and supervision (see canopen_master.h).
struct CanopenSettings {
  double boot_timeout_s = 2.0;  ///< Wait this long for boot-up messages, then go on (fault bit).
  /// Producer heartbeat time written to each node's 0x1017 [s]; 0 = leave the node's own.
  double heartbeat_period_s = 0.1;
  /// Consumer timeout [s]: no heartbeat for this long -> node lost. 0 = no supervision.
  double heartbeat_timeout_s = 0.35;
  double sdo_timeout_s = 0.1;  ///< One SDO request's answer time [s].
  int sdo_retries = 2;         ///< Repeats of a request that timed out before giving up.
  /// TPDO1 transmission type written to 0x1800:2 (1..240: every n-th SYNC). 0 = leave it.
  int tpdo_transmission_type = 1;
  /// Send NMT reset communication (0x82, all nodes) at start so nodes that booted before the
  /// firmware announce themselves again.
  bool reset_communication_at_start = false;
};

/// SYNC production and the cycle's timing (see cycle_assembler.h).
struct SyncSettings {
  bool produce = true;     ///< The firmware is the SYNC producer (else it follows 0x080).
  double period_s = 0.01;  ///< SYNC / estimator cycle period [s], > 0.
  /// A cycle closes at the latest this long after its SYNC [s], in [0, period]; 0 = no deadline
  /// (a cycle then waits for its frames or the next SYNC: the choice for replayed traffic,
  /// which cannot depend on scheduling). The loader's default is 0.9 period.
  double deadline_s = 0.0;
};

/// Bosch MM5.10-style yaw-rate IMU (bus/dbc/bosch_mm5_10.dbc).
struct ImuSettings {
  bool enabled = false;
  std::uint32_t yaw_frame_id = 0x174;  ///< Message carrying the yaw rate (z, CCW positive).
  double gyro_bias_rad_s = 0.0;        ///< Subtracted from every yaw-rate sample.
};

/// The four single-axis accelerometers of paper 002 (bus/dbc/wheelhil_accel4.dbc).
struct AccelSettings {
  bool enabled = false;
  std::uint32_t frame_id = 0;  ///< Message with the four channels a1..a4 (> 0 when enabled).
};

/// One encoder node: CANopen id and counting sense (+1, or -1 for a mirrored mounting).
struct EncoderNode {
  int node_id = 0;
  int sign = 1;
};

struct Paper000Settings {
  double track_width_m = 0.0;
  double wheel_radius_m = 0.0;
  double counts_per_rev = 0.0;
  int counter_bits = 32;
  EncoderNode left, right;
  int calibration_samples = 0;
  double residual_mean_rad = 0.0;
  double residual_sigma_rad = 0.0;
  double z = 1.96;
  HeadingRule heading_rule = HeadingRule::kMidpoint;
};

struct Paper001Settings {
  double mount_radius_m = 0.0;     ///< d.
  double follower_radius_m = 0.0;  ///< r.
  double counts_per_rev = 0.0;
  int counter_bits = 32;
  std::array<EncoderNode, 3> followers{};  ///< f, l, r.
  std::array<double, 3> angles_rad = {1.5707963267948966, 3.6651914291880923, 5.7595865315812871};
  HeadingRule heading_rule = HeadingRule::kStart;
};

struct Paper002AxisSettings {
  double k11_1_s = 80.0, k12_u_s = 0.002, k21_1_s2 = 1600.0, k22_u_s2 = 0.5;
  double boundary_layer_u = 1e-4;
  double disturbance_threshold_u_s2 = 0.1;
  double recovery_time_s = 0.1;
};

struct Paper002Settings {
  double wheel_radius_m = 0.0;        ///< Effective radius of the drive-wheel assemblies.
  double wheel_mount_radius_m = 0.0;  ///< Centre to wheel contact.
  double counts_per_rev = 0.0;
  int counter_bits = 32;
  std::array<EncoderNode, 3> wheels{};
  /// Wheel angles from the body x (forward) axis, CCW; each rolls along its CCW tangent.
  std::array<double, 3> angles_rad = {0.0, 2.0943951023931957, 4.1887902047863905};
  double accel_mount_radius_m = 0.0;
  std::array<Paper002AxisSettings, 3> axes = {
      Paper002AxisSettings{80.0, 0.002, 1600.0, 0.5, 1e-4, 0.1, 0.100},
      Paper002AxisSettings{80.0, 0.002, 1600.0, 0.5, 1e-4, 0.1, 0.150},
      Paper002AxisSettings{80.0, 0.002, 1600.0, 0.5, 1e-4, 0.5, 0.200}};
  double k_min = 0.01;
};

/// One CiA 402 drive the firmware commands: its node, where its wheel sits on the body and how
/// the wheel rolls (rollers for Mecanum / omni wheels).
struct DriveNodeSettings {
  int node_id = 0;
  double x_m = 0.0, y_m = 0.0;  ///< Wheel contact in the body frame (x forward, y left).
  bool has_rollers = false;     ///< Mecanum / omni: rollers at roller_angle to the axle.
  double roller_angle_rad = 0.0;
  int sign = 1;              ///< -1: the drive turns the wheel backwards for a positive set point.
  double heading_rad = 0.0;  ///< Rolling direction from the body x axis, CCW.
};

/// The drives the firmware masters (CiA 402, bus/dbc/cia402_drive.dbc) and how their set
/// points are made from a body velocity.
struct DriveSettings {
  bool enabled = false;
  bool velocity_rpm = true;   ///< Velocity unit of 0x60FF / 0x606C: rpm (true) or increments/s.
  double gear_ratio = 1.0;    ///< Motor turns per wheel turn.
  double counts_per_rev = 0;  ///< Motor encoder increments per motor turn (increments/s only).
  double wheel_radius_m = 0.0;
  double max_wheel_speed_rad_s = 0.0;  ///< Set points scaled down together above it; 0 = none.
  int mode = 9;                        ///< 0x6060 written at start-up: 9 csv or 3 pv.
  int abort_connection_option = 1;     ///< 0x6007 written at start-up (1: fault).
  /// 0x605A written at start-up: 6 = quick stop ramp, then hold zero with torque on (a robot
  /// that stops on a slope or with momentum stays put); 2 = ramp, then the wheel coasts.
  int quick_stop_option = 6;
  int master_node_id = 127;         ///< The firmware's own heartbeat id (0x700 + id).
  double master_heartbeat_s = 0.1;  ///< Heartbeat period (sent with the cycles); 0 = none.
  /// Tracking supervision: a drive whose velocity actual stays further than this from the set
  /// point it was sent (wheel side) for tracking_error_time_s stops the robot; 0 = off.
  double tracking_error_rad_s = 1.0;
  double tracking_error_time_s = 0.5;
  /// Written to each drive's 0x1016:1 (consumer time); 0 = 3x the effective heartbeat period.
  double drive_heartbeat_timeout_s = 0.0;
  std::vector<DriveNodeSettings> nodes;
};

/// One waypoint; heading only when has_theta (else the heading is held).
struct Waypoint {
  double x_m = 0.0, y_m = 0.0;
  bool has_theta = false;
  double theta_rad = 0.0;  ///< Absolute, not wrapped: -2 pi from 0 is a full turn clockwise.
};

enum class SteerFrom { kCorrected, kRaw };

/// The path the firmware follows from its own estimate (start at the origin, heading 0).
struct PathSettings {
  bool enabled = false;
  std::vector<Waypoint> waypoints;
  double speed_m_s = 0.25;
  double accel_m_s2 = 0.5;
  double lookahead_m = 0.3;
  double tolerance_m = 0.01;
  double heading_tolerance_rad = 0.01;
  double yaw_rate_rad_s = 0.5;                   ///< Largest commanded yaw rate.
  double heading_gain_1_s = 2.0;                 ///< Heading error to yaw rate.
  double start_delay_s = 0.0;                    ///< Standstill after the drives are enabled.
  SteerFrom steer_from = SteerFrom::kCorrected;  ///< paper000: corrected or raw odometry.
};

struct FwConfig {
  std::string source_path;  ///< The file it was read from, for messages.
  EstimatorKind estimator = EstimatorKind::kPaper000SlipCorrection;
  /// Directory with the protocol's DBC files; empty = the default search (docs/firmware.md).
  /// A relative path in the file is taken relative to the config file's directory.
  std::string dbc_dir;
  CanopenSettings canopen;
  SyncSettings sync;
  ImuSettings imu;
  AccelSettings accel;
  Paper000Settings paper000;
  Paper001Settings paper001;
  Paper002Settings paper002;
  DriveSettings drives;
  PathSettings path;

  /// The encoder nodes of the selected estimator, in the estimator's order.
  std::vector<EncoderNode> encoder_nodes() const;
};

/// Reads and validates a firmware config file.
FwConfig LoadFwConfig(const std::string& path);
/// Parses config text; `source_name` prefixes messages and anchors a relative dbc_dir.
FwConfig ParseFwConfig(const std::string& text, const std::string& source_name);

/// The YAML spelling of an estimator kind (`paper000`, `paper001`, `paper002`).
const char* EstimatorName(EstimatorKind kind) noexcept;

}  // namespace wheelhil::fw
