#include "emulator/scenario/runner.h"

#include <fcntl.h>
#include <sched.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <numbers>
#include <random>
#include <set>
#include <sstream>
#include <stdexcept>
#include <thread>

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include "bus/candump_log.h"
#include "bus/dbc.h"
#include "bus/dbc_codec.h"
#include "bus/socketcan_transport.h"
#include "bus/ucan_broker.h"
#include "bus/ucan_runtime_dir.h"
#include "emulator/devices/accel4_node.h"
#include "emulator/devices/can_bus_model.h"
#include "emulator/devices/canopen_encoder_node.h"
#include "emulator/devices/dbc_cia406_codec.h"
#include "emulator/devices/mm5_imu_node.h"
#include "emulator/faults/bus_faults.h"
#include "emulator/faults/device_faults.h"
#include "emulator/faults/fault_event.h"
#include "emulator/faults/frame_faults.h"
#include "emulator/faults/sensor_faults.h"
#include "emulator/physics/physics_world.h"
#include "emulator/scenario/artefacts.h"
#include "emulator/scenario/background_candump.h"
#include "emulator/scenario/metrics.h"
#include "emulator/scenario/step_pipeline.h"
#include "emulator/sensors/encoder_model.h"

namespace wheelhil::emulator::scenario {

namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using Clock = std::chrono::steady_clock;

constexpr std::uint32_t kSyncId = 0x080;
constexpr std::uint32_t kFwStatusId = 0x686;

double WallSeconds(Clock::time_point since) {
  return std::chrono::duration<double>(Clock::now() - since).count();
}

// Deep-merges `over` into `base` (maps recursively, everything else replaced).
void Merge(YAML::Node base, const YAML::Node& over) {
  for (const auto& kv : over) {
    const std::string key = kv.first.as<std::string>();
    if (kv.second.IsMap() && base[key] && base[key].IsMap()) {
      Merge(base[key], kv.second);
    } else {
      base[key] = kv.second;
    }
  }
}

// The firmware child process.
class Firmware {
 public:
  ~Firmware() { Stop(); }

  void Start(const std::string& command,
             const std::vector<std::pair<std::string, std::string>>& env,
             const std::string& log_path) {
    const int log_fd = ::open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    pid_ = ::fork();
    if (pid_ < 0) throw std::runtime_error("fork failed");
    if (pid_ == 0) {
      ::setpgid(0, 0);
      for (const auto& [k, v] : env) ::setenv(k.c_str(), v.c_str(), 1);
      if (log_fd >= 0) {
        ::dup2(log_fd, 1);
        ::dup2(log_fd, 2);
      }
      const std::string sh = "exec " + command;
      ::execl("/bin/sh", "sh", "-c", sh.c_str(), static_cast<char*>(nullptr));
      ::_exit(127);
    }
    if (log_fd >= 0) ::close(log_fd);
  }

  /// Exit status if it has exited.
  std::optional<int> Exited() {
    if (pid_ <= 0) return std::nullopt;
    int status = 0;
    if (::waitpid(pid_, &status, WNOHANG) == pid_) {
      pid_ = -1;
      exit_status_ = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
      return exit_status_;
    }
    return std::nullopt;
  }

  void Stop() {
    if (pid_ <= 0) return;
    ::kill(pid_, SIGTERM);
    for (int i = 0; i < 200; ++i) {
      if (Exited()) return;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    ::kill(pid_, SIGKILL);
    int status = 0;
    ::waitpid(pid_, &status, 0);
    pid_ = -1;
  }

  bool running() const { return pid_ > 0; }

 private:
  pid_t pid_ = -1;
  int exit_status_ = 0;
};

// CAN receivers the kernel has registered on `iface` (one per filter of every bound CAN socket),
// from /proc/net/can/rcvlist_*; -1 when none of those lists can be read.
int CountKernelCanReceivers(const std::string& iface) {
  int count = -1;
  for (const char* list : {"all", "fil", "inv", "sff", "eff", "err"}) {
    std::ifstream in(std::string("/proc/net/can/rcvlist_") + list);
    if (!in) continue;
    count = std::max(count, 0);
    std::string line, first;
    while (std::getline(in, line)) {
      std::istringstream words(line);
      if (words >> first && first == iface) ++count;
    }
  }
  return count;
}

std::string Substitute(std::string s, const std::string& key, const std::string& value) {
  for (std::size_t pos = s.find(key); pos != std::string::npos; pos = s.find(key, pos)) {
    s.replace(pos, key.size(), value);
    pos += value.size();
  }
  return s;
}

struct Decoded {
  const bus::DbcMessage* msg = nullptr;
  bus::SignalValues values;
};

// Everything one run holds.
class Run {
 public:
  Run(const Scenario& s, const RunOptions& o) : s_(s), o_(o) {}
  ~Run() { ReleaseCpu(); }

  RunResult Execute();

 private:
  void BuildWorld();
  void BuildDevices();
  void OpenBus(bool lockstep);
  // Lockstep: this thread (and so the broker and the firmware, created later) on one CPU at
  // SCHED_BATCH (RunOptions::cpu). Throws std::invalid_argument for a CPU not allowed here.
  void ConfineToOneCpu();
  // Gives the caller's thread back its CPU set and policy (a library call leaves no trace).
  void ReleaseCpu();
  bool WaitForFirmwareConnection(std::string& why);
  // One physics step plus the devices and the bus up to the end of the step.
  void Step(bool motion);
  // Moves the bus model to t_ns, in small slices while frames are in flight so answers to
  // frames that complete inside the step are queued at their own instants.
  void AdvanceBus(std::int64_t t_ns);
  void OnWire(const WireFrame& w);
  void EnqueueNodeFrames(int bus_node, std::size_t encoder, std::vector<NodeFrame> frames);
  // Device output -> device faults -> frame faults -> (bus-off) -> bus model.
  void SubmitDeviceFrames(int bus_node, std::vector<NodeFrame> frames, bool from_poll);
  bool EnqueueOnBus(int bus_node, const bus::CanFrame& f, std::int64_t ready_ns);
  // Builds the fault injectors at the motion start (windows are relative to it).
  void ArmFaults();
  // Physical faults (wheel friction, torque disturbance) for the step starting at tm_s; their
  // start/end events go to `events`.
  void ApplyPhysicalFaults(double tm_s, std::vector<json>& events);
  // The physics of the step starting at t_ns: the command, the physical faults (motion only)
  // and the world step. Touches the world, the vehicle and the fault scratch only, so during
  // the motion phase it may run on the pipeline's worker.
  void PhysicsStep(std::int64_t t_ns, bool motion, std::vector<json>& events);
  // The pipeline's worker for the motion phase, or none (RunOptions::physics_thread).
  void StartPhysicsPipeline(std::int64_t steps);
  void AddBumps(Terrain& terrain);
  void AppendFaultEvents();
  // Reads frames from the firmware until `done` or the wall-clock timeout; false on timeout.
  bool WaitFirmware(const std::function<bool()>& done, double timeout_s);
  // Realtime only (the transport is open there; lockstep waits with WaitFirmware).
  void DrainFirmware(int timeout_ms);
  // One pass of the pumped broker (see pumped_).
  void PumpBroker(int timeout_ms);
  void OnFirmwareFrame(const bus::CanFrame& f);
  // What OnFirmwareFrame reads from one firmware message, worked out at its first frame: the
  // signals of each field (DecodeMessage's first present one of that name wins) instead of a
  // decoded map and formatted names per frame.
  struct FwFramePlan {
    enum class Kind { kStatus, kPose, kVelocity, kSlip, kIgnored };
    Kind kind = Kind::kIgnored;
    std::string stream;  // estimate stream name (pose / velocity kinds)
    // kStatus: cycle, state. Estimates: cycle, then the kind's values in order.
    std::vector<std::vector<const bus::DbcSignal*>> fields;
    std::vector<PoseSample>* pose = nullptr;     // pose_streams_[stream], once it exists
    std::vector<VelocitySample>* vel = nullptr;  // vel_streams_[stream], once it exists
  };
  FwFramePlan& FwPlanFor(const bus::DbcMessage& msg);
  void RecordTruth(bool force);
  void Progress(bool final);
  json BuildReport(double wall_s);
  void WriteArtefacts(const json& report);

  const Scenario& s_;
  const RunOptions& o_;
  std::uint64_t seed_ = 1;
  std::string out_;
  std::string iface_;
  std::string runtime_dir_;
  std::unique_ptr<bus::UcanBroker> broker_;
  // Lockstep on the private bus: the run's own thread routes the bus (UcanBroker::Pump) when it
  // waits for the firmware, so a cycle costs two context switches (to the firmware and back)
  // instead of one per hop through a broker thread.
  bool pumped_ = false;
  int cpu_ = -1;  // ConfineToOneCpu(): the CPU, -1 none
  cpu_set_t saved_cpus_{};
  int saved_policy_ = -1;
  sched_param saved_param_{};
  static constexpr int kMaxUnpumpedFrames = 32;
  int unpumped_frames_ = 0;
  int local_port_ = -1;  // the emulator's port on the pumped bus
  Clock::time_point last_exit_check_{};
  std::optional<bus::SocketCanTransport> can_;
  Firmware firmware_;
  std::unique_ptr<bus::CandumpWriter> log_;
  // can.log through a thread of its own on the physics worker's CPUs while the worker runs
  // (declared after log_: stopped, its queue written, before log_ goes).
  std::unique_ptr<BackgroundCandump> background_log_;

  std::unique_ptr<physics::PhysicsWorld> world_;
  physics::RollerVehicle* vehicle_ = nullptr;
  // What the run reads from the vehicle after a motion step when a worker steps the physics.
  struct MotionStepState {
    physics::BodyTruth body;
    std::vector<physics::WheelTruth> wheels;
    std::vector<json> events;  // physical fault events of the step
    // The accel4 sensor readings (Accel4Node::SampleSensors) of the sample instants that fall
    // due with this step, in order: they depend on the body kinematics and the sensors' own
    // noise streams only, so the worker takes them off the run's thread.
    std::vector<std::array<double, 4>> accel;
  };
  /// The run's body kinematics as the accelerometers see them (body frame).
  static BodyKinematics AccelKinematics(const physics::BodyTruth& b);
  std::int64_t worker_accel_next_ns_ = 0;  // the worker's next accel4 sample instant
  MotionStepState start_state_;  // the vehicle at the motion start, when a worker steps it
  std::unique_ptr<StepPipeline<MotionStepState>> pipeline_;
  bool physics_thread_used_ = false;
  // The vehicle's state after the latest step: the vehicle's own, or a pipeline slot.
  const physics::BodyTruth* body_ = nullptr;
  const std::vector<physics::WheelTruth>* wheels_ = nullptr;
  const std::vector<std::array<double, 4>>* accel_samples_ = nullptr;  // the slot's, with a worker
  std::int64_t step_ns_ = 1'000'000;
  std::int64_t t_ns_ = 0;

