#pragma once
/// A scenario file (scenarios/*.yaml, every field in docs/scenarios.md): which platform drives
/// over which floor along which motion, with which sensors, devices and injected faults, which
/// firmware runs in the loop, how time advances and which metric thresholds decide the verdict.
/// SI units with the unit in each key (`speed_m_s`, `duration_s`); relative paths are taken
/// relative to the scenario file's directory. Loading validates everything and throws
/// std::invalid_argument reading "file:line:column: field: problem" (unknown keys included, so
/// typos are caught). Value types; thread-compatible.

#include <cstddef>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "emulator/devices/canopen_encoder_node.h"
#include "emulator/devices/cia402_drive_device.h"
#include "emulator/devices/dbc_device.h"
#include "emulator/devices/dbc_imu_node.h"
#include "emulator/faults/bus_faults.h"
#include "emulator/faults/device_faults.h"
#include "emulator/faults/frame_faults.h"
#include "emulator/faults/sensor_faults.h"
#include "emulator/physics/terrain.h"
#include "emulator/platforms/platform.h"
#include "emulator/scoring/expectations.h"
#include "emulator/scoring/output_binding.h"

namespace wheelhil::emulator::scenario {

/// The most entries each list of a scenario may have. Far above any real scenario; they keep a
/// generated or corrupted file from running for minutes before it fails.
struct ScenarioLimits {
  static constexpr std::size_t kMeshes = 64;
  static constexpr std::size_t kPatches = 10'000;
  static constexpr std::size_t kPolygonPoints = 1'000;
  static constexpr std::size_t kRandomPatchTracks = 64;
  static constexpr std::size_t kMotionSegments = 100'000;
  static constexpr std::size_t kWaypoints = 100'000;
  static constexpr std::size_t kExpectations = 10'000;
};

/// One piece of the commanded motion, in the body frame B (x forward, y left, z up).
struct MotionSegment {
  enum class Kind {
    kTwist,      ///< Constant body twist for duration_s.
    kTrapezoid,  ///< Travel `distance` along `direction` with a trapezoidal speed profile.
    kHold,       ///< Standstill for duration_s.
    kWheels,     ///< Direct driven-wheel speeds (rad/s, platform wheel order) for duration_s.
  };
  Kind kind = Kind::kHold;
  double duration_s = 0;
  platforms::BodyTwist twist;  ///< kTwist.
  /// kTrapezoid: unit direction in (vx, vy, wz) space; distance in m (or rad for pure turns),
  /// cruise speed (m/s or rad/s) and acceleration = deceleration (m/s^2 or rad/s^2).
  Eigen::Vector3d direction = Eigen::Vector3d::UnitX();
  double distance = 0;
  double speed = 0;
  double accel = 0;
  std::vector<double> wheel_speeds_rad_s;  ///< kWheels.
};

/// `motion: {source: firmware}`: no script. The wheels' drives (devices of kind canopen_cia402)
/// power them with what the firmware commands; the trajectory is what the firmware makes of it.
struct FirmwareMotionSpec {
  /// Where the firmware's path ends (x_m, y_m, theta_rad in the start frame: x forward, y left
  /// at the motion start), scored by the closed_loop metrics; unset: not scored against a goal.
  std::optional<Eigen::Vector3d> goal;
  bool goal_has_heading = false;
};

/// A low-friction spot on the floor (terrain patch).
struct PatchSpec {
  std::string name;
  std::vector<Eigen::Vector2d> polygon_m;
  Friction friction;
};

/// Randomly placed (seeded) small low-friction spots under the drive wheels' tracks along a
/// straight run: the paper-000 floor where the wheels "slip now and then".
struct RandomPatchesSpec {
  int count = 0;
  double x_min_m = 0, x_max_m = 0;  ///< Along the world x axis.
  double length_min_m = 0.05, length_max_m = 0.2;
  double width_m = 0.1;           ///< Across, centred on a wheel track.
  std::vector<double> track_y_m;  ///< Wheel track lines (world y) to choose from.
  Friction friction{0.05, 0.03};
  /// Uniform: each start x uniform in [x_min, x_max] (patches may overlap). Stratified: the
  /// range cut into `count` equal sections, one patch placed uniformly inside each so that it
  /// ends within its section (no overlaps; needs length_max <= the section length).
  enum class Placement { kUniform, kStratified } placement = Placement::kUniform;
};

struct TerrainSpec {
  Friction friction;                ///< The floor plane.
  std::vector<std::string> meshes;  ///< Optional mesh floors (absolute paths after loading).
  std::vector<PatchSpec> patches;
  RandomPatchesSpec random_patches;
};

/// Wheel encoders (one CiA 406 node per encoder wheel).
struct EncoderDeviceSpec {
  std::string wheel;
  int node_id = 1;
  int direction = 1;
};

/// A user's IMU described by its own DBC file (sensors.dbc_imu; emulator/devices/dbc_imu_device.h).
struct DbcImuSpec {
  std::string dbc;  ///< The DBC file (absolute after loading).
  Eigen::Vector3d mount_m = Eigen::Vector3d::Zero();  ///< Mounting point in the body frame B.
  DbcImuConfig node;  ///< Which signal carries which quantity; counters and checksums.
  double gyro_noise_density_rad_s_sqrt_hz = 0;
  double gyro_bias_rad_s = 0;
  double gyro_bias_random_walk_rad_s_sqrt_s = 0;
  double accel_noise_density_m_s2_sqrt_hz = 0;
  double accel_bias_m_s2 = 0;
};

struct SensorsSpec {
  int encoder_lines_per_rev = 500;
  bool encoder_quadrature_x4 = true;
  double encoder_missed_count_prob = 0;
  double encoder_glitch_prob = 0;
  /// Peak angle error of each encoder's off-centre disc (its phase drawn per encoder), rad.
  double encoder_eccentricity_rad = 0;
  std::vector<EncoderDeviceSpec> encoders;
  bool gyro = false;  ///< Bosch MM5.10 yaw-rate node present.
  double gyro_rate_hz = 100;
  double gyro_noise_density_rad_s_sqrt_hz = 0;
  double gyro_bias_rad_s = 0;
  double gyro_bias_random_walk_rad_s_sqrt_s = 0;
  std::uint32_t bitrate_bps = 1'000'000;
  int heartbeat_ms = 100;
  /// Paper 002's four single-axis accelerometers (one node, ACC4_Data 0x170) present.
  bool accel4 = false;
  double accel4_rate_hz = 1000;
  double accel4_radius_m = 0.15;  ///< R of paper 002 eq 3 (platform accelerometer_radius_m).
  double accel4_noise_density_m_s2_sqrt_hz = 0;
  std::vector<double> accel4_bias_m_s2;    ///< 4 values (calibration error), empty: none.
  std::vector<double> accel4_scale_error;  ///< 4 values, empty: none.
  std::optional<DbcImuSpec> dbc_imu;
};

/// One entry of `devices:` (docs/scenarios.md, docs/own-hardware.md): a device on the bus, after
/// the `sensors:` ones in bus order.
struct DeviceSpec {
  enum class Kind {
    kDbc,            ///< Every cyclic message of a node of the user's DBC (DbcDevice).
    kCanopenCia406,  ///< A CiA 406 encoder node on a wheel (as sensors.encoders' nodes).
    kMm5_10,         ///< A kDbc device over the shipped bus/dbc/bosch_mm5_10.dbc, all 6 axes.
    kCanopenCia402,  ///< A CiA 402 servo drive powering a driven wheel (Cia402DriveDevice).
  };
  Kind kind = Kind::kDbc;
  std::string where;  ///< file:line:column of the entry.
  std::string dbc;    ///< kDbc: the DBC file (absolute); kMm5_10: "${DBC_DIR}/bosch_mm5_10.dbc".
  DbcDeviceConfig dbc_device;  ///< kDbc; the seed and the start are the run's.
  EncoderDeviceSpec encoder;   ///< kCanopenCia406.
  int lines_per_rev = 500;
  bool quadrature_x4 = true;
  std::string eds;  ///< kCanopenCia406/402: the vendor's EDS/DCF (absolute), or empty.
  Cia406NodeConfig eds_node;   ///< Its dictionary from the EDS and the entry's `objects`.
  Cia402DriveDeviceConfig drive;  ///< kCanopenCia402, with its EDS and `objects` applied.
};

/// A fault injected over a window [start_s, end_s) of motion time (end_s infinite: to the end).
/// The library kinds (frame/bus/sensor/device, emulator/faults/) carry the library's own spec;
/// its window is set by the runner at the motion start. Physical kinds act on the vehicle or
/// the floor. See docs/scenarios.md, `faults`.
struct FaultSpec {
  enum class Kind {
    kEncoderEmcy,        ///< node_id raises EMCY error_code at start, clears it at end.
    kEncoderSilent,      ///< node_id's frames dropped.
    kFrame,              ///< FrameFaultFilter on the emulated devices' frames (`frame`).
    kBus,                ///< FaultyCanBus around the bus model (`bus`).
    kSensor,             ///< SensorFaultInjector on one sensor's samples (`sensor`).
    kDevice,             ///< DeviceFaultInjector on one node (`device`).
    kWheelFriction,      ///< Per-wheel friction scale / override (RollerVehicle::SetWheelFriction).
    kTorqueDisturbance,  ///< Per-wheel external spin torque (SetWheelDisturbanceTorque).
    kBump,               ///< A ramped obstacle on the floor (terrain triangles), whole run.
    kDrive,              ///< A drive's fault (over-current, stuck, torque limit): `drive`.
  };
  Kind kind = Kind::kEncoderEmcy;
  std::string where;  ///< file:line:column of the entry, for messages.
  int node_id = 0;    ///< Encoder node (emcy/silent/device/bus_off on an encoder).
  std::string node;   ///< device/bus_off: "gyro" or "accel4" when not an encoder node.
  double start_s = 0;
  double end_s = std::numeric_limits<double>::infinity();
  std::uint16_t error_code = 0x7305;