  std::shared_ptr<const DbcCia406Codec> cia406_;
  std::shared_ptr<const bus::DbcDatabase> mm5_;
  std::shared_ptr<const bus::DbcDatabase> fwdbc_;
  std::unique_ptr<CanBusModel> bus_;
  int bus_emulator_ = 0, bus_firmware_ = 0, bus_imu_ = -1;
  struct Encoder {
    EncoderDeviceSpec spec;
    std::size_t wheel = 0;
    std::unique_ptr<EncoderModel> model;
    std::unique_ptr<CanopenEncoderNode> node;
    int bus_node = 0;
    bool silent = false;
    Cia406NodeConfig config;
    std::unique_ptr<SensorFaultInjector> sensor_fault;
    std::unique_ptr<DeviceFaultInjector> device_fault;
    CanopenEncoderNode::NmtState last_state = CanopenEncoderNode::NmtState::kOff;
  };
  std::vector<Encoder> encoders_;
  std::unique_ptr<Mm5ImuNode> imu_;
  std::unique_ptr<Accel4Node> accel4_;
  int bus_accel4_ = -1;

  // Faults (emulator/faults), armed at the motion start.
  FaultEventLog fault_log_;
  std::shared_ptr<const bus::DbcDatabase> accel4_dbc_;
  std::map<int, std::unique_ptr<FrameFaultFilter>> frame_filters_;   // by bus node
  std::map<int, std::unique_ptr<DeviceFaultInjector>> node_faults_;  // gyro/accel4 by bus node
  std::unique_ptr<FaultyCanBus> faulty_bus_;
  std::unique_ptr<SensorFaultInjector> gyro_fault_;
  std::array<std::unique_ptr<SensorFaultInjector>, 4> accel_fault_;
  std::vector<char> physical_on_;     // per scenario fault: physical fault active
  bool has_physical_faults_ = false;  // a wheel_friction or torque_disturbance fault exists
  std::vector<double> phys_scale_, phys_torque_;  // ApplyPhysicalFaults' per-wheel scratch
  std::vector<std::optional<Friction>> phys_over_;
  std::vector<char> phys_touched_;
  bool library_faults_ = false;
  std::int64_t motion0_ns_ = 0;
  std::uint64_t enqueued_ = 0, completed_ = 0, silenced_ = 0, enqueue_failures_ = 0;
  std::vector<WireFrame> wire_scratch_;  ///< AdvanceBus: the frames of one slice.
  std::vector<std::size_t> drive_wheels_;

  // Lockstep bookkeeping.
  std::uint64_t syncs_sent_ = 0;
  std::map<int, double> sync_time_by_cycle_;  // cycle mod 256 -> virtual time of that SYNC.
  int last_status_cycle_ = -1;
  std::uint64_t status_frames_ = 0;
  std::set<int> awaiting_nodes_;  // Nodes whose boot-up/SDO answer the firmware must react to.
  int kernel_receivers_before_fw_ = -1;  // Kernel bus: CountKernelCanReceivers before the firmware.
  int last_fw_state_ = -1;
  std::uint64_t fw_frames_ = 0;
  // Which encoders' TPDO1 (their COB-ID and DBC length, as the firmware accepts it) went out
  // since the last SYNC: a cycle is complete on the bus when all of them did.
  std::uint32_t tpdos_since_sync_ = 0;
  std::uint32_t all_tpdos_ = 0;
  std::vector<std::uint8_t> tpdo_len_;  // By encoder; 0: no TPDO1 in the DBC.
  // Lockstep: the cycle whose FW_Status is awaited after the next SYNC (-1: none).
  int pending_status_cycle_ = -1;
  std::uint64_t syncs_on_wire_ = 0;  // SYNCs the emulator sent that completed on the bus.
  // The latest SYNC is on the wire (a flood or an error burst can hold it back) and every
  // encoder answered it.
  bool CycleCompleteOnBus() const {
    return syncs_on_wire_ == syncs_sent_ && tpdos_since_sync_ == all_tpdos_;
  }

  // Recorded data.
  double t_motion0_s_ = 0;
  Eigen::Vector3d p0_ = Eigen::Vector3d::Zero();
  double yaw0_ = 0;
  std::vector<TruthRow> truth_;
  std::vector<PoseSample> truth_pose_;
  std::vector<VelocitySample> truth_vel_;
  std::vector<double> slip_t_;
  std::vector<bool> slip_flag_;
  /// Per wheel (vehicle order), per motion step at slip_t_: the wheel is off the floor.
  std::vector<std::vector<bool>> airborne_;
  std::vector<EstimateRow> estimates_;
  std::map<std::string, std::vector<PoseSample>> pose_streams_;
  std::map<std::string, std::vector<VelocitySample>> vel_streams_;
  std::map<const bus::DbcMessage*, FwFramePlan> fw_plans_;
  std::vector<DetectionSample> detections_;
  std::vector<double> residual_t_, residual_, band_lo_, band_hi_;
  std::vector<json> events_;
  std::int64_t truth_every_ns_ = 10'000'000;
  bool in_motion_ = false;
  Clock::time_point wall0_;
  Clock::time_point last_progress_;
  std::string failure_;
};

void Run::BuildWorld() {
  physics::WorldOptions wo;
  wo.step_s = 1.0 / s_.timing.physics_rate_hz;
  step_ns_ = std::llround(1e9 / s_.timing.physics_rate_hz);
  world_ = std::make_unique<physics::PhysicsWorld>(wo);
  Terrain& terrain = world_->terrain();
  terrain.AddPlane(Eigen::Vector3d::UnitZ(), Eigen::Vector3d::Zero(), s_.terrain.friction);
  for (const auto& m : s_.terrain.meshes) {
    MeshOptions mo;
    mo.friction = s_.terrain.friction;
    terrain.AddMesh(m, mo);
  }
  for (const auto& p : s_.terrain.patches) {
    terrain.AddPatch(FrictionPatch{p.name, p.polygon_m, p.friction});
  }
  const auto& rp = s_.terrain.random_patches;
  if (rp.count > 0) {
    std::mt19937_64 rng(seed_ ^ 0x5157AB1Eull);
    std::uniform_real_distribution<double> ux(rp.x_min_m, rp.x_max_m);
    std::uniform_real_distribution<double> ul(rp.length_min_m, rp.length_max_m);
    std::uniform_int_distribution<std::size_t> ut(0, rp.track_y_m.size() - 1);
    const bool stratified = rp.placement == RandomPatchesSpec::Placement::kStratified;
    const double section = (rp.x_max_m - rp.x_min_m) / rp.count;
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    for (int i = 0; i < rp.count; ++i) {
      double x = 0;
      double len = 0;
      if (stratified) {
        len = ul(rng);
        x = rp.x_min_m + i * section + u01(rng) * (section - len);
      } else {
        x = ux(rng);
        len = ul(rng);
      }
      const double y = rp.track_y_m[ut(rng)];
      const double hw = rp.width_m / 2;
      FrictionPatch p{fmt::format("random{}", i),
                      {{x, y - hw}, {x + len, y - hw}, {x + len, y + hw}, {x, y + hw}},
                      rp.friction};
      terrain.AddPatch(p);
      events_.push_back(json{{"t_s", 0.0},
                             {"event", "patch"},
                             {"name", p.name},
                             {"x_m", x},
                             {"y_m", y},
                             {"length_m", len},
                             {"mu_peak", rp.friction.mu_peak}});
    }
  }
  AddBumps(terrain);
  vehicle_ = &world_->AddVehicle(s_.platform.vehicle, 0.0, 0.0, 0.0);
  body_ = &vehicle_->body_truth();
  wheels_ = &vehicle_->wheel_truth();
  drive_wheels_ = s_.platform.drive_wheels;
}

void Run::BuildDevices() {
  const std::string dir = o_.dbc_dir;
  cia406_ = DbcCia406Codec::FromFile(dir + "/cia406_encoder.dbc");
  mm5_ = std::make_shared<const bus::DbcDatabase>(
      bus::DbcDatabase::LoadFile(dir + "/bosch_mm5_10.dbc"));
  fwdbc_ = std::make_shared<const bus::DbcDatabase>(
      bus::DbcDatabase::LoadFile(dir + "/wheelhil_fw.dbc"));
  CanBusConfig bc;
  bc.bitrate_bps = s_.sensors.bitrate_bps;
  bus_ = std::make_unique<CanBusModel>(bc);
  bus_emulator_ = bus_->AddNode("emulator");
  bus_firmware_ = bus_->AddNode("firmware", CanBusModel::QueueOrder::kFifo, 4096);
  std::uint64_t k = 0;
  for (const auto& e : s_.sensors.encoders) {
    Encoder enc;
    enc.spec = e;
    enc.wheel = s_.platform.wheel_index(e.wheel);
    EncoderParams ep;
    ep.lines_per_rev = s_.sensors.encoder_lines_per_rev;
    ep.quadrature_x4 = s_.sensors.encoder_quadrature_x4;
    ep.direction = e.direction;
    ep.missed_count_prob = s_.sensors.encoder_missed_count_prob;
    ep.glitch_prob = s_.sensors.encoder_glitch_prob;
    ep.seed = seed_ * 1000003ull + (++k);
    // A disc is mounted at no particular angle: an edge right at the start angle would make a
    // wheel that only settles there flip a count back and forth. Drawn apart from ep.seed's
    // stream so that the encoder's own imperfections keep their draws.
    std::mt19937_64 phase_rng(ep.seed ^ 0xD15C0FFull);
    ep.disc_phase_counts = std::uniform_real_distribution<double>(0.0, 1.0)(phase_rng);
    enc.model = std::make_unique<EncoderModel>(ep);
    enc.model->Reset(vehicle_->wheel_truth()[enc.wheel].angle_rad, 0);
    Cia406NodeConfig nc;
    nc.node_id = static_cast<std::uint8_t>(e.node_id);
    nc.heartbeat_ms = static_cast<std::uint16_t>(s_.sensors.heartbeat_ms);
    enc.config = nc;
    enc.node = std::make_unique<CanopenEncoderNode>(nc, cia406_, 0);
    enc.bus_node = bus_->AddNode(fmt::format("encoder{}", e.node_id));
    encoders_.push_back(std::move(enc));
  }
  if (s_.sensors.gyro) {
    GyroParams gp;
    gp.rate_hz = s_.sensors.gyro_rate_hz;
    gp.noise_density_rad_s_sqrt_hz = s_.sensors.gyro_noise_density_rad_s_sqrt_hz;
    gp.bias_rad_s = s_.sensors.gyro_bias_rad_s;
    gp.bias_random_walk_rad_s_sqrt_s = s_.sensors.gyro_bias_random_walk_rad_s_sqrt_s;
    gp.seed = seed_ * 7919ull + 17;
    imu_ = std::make_unique<Mm5ImuNode>(mm5_, gp, std::llround(1e9 / gp.rate_hz));
    bus_imu_ = bus_->AddNode("imu");
  }
  if (s_.sensors.accel4) {
    auto params = Paper002AccelParams(s_.sensors.accel4_radius_m, s_.sensors.accel4_rate_hz,
                                      seed_ * 104729ull + 31);
    for (std::size_t i = 0; i < 4; ++i) {
      params[i].noise_density_m_s2_sqrt_hz = s_.sensors.accel4_noise_density_m_s2_sqrt_hz;
      if (!s_.sensors.accel4_bias_m_s2.empty()) {
        params[i].bias_m_s2 = {s_.sensors.accel4_bias_m_s2[i]};
      }
      if (!s_.sensors.accel4_scale_error.empty()) {
        params[i].scale_error = {s_.sensors.accel4_scale_error[i]};
      }
    }
    auto db = std::make_shared<const bus::DbcDatabase>(
        bus::DbcDatabase::LoadFile(dir + "/wheelhil_accel4.dbc"));
    accel4_dbc_ = db;
    accel4_ =
        std::make_unique<Accel4Node>(db, params, std::llround(1e9 / s_.sensors.accel4_rate_hz));
    bus_accel4_ = bus_->AddNode("accel4");
  }
}

void Run::OpenBus(bool lockstep) {
  bus::CanTransportOptions opt;
  opt.receive_own = false;
  if (o_.can_iface.empty()) {
    runtime_dir_ = bus::CreateTempUcanRuntimeDir("wheelhil-run-");
    bus::UcanBrokerOptions bo;
    bo.runtime_dir = runtime_dir_;
    bo.remove_runtime_dir = true;
    broker_ = std::make_unique<bus::UcanBroker>(bo);
    iface_ = "ucan0";
    broker_->AddBus(iface_);
    ::setenv("WHEELHIL_UCAN_DIR", runtime_dir_.c_str(), 1);
  } else {
    iface_ = o_.can_iface;
  }
  if (broker_ && lockstep) {
    broker_->UseCallerThread();
    local_port_ = broker_->OpenLocalPort(iface_);
    pumped_ = true;
  } else {
    can_.emplace(bus::SocketCanTransport::Open(iface_, opt));
  }
  log_ = std::make_unique<bus::CandumpWriter>(out_ + "/can.log",
                                              bus::CandumpWriter::FlushPolicy::kBuffered);
}

void Run::ConfineToOneCpu() {
  if (o_.cpu && *o_.cpu == -1) return;
  cpu_set_t allowed;
  CPU_ZERO(&allowed);
  if (::sched_getaffinity(0, sizeof(allowed), &allowed) != 0) return;
  const int cpu = o_.cpu ? *o_.cpu : ::sched_getcpu();
  if (cpu < 0 || cpu >= CPU_SETSIZE || !CPU_ISSET(cpu, &allowed)) {
    if (o_.cpu) {
      throw std::invalid_argument(fmt::format(
          "--cpu {}: not a CPU this process may run on (see `taskset -p $$`; -1: no pinning)",
          cpu));
    }
    return;
  }
  cpu_set_t one;
  CPU_ZERO(&one);
  CPU_SET(cpu, &one);
  saved_cpus_ = allowed;
  if (::sched_setaffinity(0, sizeof(one), &one) == 0) cpu_ = cpu;
  saved_policy_ = ::sched_getscheduler(0);
  (void)::sched_getparam(0, &saved_param_);
  // Refused only under a real-time policy; then the run keeps it.
  sched_param none{};
  if (saved_policy_ == SCHED_OTHER) (void)::sched_setscheduler(0, SCHED_BATCH, &none);
}

void Run::ReleaseCpu() {
  if (cpu_ >= 0) (void)::sched_setaffinity(0, sizeof(saved_cpus_), &saved_cpus_);
  if (saved_policy_ == SCHED_OTHER) (void)::sched_setscheduler(0, SCHED_OTHER, &saved_param_);
  cpu_ = -1;
  saved_policy_ = -1;
}

bool Run::WaitForFirmwareConnection(std::string& why) {
  if (!broker_) {
    // A kernel bus has no broker to see the other side, but the kernel's receive lists show a
    // socket bound to the interface: wait (up to the timeout) for one more receiver than before
    // the firmware started, else (lists unreadable) give it 300 ms. Frames sent before it binds
    // are lost to it (a boot-up in the user-mode-linux guest was). A firmware command that never
    // binds here (a real board's flasher, exit status 0) only costs the wait.
    if (kernel_receivers_before_fw_ < 0) {
      std::this_thread::sleep_for(std::chrono::milliseconds(300));
      return true;
    }
    const auto t0 = Clock::now();
    while (WallSeconds(t0) < s_.timing.timeout_s &&
           CountKernelCanReceivers(iface_) <= kernel_receivers_before_fw_) {
      if (auto code = firmware_.Exited(); code && *code != 0) {
        why = fmt::format("the firmware exited with status {} before opening {} (see firmware.log)",
                          *code, iface_);
        return false;
      } else if (code) {
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return true;
  }
  const auto t0 = Clock::now();
  while (WallSeconds(t0) < s_.timing.timeout_s) {
    for (const auto& st : broker_->Stats()) {
      if (st.name == iface_ && st.clients >= 2) return true;
    }
    if (auto code = firmware_.Exited()) {
      why = fmt::format("the firmware exited with status {} before opening {} (see firmware.log)",
                        *code, iface_);
      return false;
    }
    if (pumped_) {
      broker_->Pump(2);  // its connection and its requests need a broker pass
    } else {
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
  }
  why = fmt::format("the firmware did not open {} within {} s", iface_, s_.timing.timeout_s);
  return false;
}

void Run::EnqueueNodeFrames(int bus_node, std::size_t encoder, std::vector<NodeFrame> frames) {
  if (encoder < encoders_.size() && encoders_[encoder].silent) {
    silenced_ += frames.size();
    return;
  }
  SubmitDeviceFrames(bus_node, std::move(frames), false);
}

bool Run::EnqueueOnBus(int bus_node, const bus::CanFrame& f, std::int64_t ready_ns) {
  const std::uint64_t off0 = faulty_bus_ ? faulty_bus_->dropped_bus_off() : 0;
  const bool ok = faulty_bus_ ? faulty_bus_->Enqueue(bus_node, f, ready_ns)
                              : bus_->Enqueue(bus_node, f, ready_ns);
  if (ok) {
    ++enqueued_;
  } else if (!faulty_bus_ || faulty_bus_->dropped_bus_off() == off0) {
    // A bus-off discard is counted by FaultyCanBus (metrics.faults), not as a bus failure.
    ++enqueue_failures_;
  }
  return ok;
}

void Run::SubmitDeviceFrames(int bus_node, std::vector<NodeFrame> frames, bool from_poll) {
  // No frames and no frame filter (which may release delayed frames) for the node: nothing to do
  // (every node is called with its Poll/OnFrame output, most of the time empty).
  if (frames.empty() && !frame_filters_.contains(bus_node)) return;
  // Device faults of the node (encoders: the Encoder's injector; gyro/accel4: node_faults_).
  DeviceFaultInjector* dev = nullptr;
  for (auto& e : encoders_) {
    if (e.bus_node == bus_node) dev = e.device_fault.get();
  }
  if (const auto it = node_faults_.find(bus_node); it != node_faults_.end()) dev = it->second.get();
  if (dev != nullptr && !frames.empty()) dev->FilterOutputs(frames);
  if (const auto it = frame_filters_.find(bus_node); it != frame_filters_.end()) {
    std::int64_t until = bus_->now_ns();
    if (from_poll) until = std::max(until, t_ns_);
    for (const auto& f : frames) until = std::max(until, f.due_ns);
    frames = it->second->Process(frames, until);
  }
  for (const auto& nf : frames) {
    (void)EnqueueOnBus(bus_node, nf.frame, std::max(nf.due_ns, bus_->now_ns()));
  }
}

void Run::ArmFaults() {
  const std::int64_t t0 = t_ns_;  // motion start: the origin of every fault window
  motion0_ns_ = t0;
  auto shift = [&](FaultWindow w) {
    w.t0_ns += t0;
    if (w.t1_ns != FaultWindow::kForever) w.t1_ns += t0;
    return w;
  };
  auto bus_node_of = [&](const FaultSpec& f) {
    if (f.node == "gyro") return bus_imu_;
    if (f.node == "accel4") return bus_accel4_;
    for (const auto& e : encoders_) {
      if (e.spec.node_id == f.node_id) return e.bus_node;
    }
    return -1;
  };
  std::vector<FrameFault> frame;
  std::vector<BusFault> bus;
  std::map<int, std::vector<DeviceFault>> device;  // by bus node
  std::map<std::string, std::vector<SensorFault>> sensor;
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
          x.node = bus_node_of(f);
          x.node_name = f.node.empty() ? fmt::format("encoder{}", f.node_id) : f.node;
        }
        bus.push_back(std::move(x));
        break;
      }
      case FaultSpec::Kind::kDevice: {
        DeviceFault x = f.device;
        x.window = shift(x.window);
        device[bus_node_of(f)].push_back(x);
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
  // Seeds: one stream per injector, from the run seed.
  std::uint64_t k = 0;
  auto next_seed = [&] { return (seed_ ^ 0xFA017F00D5EEDull) * 6364136223846793005ull + (++k); };
  if (!frame.empty()) {
    // Every emulated device's output (not the SYNC producer, not the firmware's frames: those
    // reach the firmware outside the model).
    std::vector<int> nodes;
    for (const auto& e : encoders_) nodes.push_back(e.bus_node);
    if (bus_imu_ >= 0) nodes.push_back(bus_imu_);
    if (bus_accel4_ >= 0) nodes.push_back(bus_accel4_);
    std::shared_ptr<const bus::DbcDatabase> dbc = accel4_dbc_;
    if (!dbc) {
      dbc = std::make_shared<const bus::DbcDatabase>(
          bus::DbcDatabase::LoadFile(o_.dbc_dir + "/wheelhil_accel4.dbc"));
    }
    // Each filter sees every window pass (Process runs every step), so the first one alone
    // records the start/end events: one pair per fault, not one per device.
    FaultEventLog* log = &fault_log_;
    for (int n : nodes) {
      frame_filters_[n] = std::make_unique<FrameFaultFilter>(frame, dbc, next_seed(), log);
      log = nullptr;
    }
  }
  if (!bus.empty()) {
    faulty_bus_ = std::make_unique<FaultyCanBus>(*bus_, bus, StuffingMode::kExact, &fault_log_);
  }
  for (auto& [node, faults] : device) {
    bool is_encoder = false;
    for (auto& e : encoders_) {
      if (e.bus_node != node) continue;
      is_encoder = true;
      e.device_fault = std::make_unique<DeviceFaultInjector>(
          fmt::format("encoder{}", e.spec.node_id), static_cast<std::uint8_t>(e.spec.node_id),
          faults, &fault_log_);
    }
    if (!is_encoder) {
      node_faults_[node] = std::make_unique<DeviceFaultInjector>(
          node == bus_imu_ ? "gyro" : "accel4", 0x7F, faults, &fault_log_);
    }
  }
  for (auto& [name, faults] : sensor) {
    if (name == "gyro") {
      const double std =
          s_.sensors.gyro_noise_density_rad_s_sqrt_hz * std::sqrt(s_.sensors.gyro_rate_hz);
      gyro_fault_ =
          std::make_unique<SensorFaultInjector>(name, faults, std, next_seed(), &fault_log_);
    } else if (name.starts_with("accel4.")) {
      const int c = name.back() - '1';
      const double std =
          s_.sensors.accel4_noise_density_m_s2_sqrt_hz * std::sqrt(s_.sensors.accel4_rate_hz);
      accel_fault_[static_cast<std::size_t>(c)] =
          std::make_unique<SensorFaultInjector>(name, faults, std, next_seed(), &fault_log_);
    } else {
      const std::string wheel = name.substr(std::string("encoder.").size());
      for (auto& e : encoders_) {
        if (e.spec.wheel != wheel) continue;
        // The encoder's own noise is its quantisation: 1/sqrt(12) count.
        e.sensor_fault =
            std::make_unique<SensorFaultInjector>(fmt::format("encoder {}", wheel), faults,
                                                  1.0 / std::sqrt(12.0), next_seed(), &fault_log_);
      }
    }
  }
}

void Run::ApplyPhysicalFaults(double tm_s, std::vector<json>& events) {
  if (physical_on_.size() != s_.faults.size()) {
    physical_on_.assign(s_.faults.size(), 0);
    has_physical_faults_ = std::any_of(s_.faults.begin(), s_.faults.end(), [](const FaultSpec& f) {
      return f.kind == FaultSpec::Kind::kWheelFriction ||
             f.kind == FaultSpec::Kind::kTorqueDisturbance;
    });
  }
  // Called every step: nothing to do (and nothing to allocate) without a physical fault.
  if (!has_physical_faults_) return;
  const std::size_t nw = s_.platform.vehicle.wheels.size();
  // Per-wheel scratch, sized once (assign does not reallocate after the first step).
  auto& scale = phys_scale_;
  auto& torque = phys_torque_;
  auto& over = phys_over_;
  auto& touched = phys_touched_;
  scale.assign(nw, 1.0);
  torque.assign(nw, 0.0);
  over.assign(nw, std::nullopt);
  touched.assign(nw, 0);
  for (std::size_t i = 0; i < s_.faults.size(); ++i) {
    const FaultSpec& f = s_.faults[i];
    if (f.kind != FaultSpec::Kind::kWheelFriction &&
        f.kind != FaultSpec::Kind::kTorqueDisturbance) {
      continue;
    }
    touched[f.wheel_index] = 1;
    const bool on = tm_s >= f.start_s && tm_s < f.end_s;
    if (on) {
      if (f.kind == FaultSpec::Kind::kWheelFriction) {
        scale[f.wheel_index] *= f.mu_scale;
        if (f.mu_override) over[f.wheel_index] = f.mu_override;
      } else {
        torque[f.wheel_index] += f.torque_nm;
      }
    }
    if (static_cast<bool>(physical_on_[i]) == on) continue;
    physical_on_[i] = on;
    const bool friction = f.kind == FaultSpec::Kind::kWheelFriction;
    json ev{{"t_s", tm_s},
            {"event", on ? "fault_start" : "fault_end"},
            {"category", "physics"},
            {"fault", friction ? "wheel_friction" : "torque_disturbance"},
            {"wheel", f.wheel}};
    if (friction) {
      ev["mu_scale"] = f.mu_scale;
      if (f.mu_override) {
        ev["mu_peak"] = f.mu_override->mu_peak;
        ev["mu_slide"] = f.mu_override->mu_slide;
      }
    } else {
      ev["torque_nm"] = f.torque_nm;
    }
    events.push_back(ev);
  }
  for (std::size_t w = 0; w < nw; ++w) {
    if (!touched[w]) continue;
    (void)vehicle_->SetWheelFriction(w, scale[w], over[w]);
    (void)vehicle_->SetWheelDisturbanceTorque(w, torque[w]);
  }
}

void Run::AddBumps(Terrain& terrain) {
  int n = 0;
  for (const auto& f : s_.faults) {
    if (f.kind != FaultSpec::Kind::kBump) continue;
    // A ridge across x: foot, top start, top end, foot; two rows of vertices at y -/+ width/2.
    const double xs[4] = {f.x_m, f.x_m + f.ramp_length_m, f.x_m + f.ramp_length_m + f.top_length_m,
                          f.x_m + 2 * f.ramp_length_m + f.top_length_m};
    const double zs[4] = {0.0, f.height_m, f.height_m, 0.0};
    std::vector<Eigen::Vector3d> v;
    for (int side = 0; side < 2; ++side) {
      const double y = f.y_m + (side == 0 ? -0.5 : 0.5) * f.width_m;
      for (int j = 0; j < 4; ++j) v.emplace_back(xs[j], y, zs[j]);
    }
    std::vector<std::array<int, 3>> tris;
    for (int j = 0; j < 3; ++j) {
      if (j == 1 && f.top_length_m <= 0) continue;
      tris.push_back({j, j + 1, 4 + j + 1});
      tris.push_back({j, 4 + j + 1, 4 + j});
    }
    terrain.AddTriangles(v, tris, f.bump_friction.value_or(s_.terrain.friction),
                         fmt::format("bump{}", n));
    events_.push_back(json{{"t_s", 0.0},
                           {"event", "fault_applied"},
                           {"category", "physics"},
                           {"fault", "bump"},
                           {"name", fmt::format("bump{}", n)},
                           {"x_m", f.x_m},
                           {"y_m", f.y_m},
                           {"width_m", f.width_m},
                           {"height_m", f.height_m},
                           {"ramp_length_m", f.ramp_length_m},
                           {"top_length_m", f.top_length_m}});
    ++n;
  }
}

void Run::AppendFaultEvents() {
  for (const auto& e : fault_log_.events()) {
    events_.push_back(json{{"t_s", static_cast<double>(e.t_ns - motion0_ns_) * 1e-9},
                           {"event", "fault_" + e.phase},
                           {"category", e.category},
                           {"fault", e.kind},
                           {"target", e.target},
                           {"detail", e.detail}});
  }
  fault_log_.Clear();
}

void Run::OnWire(const WireFrame& w) {
  const bool injected = faulty_bus_ && (w.node == faulty_bus_->flood_node() ||
                                        w.node == faulty_bus_->error_node() || w.frame.error);
  if (!injected) ++completed_;
  if (background_log_) {
    background_log_->Write(w.complete_ns, w.frame);
  } else {
    (void)log_->Write(w.complete_ns, iface_, w.frame);
  }
  if (w.frame.error) return;  // an error burst: in can.log only (nothing to deliver)
  if (w.node != bus_firmware_) {
    if (pumped_) {
      if (!broker_->SendLocal(local_port_, w.frame)) ++enqueue_failures_;
      // A pumped broker moves nothing on its own: hand the firmware what piled up between
      // two waits for it before its socket fills.
      if (++unpumped_frames_ >= kMaxUnpumpedFrames) PumpBroker(0);
    } else if (can_->Send(w.frame)) {
      ++enqueue_failures_;
    }
    // Boot-ups and SDO answers: the firmware reacts to each; lockstep waits for it.
    const std::uint32_t id = w.frame.id;
    if (!w.frame.extended && id == kSyncId && w.node == bus_emulator_) {
      tpdos_since_sync_ = 0;
      ++syncs_on_wire_;
    }
    // tpdo_len_ is filled at the motion start; before it no cycle runs.
    for (std::size_t i = 0; i < tpdo_len_.size() && !w.frame.extended; ++i) {
      if (w.node == encoders_[i].bus_node &&
          id == 0x180u + static_cast<std::uint32_t>(encoders_[i].spec.node_id) &&
          w.frame.len == tpdo_len_[i]) {
        tpdos_since_sync_ |= 1u << i;
      }
    }
    if (!w.frame.extended &&
        ((id >= 0x701 && id <= 0x77F && w.frame.len == 1 && w.frame.data[0] == 0) ||
         (id >= 0x581 && id <= 0x5FF))) {
      awaiting_nodes_.insert(static_cast<int>(id & 0x7F));
    }
  }
  // Every node hears every frame but its own.
  for (std::size_t i = 0; i < encoders_.size(); ++i) {
    if (encoders_[i].bus_node == w.node) continue;
    EnqueueNodeFrames(encoders_[i].bus_node, i, encoders_[i].node->OnFrame(w.frame, w.complete_ns));
  }
}

void Run::AdvanceBus(std::int64_t t_ns) {
  constexpr std::int64_t kSlice = 20'000;
  while (bus_->now_ns() < t_ns) {
    const bool busy = enqueued_ > completed_;
    std::int64_t to = busy ? std::min(t_ns, bus_->now_ns() + kSlice) : t_ns;
    if (faulty_bus_) {
      for (const auto& w : faulty_bus_->AdvanceTo(to)) OnWire(w);
      continue;
    }
    if (busy && to < t_ns) {
      // Slices that end before the bus's next event only move its clock (no frame reaches
      // OnWire, so nothing is enqueued in between and `busy` stays): go straight to the first
      // slice boundary at or after that event. The boundaries stay those of the slice-by-slice
      // walk, so the bus sees the same calls where anything happens.
      const std::int64_t until = std::min(t_ns, bus_->NextEventNs());
      if (until > to) to = std::min(t_ns, to + (until - to + kSlice - 1) / kSlice * kSlice);
    }
    bus_->AdvanceTo(to, wire_scratch_);
    if (wire_scratch_.empty()) continue;
    // OnWire enqueues into the bus model but never advances it: the buffer stays as it is.
    for (const auto& w : wire_scratch_) OnWire(w);
  }
}

void Run::RecordTruth(bool force) {
  if (!force && t_ns_ % truth_every_ns_ != 0) return;
  const auto& b = *body_;
  const double t = static_cast<double>(t_ns_) * 1e-9 - t_motion0_s_;
  const double c = std::cos(-yaw0_), sn = std::sin(-yaw0_);
  const Eigen::Vector3d d = b.p_WB - p0_;
  TruthRow r;
  r.t_s = t;
  r.x_m = c * d.x() - sn * d.y();
  r.y_m = sn * d.x() + c * d.y();
  r.z_m = b.p_WB.z();
  r.theta_rad = b.yaw_rad - yaw0_;
  const Eigen::Vector3d v_B = b.q_WB.conjugate() * b.v_WB_W;
  const Eigen::Vector3d w_B = b.q_WB.conjugate() * b.omega_WB_W;
  r.vx_m_s = v_B.x();
  r.vy_m_s = v_B.y();
  r.omega_rad_s = w_B.z();
  const auto& wt = *wheels_;
  for (std::size_t i = 0; i < drive_wheels_.size(); ++i) {
    const bool slipping = s_.slip_threshold_m_s
                              ? wt[drive_wheels_[i]].slip_speed_m_s > *s_.slip_threshold_m_s
                              : wt[drive_wheels_[i]].slipping;
    if (slipping) r.slipping_wheels |= 1 << i;
  }
  if (!truth_.empty() && truth_.back().t_s == t) return;
  truth_.push_back(r);
  truth_pose_.push_back({t, r.x_m, r.y_m, r.theta_rad});
  truth_vel_.push_back({t, r.vx_m_s, r.vy_m_s, r.omega_rad_s});
}

void Run::PhysicsStep(std::int64_t t_ns, bool motion, std::vector<json>& events) {
  const double t_s = static_cast<double>(t_ns) * 1e-9;
  // Command for the step.
  if (motion) {
    const double tm = t_s - t_motion0_s_;
    double t0 = 0;
    bool wheels = false;
    for (const auto& m : s_.motion) {
      if (tm >= t0 && tm < t0 + m.duration_s && m.kind == MotionSegment::Kind::kWheels) {
        for (std::size_t i = 0; i < m.wheel_speeds_rad_s.size(); ++i) {
          (void)vehicle_->SetWheelSpeedCommand(i, m.wheel_speeds_rad_s[i]);
        }
        wheels = true;
      }
      t0 += m.duration_s;
    }
    if (!wheels) platforms::CommandTwist(*vehicle_, s_.platform, TwistAt(s_.motion, tm));
  } else {
    platforms::CommandTwist(*vehicle_, s_.platform, platforms::BodyTwist{});
  }
  if (motion) ApplyPhysicalFaults(static_cast<double>(t_ns - motion0_ns_) * 1e-9, events);
  world_->Step();
}

void Run::StartPhysicsPipeline(std::int64_t steps) {
  using PT = RunOptions::PhysicsThread;
  if (o_.physics_thread == PT::kOff || steps <= 0) return;
  // The worker's CPUs: those the run may use except the run's own (ConfineToOneCpu).
  cpu_set_t allowed;
  CPU_ZERO(&allowed);
  if (cpu_ >= 0) {
    allowed = saved_cpus_;
    CPU_CLR(cpu_, &allowed);
  } else if (::sched_getaffinity(0, sizeof(allowed), &allowed) != 0) {
    CPU_ZERO(&allowed);
  }
  const int others = CPU_COUNT(&allowed) - (cpu_ >= 0 ? 0 : 1);
  if (o_.physics_thread == PT::kAuto && others < 1) return;
  if (CPU_COUNT(&allowed) == 0) CPU_SET(cpu_ >= 0 ? cpu_ : 0, &allowed);  // kOn, one CPU
  const std::int64_t t0_ns = t_ns_;
  // From here the worker owns the vehicle: what the run reads before the first motion step
  // (the truth row of the motion start) is a copy.
  start_state_.body = vehicle_->body_truth();
  start_state_.wheels = vehicle_->wheel_truth();
  // From here the worker also owns the accelerometers' sensor models (their noise streams);
  // the run's thread still encodes every sample (counter, next instant).
  if (accel4_) worker_accel_next_ns_ = accel4_->next_sample_ns();
  body_ = &start_state_.body;
  wheels_ = &start_state_.wheels;
  // 2048 steps of look-ahead (~2 s of motion at 1 kHz, ~1.5 MB): either side may lose its CPU
  // to another process for a time slice (a few ms) without the other running dry or blocking
  // (with 256, on a machine busy with a build, paper000_slip went 164x against 258x now).
  pipeline_ = std::make_unique<StepPipeline<MotionStepState>>(
      2048, steps,
      [this, t0_ns](std::int64_t step, MotionStepState& out) {
        out.events.clear();
        PhysicsStep(t0_ns + step * step_ns_, true, out.events);
        out.body = vehicle_->body_truth();
        out.wheels = vehicle_->wheel_truth();
        out.accel.clear();
        if (accel4_) {
          // The instants the run's thread samples after this step: those <= its t_ns_ then.
          const std::int64_t t_after = t0_ns + (step + 1) * step_ns_;
          for (; worker_accel_next_ns_ <= t_after; worker_accel_next_ns_ += accel4_->period_ns()) {
            out.accel.push_back(accel4_->SampleSensors(AccelKinematics(out.body)));
          }
        }
      },
      cpu_ >= 0 || o_.physics_thread == PT::kOn ? &allowed : nullptr);
  physics_thread_used_ = true;
  // The lines of the frames from here on are formatted there as well.
  if (log_) {
    background_log_ = std::make_unique<BackgroundCandump>(
        *log_, iface_, cpu_ >= 0 || o_.physics_thread == PT::kOn ? &allowed : nullptr);
  }
}

BodyKinematics Run::AccelKinematics(const physics::BodyTruth& b) {
  BodyKinematics k;
  k.a_WBo_B = b.q_WB.conjugate() * b.a_WB_W;
  k.omega_WB_B = b.q_WB.conjugate() * b.omega_WB_W;
  k.alpha_WB_B = b.q_WB.conjugate() * b.alpha_WB_W;
  k.g_B = b.q_WB.conjugate() * Eigen::Vector3d(0.0, 0.0, -9.80665);
  return k;
}

void Run::Step(bool motion) {
  if (motion && pipeline_) {
    const MotionStepState* st = nullptr;
    try {
      st = &pipeline_->Next();
    } catch (const std::exception& e) {
      if (failure_.empty()) failure_ = e.what();
      return;
    }
    for (const json& e : st->events) events_.push_back(e);
    body_ = &st->body;
    wheels_ = &st->wheels;
    accel_samples_ = &st->accel;
  } else {
    PhysicsStep(t_ns_, motion, events_);
    body_ = &vehicle_->body_truth();
    wheels_ = &vehicle_->wheel_truth();
  }
  t_ns_ += step_ns_;
  const double t_now = static_cast<double>(t_ns_) * 1e-9;

  // Faults.
  for (const auto& f : s_.faults) {
    if (f.kind != FaultSpec::Kind::kEncoderEmcy && f.kind != FaultSpec::Kind::kEncoderSilent) {
      continue;
    }
    const double t_start = t_motion0_s_ + f.start_s, t_end = t_motion0_s_ + f.end_s;
    if (!motion) continue;
    for (auto& e : encoders_) {
      if (e.spec.node_id != f.node_id) continue;
      const bool on = t_now >= t_start && t_now < t_end;
      const bool was = t_now - static_cast<double>(step_ns_) * 1e-9 >= t_start &&
                       t_now - static_cast<double>(step_ns_) * 1e-9 < t_end;
      if (on == was) continue;
      events_.push_back(json{
          {"t_s", t_now - t_motion0_s_},
          {"event", on ? "fault_start" : "fault_end"},
          {"fault", f.kind == FaultSpec::Kind::kEncoderEmcy ? "encoder_emcy" : "encoder_silent"},
          {"node_id", f.node_id}});
      if (f.kind == FaultSpec::Kind::kEncoderEmcy) {
        if (on) {
          e.node->RaiseFault(f.error_code, 0x81, t_ns_);
        } else {
          e.node->ClearFault(t_ns_);
        }
      } else {
        e.silent = on;
      }
    }
  }

  // Sensors and devices.
  const auto& wt = *wheels_;
  for (std::size_t i = 0; i < encoders_.size(); ++i) {
    auto& e = encoders_[i];
    std::optional<std::uint32_t> counts = e.model->Sample(wt[e.wheel].angle_rad);
    if (e.sensor_fault) counts = e.sensor_fault->ApplyCounts(*counts, t_ns_);
    const double speed = wt[e.wheel].omega_rad_s * e.model->counts_per_rev() /
                         (2.0 * std::numbers::pi) * e.spec.direction;
    // A dropped sample (dropout) leaves the node's last measurement in place.
    if (counts) e.node->SetMeasurement(*counts, speed);
    if (e.device_fault) {
      if (e.device_fault->NextActionNs() <= t_ns_) {
        (void)e.device_fault->ApplyTo(*e.node, e.config, cia406_, t_ns_);
      }
      e.device_fault->AdvanceTo(t_ns_);
    }
    if (e.silent) {
      silenced_ += e.node->Poll(t_ns_).size();
    } else {
      SubmitDeviceFrames(e.bus_node, e.node->Poll(t_ns_), true);
    }
    if (e.node->state() != e.last_state) {
      e.last_state = e.node->state();
      events_.push_back(json{{"t_s", t_now - t_motion0_s_},
                             {"event", "node_state"},
                             {"node_id", e.spec.node_id},
                             {"state", static_cast<int>(e.last_state)}});
    }
  }
  if (imu_) {
    while (imu_->next_sample_ns() <= t_ns_) {
      const std::int64_t ts = imu_->next_sample_ns();
      const auto& b = *body_;
      const Eigen::Vector3d w_B = b.q_WB.conjugate() * b.omega_WB_W;
      const Eigen::Vector3d a_B = b.q_WB.conjugate() * b.a_WB_W;
      std::optional<double> rate = imu_->SampleYawRate(w_B);
      if (gyro_fault_) rate = gyro_fault_->Apply(*rate, ts);
      if (!rate) continue;  // dropout: no frame for this sample
      NodeFrame nf;
      nf.due_ns = ts;
      (void)imu_->Encode(*rate, a_B.y(), nf.frame);
      SubmitDeviceFrames(bus_imu_, {nf}, true);
    }
  }
  if (accel4_) {
    // The four accelerometers at each sample instant, from the body kinematics of this step.
    const bool from_worker = motion && pipeline_;
    std::size_t taken = 0;
    while (accel4_->next_sample_ns() <= t_ns_) {
      const std::int64_t ts = accel4_->next_sample_ns();
      std::array<double, 4> a{};
      if (!from_worker) {
        a = accel4_->SampleSensors(AccelKinematics(*body_));
      } else if (taken < accel_samples_->size()) {
        a = (*accel_samples_)[taken++];
      } else {
        // Cannot happen (the worker walks the same instants); fail loudly rather than differ.
        if (failure_.empty()) failure_ = "internal: accel4 sample missing from the physics worker";
        break;
      }
      bool dropped = false;
      for (std::size_t c = 0; c < 4; ++c) {
        if (!accel_fault_[c]) continue;
        const auto v = accel_fault_[c]->Apply(a[c], ts);
        if (v) {
          a[c] = *v;
        } else {
          dropped = true;
        }
      }
      NodeFrame nf;
      nf.due_ns = ts;
      (void)accel4_->EncodeSample(a, nf.frame);  // advances (and counts) even when dropped
      if (!dropped) SubmitDeviceFrames(bus_accel4_, {nf}, true);
    }
  }
  // Frames a frame fault delayed (or a duplicate's copy) that are due now; silent windows.
  for (auto& [node, filter] : frame_filters_) SubmitDeviceFrames(node, {}, true);
  for (auto& [node, dev] : node_faults_) dev->AdvanceTo(t_ns_);
  if (motion) {
    const auto& wt2 = *wheels_;
    bool slip = false;
    for (std::size_t w : drive_wheels_) {
      slip = slip || (s_.slip_threshold_m_s ? wt2[w].slip_speed_m_s > *s_.slip_threshold_m_s
                                            : wt2[w].slipping);
    }
    slip_t_.push_back(t_now - step_ns_ * 1e-9 - t_motion0_s_);
    slip_flag_.push_back(slip);
    airborne_.resize(wt2.size());
    for (std::size_t w = 0; w < wt2.size(); ++w) airborne_[w].push_back(!wt2[w].in_contact);
  }
}

void Run::OnFirmwareFrame(const bus::CanFrame& f) {
  ++fw_frames_;
  // Into the bus model at the current virtual instant (it is logged when it completes).
  if (bus_->Enqueue(bus_firmware_, f, bus_->now_ns())) {
    ++enqueued_;
  } else {
    ++enqueue_failures_;
  }
  if (f.extended) return;
  // Reactions the lockstep start-up waits for: SDO requests and NMT commands.
  if (f.id >= 0x601 && f.id <= 0x67F) awaiting_nodes_.erase(static_cast<int>(f.id & 0x7F));
  if (f.id == 0x000 && f.len >= 2) {
    if (f.data[1] == 0) {
      awaiting_nodes_.clear();
    } else {
      awaiting_nodes_.erase(f.data[1]);
    }
  }
  const bus::DbcMessage* msg = fwdbc_->FindMessage(f.id, false);
  if (msg == nullptr) return;
  FwFramePlan& plan = FwPlanFor(*msg);
  // A field's value as DecodeMessage's map would give it: its first signal of that name present
  // in the frame, 0 when none is.
  auto get = [&](std::size_t field) {
    double value = 0.0;
    for (const bus::DbcSignal* sig : plan.fields[field]) {
      if (bus::DecodeSignalIfPresent(*msg, *sig, f, &value)) return value;
    }
    return 0.0;
  };
  if (plan.kind == FwFramePlan::Kind::kStatus) {
    ++status_frames_;
    last_status_cycle_ = static_cast<int>(get(0));
    const int state = static_cast<int>(get(1));
    if (state != last_fw_state_) {
      last_fw_state_ = state;
      const double t = static_cast<double>(bus_->now_ns()) * 1e-9 - t_motion0_s_;
      events_.push_back(json{{"t_s", t}, {"event", "firmware_state"}, {"state", state}});
    }
    return;
  }
  // Estimate frames: time of the SYNC that opened their cycle.
  if (plan.kind == FwFramePlan::Kind::kIgnored) return;
  const int cycle = static_cast<int>(get(0));
  const auto it = sync_time_by_cycle_.find(cycle);
  if (it == sync_time_by_cycle_.end()) return;
  const double t = it->second - t_motion0_s_;
  switch (plan.kind) {
    case FwFramePlan::Kind::kPose: {
      const PoseSample ps{t, get(1), get(2), get(3)};
      if (plan.pose == nullptr) plan.pose = &pose_streams_[plan.stream];
      plan.pose->push_back(ps);
      estimates_.push_back({t, cycle, plan.stream, ps.x_m, ps.y_m, ps.theta_rad});
      break;
    }
    case FwFramePlan::Kind::kVelocity: {
      const VelocitySample vs{t, get(1), get(2), get(3)};
      if (plan.vel == nullptr) plan.vel = &vel_streams_[plan.stream];
      plan.vel->push_back(vs);
      estimates_.push_back({t, cycle, plan.stream, vs.vx_m_s, vs.vy_m_s, vs.omega_rad_s});
      break;
    }
    case FwFramePlan::Kind::kSlip:
      detections_.push_back({t, get(1) != 0});
      if (get(2) != 0) {
        residual_t_.push_back(t);
        residual_.push_back(get(3));
        band_lo_.push_back(get(4));
        band_hi_.push_back(get(5));
      }
      break;
    default:
      break;
  }
}

Run::FwFramePlan& Run::FwPlanFor(const bus::DbcMessage& msg) {
  const auto found = fw_plans_.find(&msg);
  if (found != fw_plans_.end()) return found->second;
  FwFramePlan plan;
  auto field = [&](const std::string& name) {
    std::vector<const bus::DbcSignal*> sigs;
    for (const auto& sg : msg.signals) {
      if (sg.name == name) sigs.push_back(&sg);
    }
    plan.fields.push_back(std::move(sigs));
  };
  auto estimate = [&](FwFramePlan::Kind kind, const char* stream, const std::string& prefix,
                      std::initializer_list<const char*> names) {
    plan.kind = kind;
    plan.stream = stream;
    for (const char* n : names) field(prefix + n);
  };
  if (msg.id == kFwStatusId && !msg.extended) {
    plan.kind = FwFramePlan::Kind::kStatus;
    field("Status_Cycle");
    field("Status_State");
  } else {
    // The cycle: the first signal named <prefix>_Cycle; a message without one is not an estimate.
    std::string cycle;
    for (const auto& sg : msg.signals) {
      if (sg.name.size() > 6 && sg.name.ends_with("_Cycle")) {
        cycle = sg.name;
        break;
      }
    }
    plan.kind = FwFramePlan::Kind::kIgnored;
    if (!cycle.empty()) {
      field(cycle);
      if (msg.name == "FW_Pose")
        estimate(FwFramePlan::Kind::kPose, "pose", "Pose", {"_X", "_Y", "_Theta"});
      if (msg.name == "FW_PoseRaw") {
        estimate(FwFramePlan::Kind::kPose, "pose_raw", "PoseRaw", {"_X", "_Y", "_Theta"});
      }
      if (msg.name == "FW_Velocity") {
        estimate(FwFramePlan::Kind::kVelocity, "fused", "Vel", {"_Vx", "_Vy", "_Omega"});
      }
      if (msg.name == "FW_VelocityOdom") {
        estimate(FwFramePlan::Kind::kVelocity, "odometry", "VelOdom", {"_Vx", "_Vy", "_Omega"});
      }
      if (msg.name == "FW_VelocityAccel") {
        estimate(FwFramePlan::Kind::kVelocity, "accel", "VelAccel", {"_Vx", "_Vy", "_Omega"});
      }
      if (msg.name == "FW_SlipStatus") {
        estimate(FwFramePlan::Kind::kSlip, "", "Slip_",
                 {"OutOfBand", "Calibrated", "Residual", "BandLower", "BandUpper"});
      }
    }
  }
  return fw_plans_.emplace(&msg, std::move(plan)).first->second;
}

void Run::PumpBroker(int timeout_ms) {
  unpumped_frames_ = 0;
  if (!broker_->Pump(timeout_ms) && failure_.empty()) failure_ = "the userspace bus stopped";
}

void Run::DrainFirmware(int timeout_ms) {
  bus::ReceivedFrame rx;
  int wait = timeout_ms;
  while (!can_->Receive(rx, wait)) {
    OnFirmwareFrame(rx.frame);
    wait = 0;
  }
}

bool Run::WaitFirmware(const std::function<bool()>& done, double timeout_s) {
  const auto t0 = Clock::now();
  while (!done()) {
    const double left = timeout_s - WallSeconds(t0);
    if (left <= 0) return false;
    bus::ReceivedFrame rx;
    const int wait_ms = std::max(1, std::min(50, static_cast<int>(left * 1000)));
    if (pumped_) {
      // Frames already routed to us first; else one broker pass, which hands the firmware what
      // the emulator sent since the last one and then sleeps until the firmware writes.
      if (broker_->ReceiveLocal(local_port_, &rx.frame)) {
        OnFirmwareFrame(rx.frame);
        continue;
      }
      PumpBroker(wait_ms);
      if (!failure_.empty()) return false;
      // waitpid costs a system call: look at most every 20 ms (a pass ends on any traffic).
      if (firmware_.running() && WallSeconds(last_exit_check_) > 0.02) {
        last_exit_check_ = Clock::now();
        if (firmware_.Exited()) {
          failure_ = "the firmware exited during the run (see firmware.log)";
          return false;
        }
      }
      continue;
    }
    const auto ec = can_->Receive(rx, wait_ms);
    if (!ec) {
      OnFirmwareFrame(rx.frame);
    } else if (firmware_.running() && firmware_.Exited()) {
      failure_ = "the firmware exited during the run (see firmware.log)";
      return false;
    }
  }
  return true;
}

void Run::Progress(bool final) {
  if (!o_.progress) return;
  if (!final && WallSeconds(last_progress_) < 0.2) return;
  last_progress_ = Clock::now();
  const double sim = static_cast<double>(t_ns_) * 1e-9 - t_motion0_s_;
  const double wall = WallSeconds(wall0_);
  fmt::print(stderr, "\r{}: t = {:7.2f} / {:.2f} s  cycle {:6}  {:7.1f}x real time{}", s_.name,
             std::max(0.0, sim), s_.timing.duration_s, syncs_sent_,
             wall > 0 ? std::max(0.0, sim) / wall : 0.0, final ? "\n" : "");
}

RunResult Run::Execute() {
  RunResult result;
  seed_ = o_.seed.value_or(s_.seed);
  out_ = o_.out_dir;
  std::error_code ec;
  fs::create_directories(out_, ec);
  if (ec || !fs::is_directory(out_)) {
    throw std::invalid_argument(fmt::format("--out {}: cannot create the directory", out_));
  }
  if (!fs::exists(o_.dbc_dir + "/wheelhil_fw.dbc")) {
    throw std::invalid_argument(
        fmt::format("no DBC files in '{}' (set WHEELHIL_DBC_DIR)", o_.dbc_dir));
  }
  const bool lockstep = s_.timing.lockstep && !o_.realtime;
  if (lockstep) ConfineToOneCpu();
  wall0_ = Clock::now();
  last_progress_ = wall0_;
  truth_every_ns_ = std::min<std::int64_t>(10'000'000, std::llround(s_.timing.sync_period_s * 1e9));
  BuildWorld();
  BuildDevices();
  OpenBus(lockstep);
  events_.push_back(json{{"t_s", 0.0},
                         {"event", "run_start"},
                         {"seed", seed_},
                         {"lockstep", lockstep},
                         {"bus", o_.can_iface.empty() ? "ucan" : "socketcan"}});

  // The firmware.
  if (!s_.firmware.command.empty()) {
    std::string cmd = s_.firmware.command;
    if (!s_.firmware.config.empty()) {
      const std::string cfg_path = fs::absolute(out_ + "/firmware_config.yaml").string();
      TimingSpec timing = s_.timing;
      timing.lockstep = lockstep;
      WriteText(cfg_path, DerivedFirmwareConfig(s_.firmware, timing));
      cmd = Substitute(cmd, "${CONFIG}", cfg_path);
    }
    cmd = Substitute(Substitute(cmd, "${CAN}", iface_), "${BIN}", o_.bin_dir);
    std::vector<std::pair<std::string, std::string>> env;
    if (broker_ && o_.ucan_child_env) env = o_.ucan_child_env(runtime_dir_);
    env.emplace_back("WHEELHIL_DBC_DIR", o_.dbc_dir);
    if (!broker_) kernel_receivers_before_fw_ = CountKernelCanReceivers(iface_);
    firmware_.Start(cmd, env, out_ + "/firmware.log");
    std::string why;
    if (!WaitForFirmwareConnection(why)) failure_ = why;
  } else if (broker_) {
    std::string why;
    if (!WaitForFirmwareConnection(why)) failure_ = "no firmware attached: " + why;
  }

  // Start-up: nodes boot, the firmware configures and starts them.
  const std::int64_t boot_limit_ns = std::llround(10e9);
  auto all_operational = [&] {
    return std::all_of(encoders_.begin(), encoders_.end(), [](const Encoder& e) {
      return e.node->state() == CanopenEncoderNode::NmtState::kOperational;
    });
  };
  while (failure_.empty() && !(all_operational() && awaiting_nodes_.empty())) {
    Step(false);
    RecordTruth(false);
    AdvanceBus(t_ns_);
    if (lockstep) {
      if (!awaiting_nodes_.empty() &&
          !WaitFirmware([&] { return awaiting_nodes_.empty(); }, s_.timing.timeout_s)) {
        if (failure_.empty()) {
          failure_ = fmt::format(
              "timeout: the firmware did not answer node {}'s boot-up/SDO within {} s (wall)",
              *awaiting_nodes_.begin(), s_.timing.timeout_s);
        }
      }
    } else {
      DrainFirmware(0);
      std::this_thread::sleep_until(wall0_ + std::chrono::nanoseconds(t_ns_));
    }
    if (t_ns_ > boot_limit_ns && failure_.empty()) {
      failure_ = "the encoder nodes were not started (NMT start) within 10 s of virtual time";
    }
  }
  // Let the settled vehicle define the start.
  const std::int64_t settle_ns = std::llround(0.2e9);
  for (std::int64_t until = t_ns_ + settle_ns; failure_.empty() && t_ns_ < until;) {
    Step(false);
    AdvanceBus(t_ns_);
    if (!lockstep) DrainFirmware(0);
  }
  // Motion: SYNC every period; lockstep waits for the firmware's status of each cycle.
  const std::int64_t period_ns = std::llround(s_.timing.sync_period_s * 1e9);
  const std::int64_t steps_per_cycle = period_ns / step_ns_;
  const std::int64_t cycles = std::llround(s_.timing.duration_s * 1e9) / period_ns;
  t_motion0_s_ = static_cast<double>(t_ns_) * 1e-9;
  p0_ = vehicle_->body_truth().p_WB;
  yaw0_ = vehicle_->body_truth().yaw_rad;
  events_.push_back(json{{"t_s", 0.0}, {"event", "motion_start"}});
  ArmFaults();
  in_motion_ = true;
  truth_.clear();
  truth_pose_.clear();
  truth_vel_.clear();
  const auto wall_motion0 = Clock::now();
  // Lockstep waits only where the firmware's answer is fixed by the frames it was given: after
  // the cycle's last TPDO1 when every encoder answered the SYNC in time, else after the next
  // SYNC (which closes the cycle). The firmware runs without a deadline in lockstep.
  all_tpdos_ = encoders_.empty() ? 0u : static_cast<std::uint32_t>((1ull << encoders_.size()) - 1);
  tpdo_len_.clear();
  for (const auto& e : encoders_) {
    const bus::DbcMessage* m =
        cia406_->database().FindMessage(0x180u + static_cast<std::uint32_t>(e.spec.node_id), false);
    tpdo_len_.push_back(m != nullptr ? static_cast<std::uint8_t>(m->length) : 0);
  }
  auto wait_status = [&](int cycle, std::int64_t k) {
    if (!WaitFirmware([&] { return last_status_cycle_ == cycle && status_frames_ > 0; },
                      s_.timing.timeout_s) &&
        failure_.empty()) {
      failure_ =
          fmt::format("timeout: no FW_Status for cycle {} within {} s (wall) at t = {:.3f} s", k,
                      s_.timing.timeout_s, static_cast<double>(t_ns_) * 1e-9 - t_motion0_s_);
    }
  };
  if (lockstep) StartPhysicsPipeline(cycles * steps_per_cycle);
  for (std::int64_t k = 0; failure_.empty() && k <= cycles; ++k) {
    // SYNC k at the start of the cycle.
    RecordTruth(true);
    bus::CanFrame sync;
    sync.id = kSyncId;
    sync.len = 0;
    if (bus_->Enqueue(bus_emulator_, sync, t_ns_)) {
      ++enqueued_;
    } else {
      ++enqueue_failures_;
    }
    sync_time_by_cycle_[static_cast<int>(syncs_sent_ % 256)] = static_cast<double>(t_ns_) * 1e-9;
    const int want = static_cast<int>(syncs_sent_ % 256);
    ++syncs_sent_;
    // The SYNC and the TPDOs answering it (the encoder readings at this instant) go out
    // before the physics moves on.
    AdvanceBus(t_ns_ + step_ns_ / 2);
    if (lockstep && pending_status_cycle_ >= 0) {
      // The previous cycle was incomplete on the bus: this SYNC closes it once it is on the
      // wire (an error burst or a flood can hold it back beyond half a step).
      for (const std::int64_t until = t_ns_ + period_ns;
           syncs_on_wire_ < syncs_sent_ && bus_->now_ns() < until;) {
        AdvanceBus(std::min(until, bus_->now_ns() + step_ns_ / 2));
      }
      wait_status(std::exchange(pending_status_cycle_, -1), k - 1);
    }
    if (lockstep && k == cycles && failure_.empty()) {
      // The last cycle: no physics step follows, so let the bus finish its TPDO1s (at most
      // one period) before waiting for the answer.
      for (const std::int64_t until = t_ns_ + period_ns;
           !CycleCompleteOnBus() && bus_->now_ns() < until;) {
        AdvanceBus(std::min(until, bus_->now_ns() + step_ns_ / 2));
      }
    }
    for (std::int64_t i = 0; i < steps_per_cycle && k < cycles; ++i) {
      Step(true);
      RecordTruth(false);
      AdvanceBus(t_ns_);
      if (i == 0 && lockstep) {
        if (CycleCompleteOnBus()) {
          wait_status(want, k);
        } else {
          pending_status_cycle_ = want;
        }
      }
      if (!lockstep) {
        DrainFirmware(0);
        std::this_thread::sleep_until(
            wall_motion0 + std::chrono::nanoseconds(t_ns_ - std::llround(t_motion0_s_ * 1e9)));
      }
      Progress(false);
    }
    if (k == cycles && failure_.empty()) {
      if (!lockstep || CycleCompleteOnBus()) {
        if (!WaitFirmware([&] { return last_status_cycle_ == want && status_frames_ > 0; },
                          s_.timing.timeout_s)) {
          if (failure_.empty()) {
            failure_ = fmt::format("timeout: no FW_Status for the last cycle {} within {} s", k,
                                   s_.timing.timeout_s);
          }
        }
      } else {
        // A TPDO1 of the last SYNC never came (silent node, dropped frame): no later SYNC
        // closes that cycle, so its answer is not awaited.
        events_.push_back(json{{"t_s", static_cast<double>(t_ns_) * 1e-9 - t_motion0_s_},
                               {"event", "last_cycle_incomplete"},
                               {"cycle", k}});
      }
    }
  }
  pipeline_.reset();        // stops the worker (a failed run leaves it steps ahead)
  background_log_.reset();  // its queue written: what follows goes to log_ directly, in order
  Progress(true);
  for (const auto& w : bus_->Drain()) {
    ++completed_;
    (void)log_->Write(w.complete_ns, iface_, w.frame);
  }
  const double wall_s = WallSeconds(wall0_);
  AppendFaultEvents();
  firmware_.Stop();
  log_.reset();
  if (!failure_.empty()) {
    events_.push_back(json{{"t_s", static_cast<double>(t_ns_) * 1e-9 - t_motion0_s_},
                           {"event", "failure"},
                           {"reason", failure_}});
  }
  json report = BuildReport(wall_s);
  json expectations = json::array();
  const bool all_ok = EvaluateExpectations(s_.expectations, report["metrics"], expectations);
  report["expectations"] = expectations;
  report["verdict"] = (all_ok && failure_.empty()) ? "pass" : "fail";
  if (!failure_.empty()) report["failure"] = failure_;
  WriteArtefacts(report);
  result.report = report;
  result.failure = failure_;
  result.exit_code = (all_ok && failure_.empty()) ? 0 : 1;
  if (broker_) {
    can_.reset();
    broker_.reset();
  }
  return result;
}

json Run::BuildReport(double wall_s) {
  json r;
  r["scenario"] = s_.name;
  r["seed"] = seed_;
  const double sim = std::max(0.0, static_cast<double>(t_ns_) * 1e-9 - t_motion0_s_);
  r["sim_time_s"] = sim;
  r["cycles"] = syncs_sent_;
  r["sync_period_s"] = s_.timing.sync_period_s;
  json metrics = json::object();
  for (const auto& [name, est] : pose_streams_) {
    const PoseMetrics m = ComputePoseMetrics(truth_pose_, est);
    metrics[name] = json{{"final_position_error_m", m.final_position_error_m},
                         {"final_heading_error_rad", m.final_heading_error_rad},
                         {"ape_rmse_m", m.ape_rmse_m},
                         {"distance_m", m.distance_m},
                         {"rotation_rad", m.rotation_rad},
                         {"samples", m.samples}};
    if (m.distance_m > 0) {
      metrics[name]["final_position_error_pct_of_distance"] =
          100.0 * m.final_position_error_m / m.distance_m;
    }
  }
  if (metrics.contains("pose") && metrics.contains("pose_raw")) {
    const double c = metrics["pose"]["final_position_error_m"].get<double>();
    const double u = metrics["pose_raw"]["final_position_error_m"].get<double>();
    metrics["correction"] = json{{"uncorrected_over_corrected", c > 0 ? u / c : 0.0},
                                 {"corrected_below_uncorrected", c < u}};
  }
  for (const auto& [name, est] : vel_streams_) {
    metrics[name]["velocity_rmse_m_s"] = VelocityRmse(truth_vel_, est);
    metrics[name]["samples"] = est.size();
  }
  const auto intervals =
      FlagsToIntervals(slip_t_, slip_flag_, static_cast<double>(step_ns_) * 1e-9, 0.02, 0.0);
  for (const auto& iv : intervals) {
    events_.push_back(
        json{{"t_s", iv.start_s}, {"event", "slip"}, {"start_s", iv.start_s}, {"end_s", iv.end_s}});
  }
  // Contact loss per wheel (ground truth): episodes are merged over regained contact shorter
  // than 10 ms, so a wheel chattering over a bump is one episode; the time is the steps off the
  // floor.
  json contact = json::object();
  int wheels_losing_contact = 0;
  std::size_t all_episodes = 0;
  const double step_s = static_cast<double>(step_ns_) * 1e-9;
  for (std::size_t w = 0; w < airborne_.size(); ++w) {
    const auto episodes = FlagsToIntervals(slip_t_, airborne_[w], step_s, 0.01, 0.0);
    if (episodes.empty()) continue;
    const std::string& wheel = s_.platform.vehicle.wheels[w].name;
    double longest = 0;
    for (const auto& iv : episodes) {
      longest = std::max(longest, iv.end_s - iv.start_s);
      events_.push_back(json{{"t_s", iv.start_s},
                             {"event", "contact_lost"},
                             {"wheel", wheel},
                             {"start_s", iv.start_s},
                             {"end_s", iv.end_s}});
    }
    const auto steps = std::count(airborne_[w].begin(), airborne_[w].end(), true);
    ++wheels_losing_contact;
    all_episodes += episodes.size();
    contact[wheel + "_episodes"] = episodes.size();
    contact[wheel + "_time_s"] = static_cast<double>(steps) * step_s;
    contact[wheel + "_longest_s"] = longest;
  }
  contact["wheels_losing_contact"] = wheels_losing_contact;
  contact["episodes"] = all_episodes;
  metrics["contact"] = contact;
  std::stable_sort(events_.begin(), events_.end(), [](const json& a, const json& b) {
    return a["t_s"].get<double>() < b["t_s"].get<double>();
  });
  if (!detections_.empty()) {
    const SlipMetrics sm = ComputeSlipMetrics(intervals, detections_, s_.timing.sync_period_s);
    json j{{"precision", sm.precision},
           {"recall", sm.recall},
           {"true_positive", sm.true_positive},
           {"false_positive", sm.false_positive},
           {"false_negative", sm.false_negative},
           {"true_negative", sm.true_negative},
           {"truth_intervals", sm.intervals},
           {"intervals_detected", sm.intervals_detected},
           {"detections", std::count_if(detections_.begin(), detections_.end(),
                                        [](const DetectionSample& d) { return d.detected; })}};
    if (sm.mean_latency_s) j["mean_latency_s"] = *sm.mean_latency_s;
    if (sm.max_latency_s) j["max_latency_s"] = *sm.max_latency_s;
    metrics["slip"] = j;
    if (!residual_.empty()) {
      const NormalityResult n = NormalityTest(residual_);
      metrics["residual"] = json{{"samples", n.n},
                                 {"mean_rad", n.mean},
                                 {"sigma_rad", n.sigma},
                                 {"skewness_g1", n.g1},
                                 {"excess_kurtosis_g2", n.g2},
                                 {"u1", n.u1},
                                 {"u2", n.u2},
                                 {"normality_accepted", n.accepted}};
    }
  } else if (!intervals.empty()) {
    metrics["slip"] = json{{"truth_intervals", intervals.size()}};
  }
  double slip_time = 0;
  for (const auto& iv : intervals) slip_time += iv.end_s - iv.start_s;
  metrics["truth"] = json{{"slip_intervals", intervals.size()},
                          {"slip_time_s", slip_time},
                          {"distance_m", PathLength(truth_pose_)},
                          {"rotation_rad", TotalRotation(truth_pose_)}};
  metrics["bus"] =
      json{{"frames", bus_->frames_sent()},
           {"load", bus_->BusLoad()},
           {"drops", bus_->frames_dropped() + enqueue_failures_},
           {"silenced_frames", silenced_},
           {"firmware_frames", fw_frames_},
           {"max_queue_delay_s", static_cast<double>(bus_->max_queue_delay_ns()) * 1e-9}};
  if (library_faults_) {
    json fj{{"bus_off_dropped", faulty_bus_ ? faulty_bus_->dropped_bus_off() : 0},
            {"flood_frames", faulty_bus_ ? faulty_bus_->flood_frames() : 0},
            {"error_frames", faulty_bus_ ? faulty_bus_->error_frames() : 0}};
    std::uint64_t affected = 0, unapplied = 0, suppressed = 0;
    std::int64_t missed = 0;
    // Frame faults in list order (the filters' fault indices), totals per kind.
    std::vector<FrameFaultKind> frame_kinds;
    for (const auto& f : s_.faults) {
      if (f.kind == FaultSpec::Kind::kFrame) frame_kinds.push_back(f.frame.kind);
    }
    std::map<std::string, std::uint64_t> by_kind;
    for (const auto& [node, filter] : frame_filters_) {
      for (std::size_t i = 0; i < frame_kinds.size(); ++i) {
        affected += filter->affected(i);
        by_kind[std::string(FrameFaultKindName(frame_kinds[i]))] += filter->affected(i);
      }
      unapplied += filter->unapplied();
    }
    for (const auto& [kind, n] : by_kind) fj["frames_" + kind] = n;
    for (const auto& e : encoders_) {
      if (e.device_fault) suppressed += e.device_fault->suppressed_frames();
      if (e.sensor_fault) missed += e.sensor_fault->missed_counts();
    }
    for (const auto& [node, dev] : node_faults_) suppressed += dev->suppressed_frames();
    fj["frames_affected"] = affected;
    fj["frames_unapplied"] = unapplied;
    fj["device_suppressed_frames"] = suppressed;
    fj["missed_counts"] = missed;
    metrics["faults"] = fj;
  }
  r["metrics"] = metrics;
  r["wall"] = json{{"wall_time_s", wall_s},
                   {"real_time_factor", wall_s > 0 ? sim / wall_s : 0.0},
                   {"cpu", cpu_},
                   {"physics_thread", physics_thread_used_}};
  return r;
}

void Run::WriteArtefacts(const json& report) {
  WriteTruthCsv(out_ + "/truth.csv", truth_);
  WriteEstimateCsv(out_ + "/estimate.csv", estimates_);
  WriteTum(out_ + "/truth.tum", truth_pose_);
  if (pose_streams_.count("pose")) WriteTum(out_ + "/estimate.tum", pose_streams_["pose"]);
  if (pose_streams_.count("pose_raw")) {
    WriteTum(out_ + "/estimate_raw.tum", pose_streams_["pose_raw"]);
  }
  WriteJsonLines(out_ + "/events.jsonl", events_);
  WriteText(out_ + "/report.json", report.dump(2) + "\n");

  const char* colors[] = {"#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b"};
  std::vector<std::string> plots;
  {
    std::vector<Series> ss;
    Series t{"truth", "#1f77b4", {}, {}};
    for (const auto& p : truth_pose_) t.x.push_back(p.x_m), t.y.push_back(p.y_m);
    ss.push_back(t);
    int c = 0;
    for (const auto& [name, est] : pose_streams_) {
      Series e{name, colors[c++ % 5], {}, {}, true};
      for (const auto& p : est) e.x.push_back(p.x_m), e.y.push_back(p.y_m);
      ss.push_back(e);
    }
    plots.push_back(SvgPlot("Trajectory: truth vs estimates", "x [m]", "y [m]", ss, false));
  }
  if (!residual_.empty()) {
    std::vector<Series> ss{{"residual r", "#1f77b4", residual_t_, residual_},
                           {"band lower", "#d62728", residual_t_, band_lo_, true},
                           {"band upper", "#d62728", residual_t_, band_hi_, true}};
    plots.push_back(
        SvgPlot("Paper 000 residual against its band (cf. fig 8)", "t [s]", "r [rad]", ss));
  }
  if (!vel_streams_.empty()) {
    std::vector<Series> ss;
    Series t{"truth vx", "#1f77b4", {}, {}};
    for (const auto& v : truth_vel_) t.x.push_back(v.t_s), t.y.push_back(v.vx_m_s);
    ss.push_back(t);
    int c = 0;
    for (const auto& [name, est] : vel_streams_) {
      Series e{name + " vx", colors[c++ % 5], {}, {}, true};
      for (const auto& v : est) e.x.push_back(v.t_s), e.y.push_back(v.vx_m_s);
      ss.push_back(e);
    }
    plots.push_back(SvgPlot("Forward velocity (cf. paper 002 figs 2-4)", "t [s]", "vx [m/s]", ss));
  }
  if (!pose_streams_.empty() && !truth_pose_.empty()) {
    std::vector<Series> ss;
    int c = 0;
    for (const auto& [name, est] : pose_streams_) {
      Series e{name, colors[c++ % 5], {}, {}};
      // Distance travelled (truth) at each estimate sample vs the position error there.
      std::size_t j = 0;
      double dist = 0;
      for (const auto& p : est) {
        while (j + 1 < truth_pose_.size() && truth_pose_[j + 1].t_s <= p.t_s) {
          dist += std::hypot(truth_pose_[j + 1].x_m - truth_pose_[j].x_m,
                             truth_pose_[j + 1].y_m - truth_pose_[j].y_m);
          ++j;
        }
        const PoseSample t = InterpolatePose(truth_pose_, p.t_s);
        e.x.push_back(dist);
        e.y.push_back(std::hypot(p.x_m - t.x_m, p.y_m - t.y_m));
      }
      ss.push_back(e);
    }
    plots.push_back(
        SvgPlot("Position error over distance travelled", "distance [m]", "error [m]", ss));
  }
  WriteText(out_ + "/report.html", HtmlReport(report, plots));
}

}  // namespace

std::vector<std::pair<std::string, double>> FlattenMetrics(const json& metrics) {
  std::vector<std::pair<std::string, double>> out;
  for (const auto& [stream, m] : metrics.items()) {
    if (!m.is_object()) continue;
    for (const auto& [k, v] : m.items()) {
      if (v.is_number()) out.emplace_back(stream + "." + k, v.get<double>());
      if (v.is_boolean()) out.emplace_back(stream + "." + k, v.get<bool>() ? 1.0 : 0.0);
    }
  }
  return out;
}

bool EvaluateExpectations(const std::vector<Expectation>& expectations, const json& metrics,
                          json& out) {
  const auto flat = FlattenMetrics(metrics);
  auto find = [&](const std::string& name) -> std::optional<double> {
    for (const auto& [k, v] : flat) {
      if (k == name) return v;
    }
    return std::nullopt;
  };
  bool all = true;
  out = json::array();
  for (const auto& e : expectations) {
    const auto value = find(e.metric);
    std::optional<double> limit = e.value;
    if (!e.other_metric.empty()) limit = find(e.other_metric);
    bool ok = false;
    if (value && limit) {
      if (e.op == "<") ok = *value < *limit;
      if (e.op == "<=") ok = *value <= *limit;
      if (e.op == ">") ok = *value > *limit;
      if (e.op == ">=") ok = *value >= *limit;
    }
    const std::string rhs =
        e.other_metric.empty() ? fmt::format("{}", e.value.value_or(0.0)) : e.other_metric;
    json j{{"metric", e.metric},
           {"op", e.op},
           {"text", fmt::format("{} {} {}", e.metric, e.op, rhs)},
           {"passed", ok}};
    if (value) j["value"] = *value;
    if (limit) j["limit"] = *limit;
    if (!value) j["problem"] = "metric not produced by this run";
    if (value && !limit) j["problem"] = "comparison metric not produced by this run";
    out.push_back(j);
    all = all && ok;
  }
  return all;
}

std::string DerivedFirmwareConfig(const FirmwareSpec& firmware, const TimingSpec& timing) {
  YAML::Node cfg = YAML::LoadFile(firmware.config);
  if (!firmware.overrides_yaml.empty()) Merge(cfg, YAML::Load(firmware.overrides_yaml));
  if (cfg["dbc_dir"] && cfg["dbc_dir"].IsScalar()) {
    const fs::path p(cfg["dbc_dir"].Scalar());
    if (p.is_relative()) {
      cfg["dbc_dir"] = (fs::path(firmware.config).parent_path() / p).lexically_normal().string();
    }
  }
  cfg["sync"]["produce"] = false;
  cfg["sync"]["period_s"] = timing.sync_period_s;
  // A cycle closes as soon as its frames are in; the deadline only matters for lost frames. In
  // lockstep there is none: the firmware would apply it on its own clock, which is not the
  // virtual time of the frames, so whether a frame counts as in time would depend on how the
  // host scheduled the run. The next SYNC closes an incomplete cycle instead (docs/firmware.md).
  cfg["sync"]["deadline_s"] = timing.lockstep ? 0.0 : timing.sync_period_s;
  YAML::Emitter e;
  e << cfg;
  return std::string("# Derived by wheelhil run from ") + firmware.config + "\n" + e.c_str() + "\n";
}

RunResult RunScenario(const Scenario& scenario, const RunOptions& options) {
  Run run(scenario, options);
  return run.Execute();
}

}  // namespace wheelhil::emulator::scenario