  FrameFault frame;    ///< kFrame (window set by the runner).
  BusFault bus;        ///< kBus (window and bus node set by the runner).
  SensorFault sensor;  ///< kSensor (window set by the runner).
  DeviceFault device;  ///< kDevice (window set by the runner).
  DriveFault drive;    ///< kDrive (window set by the runner); the drive's name is `node`.
  /// kSensor: "gyro" (yaw rate, rad/s), "encoder" (counts, the node of `wheel`), "accel4"
  /// (m/s^2; channel 1..4, 0 = all four).
  std::string sensor_name;
  int channel = 0;

  /// kWheelFriction / kTorqueDisturbance / kSensor encoder: platform wheel name and index.
  std::string wheel;
  std::size_t wheel_index = 0;
  double mu_scale = 1.0;                ///< kWheelFriction: multiplies mu_peak and mu_slide.
  std::optional<Friction> mu_override;  ///< kWheelFriction: replaces the floor's friction.
  double torque_nm = 0;                 ///< kTorqueDisturbance.

  /// kBump: a trapezoidal ridge across world x (the vehicle starts at the origin heading +x):
  /// up-ramp from x_m to x_m + ramp_length_m, flat top of top_length_m at height_m, down-ramp of
  /// ramp_length_m; width_m across, centred on y_m.
  double x_m = 0, y_m = 0, width_m = 2.0, height_m = 0.01, ramp_length_m = 0.04,
         top_length_m = 0.05;
  std::optional<Friction> bump_friction;  ///< Default: the floor's (terrain.friction).
};

struct FirmwareSpec {
  /// Command line; `${CAN}`, `${CONFIG}` and `${BIN}` (directory of the wheelhil executable)
  /// are substituted. Empty: none started (attach an external firmware to the bus).
  std::string command;
  std::string config;          ///< Firmware config file (absolute after loading); may be empty.
  std::string overrides_yaml;  ///< YAML map merged into the config (as text), may be empty.
  /// Where its estimates are in its frames (emulator/scoring/output_binding.h); none: nothing
  /// of the firmware is scored.
  std::optional<scoring::OutputsSpec> outputs;
};

/// What a scenario or command line that names the cooperative clock is told.
inline constexpr char kCooperativeClockRetired[] =
    "the cooperative FW_Status handshake was retired: lockstep runs any firmware on its own "
    "virtual clock (timing.clock: virtual, the default; docs/virtual-time.md); the reference "
    "firmware still sends FW_Status, which nothing waits for";

struct TimingSpec {
  bool lockstep = true;
  double duration_s = 10;  ///< Virtual time of the motion phase.
  double physics_rate_hz = 1000;
  double sync_period_s = 0.01;  ///< The SYNC / firmware cycle period.
  double timeout_s = 5;         ///< Wall-clock wait for the firmware's answer to a cycle.
  /// The firmware is the SYNC producer (the CANopen master's role, the default); else the
  /// emulator is (an emulated master: the firmware's own config must then not produce SYNC).
  bool firmware_produces_sync = true;
  bool sync_producer_named = false;
  /// Virtual clock: what each call that does not block (a clock read, a zero-timeout poll)
  /// costs a thread after its first 64 since its last wait, s; 0: nothing, and a thread that
  /// never blocks ends the run (docs/virtual-time.md, "Busy loops").
  double spin_cost_s = 0;
};

using Expectation = scoring::Expectation;

struct Scenario {
  std::string source_path;
  std::string name;
  std::string description;
  std::uint64_t seed = 1;
  platforms::Platform platform;
  /// `platform.tolerances: sample` (the default): each run draws the platform file's
  /// tolerances from the run's seed; `nominal`: the robot is built exactly to the file.
  bool sample_tolerances = true;
  TerrainSpec terrain;
  std::vector<MotionSegment> motion;  ///< Empty with firmware_motion.
  std::optional<FirmwareMotionSpec> firmware_motion;
  SensorsSpec sensors;
  std::vector<DeviceSpec> devices;
  std::vector<FaultSpec> faults;
  FirmwareSpec firmware;
  TimingSpec timing;
  std::vector<Expectation> expectations;
  /// The metric components that score the run (scoring.metrics; emulator/scoring/
  /// metric_components.h); empty: all of them.
  std::vector<std::string> metric_components;
  /// `logs:` the formats the bus log is also written in beside can.log ("asc" -> can.asc,
  /// "blf" -> can.blf; bus/vector_logs.h), and "mcap": the whole run as run.mcap
  /// (emulator/scoring/run_mcap.h); empty: can.log only.
  std::vector<std::string> log_formats;
  /// Ground-truth slip for scoring: a drive wheel slips while its contact slip speed exceeds
  /// this (m/s); unset: the platform's solver.slip_threshold_m_s flag.
  std::optional<double> slip_threshold_m_s;
};

/// Reads and validates a scenario file.
Scenario LoadScenarioFile(const std::string& path);
/// Parses scenario text; `file` names it in messages and anchors relative paths.
Scenario ParseScenario(const std::string& text, const std::string& file);

/// Commanded body twist at time t_s into the motion (zero after the last segment).
platforms::BodyTwist TwistAt(const std::vector<MotionSegment>& motion, double t_s);
/// Total duration of the motion segments (trapezoids: their profile's duration).
double MotionDuration(const std::vector<MotionSegment>& motion);
/// Duration of a trapezoidal profile over `distance` with cruise `speed` and `accel`
/// (triangular when the distance is too short to reach the cruise speed).
double TrapezoidDuration(double distance, double speed, double accel);
/// Speed along the profile at time t (0 outside [0, duration]).
double TrapezoidSpeed(double distance, double speed, double accel, double t_s);

}  // namespace wheelhil::emulator::scenario
