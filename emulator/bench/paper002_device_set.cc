#include "emulator/bench/paper002_device_set.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include <fmt/format.h>

#include "bus/canopen.h"
#include "bus/dbc.h"
#include "bus/dbc_codec.h"
#include "emulator/devices/can_bus_model.h"
#include "emulator/devices/canopen_encoder_node.h"
#include "emulator/devices/dbc_cia406_codec.h"
#include "emulator/sensors/accelerometer_model.h"
#include "emulator/sensors/encoder_model.h"
#include "emulator/sensors/gyro_model.h"

namespace wheelhil::emulator::bench {

using realtime::PacedFrame;

namespace {

constexpr double kWheelRadiusM = 0.05;       // scenarios/firmware/paper002_orthogonal_omni.yaml
constexpr double kAccelMountRadiusM = 0.15;  // R of eq 3
constexpr int kLinesPerRev = 1024;           // 4096 counts/rev after x4
constexpr double kGravity = 9.80665;
constexpr std::array<double, 3> kWheelAngleRad = {0.0, 2.0 * std::numbers::pi / 3.0,
                                                  4.0 * std::numbers::pi / 3.0};

/// Paper 002's experiment: 0.9 m in x, 0.1 m/s cruise, 0.5 m/s^2 ramps, then standing; the
/// profile repeats every 10 s. Returns x [m], v [m/s], a [m/s^2].
struct Motion {
  double x_m, v_m_s, a_m_s2;
};
Motion MotionAt(double t_s) {
  constexpr double kA = 0.5, kV = 0.1, kRamp = kV / kA, kCruiseEnd = 9.0, kStop = 9.2;
  const double t = std::fmod(t_s, 10.0);
  const double x_ramp = 0.5 * kA * kRamp * kRamp;
  if (t < kRamp) return {0.5 * kA * t * t, kA * t, kA};
  if (t < kCruiseEnd) return {x_ramp + kV * (t - kRamp), kV, 0.0};
  const double x_cruise = x_ramp + kV * (kCruiseEnd - kRamp);
  if (t < kStop) {
    const double d = t - kCruiseEnd;
    return {x_cruise + kV * d - 0.5 * kA * d * d, kV - kA * d, -kA};
  }
  return {x_cruise + x_ramp, 0.0, 0.0};
}

const bus::DbcSignal& NeedSignal(const bus::DbcMessage& m, const char* name,
                                 const std::string& file) {
  const bus::DbcSignal* s = m.FindSignal(name);
  if (!s)
    throw std::invalid_argument(fmt::format("{}: message {} has no signal {}", file, m.name, name));
  return *s;
}
const bus::DbcMessage& NeedMessage(const bus::DbcDatabase& db, std::uint32_t id,
                                   const std::string& file) {
  const bus::DbcMessage* m = db.FindMessage(id, false);
  if (!m) throw std::invalid_argument(fmt::format("{}: no message 0x{:X}", file, id));
  return *m;
}

}  // namespace

struct Paper002DeviceSet::Impl {
  Paper002DeviceSetOptions options;
  bus::DbcDatabase cia406_db, accel_db, imu_db;
  std::shared_ptr<const DbcCia406Codec> codec;
  std::vector<CanopenEncoderNode> nodes;
  std::vector<EncoderModel> encoders;
  std::vector<AccelerometerModel> accels;  // a1..a4
  AccelerometerModel imu_accel;
  std::array<GyroModel, 3> imu_gyros;  // x (roll), y (pitch), z (yaw)
  CanBusModel bus;
  int master_node = 0, accel_node = 0, imu_node = 0;
  std::array<int, 3> encoder_bus_nodes{};
  bus::CanFrame sync;
  const bus::DbcMessage* acc4 = nullptr;
  std::array<const bus::DbcSignal*, 4> acc4_channels{};
  const bus::DbcSignal* acc4_counter = nullptr;
  const bus::DbcSignal* acc4_checksum = nullptr;
  std::array<const bus::DbcMessage*, 3> mm5{};  // 0x174 yaw/ay, 0x178 roll/ax, 0x17C pitch/az
  std::array<const bus::DbcSignal*, 3> mm5_rate{}, mm5_accel{};
  std::int64_t cycle = 0;
  std::uint64_t problems = 0;
  unsigned accel_counter = 0;

  static AccelerometerModel MakeImuAccel(std::uint64_t seed) {
    AccelerometerParams p;
    p.rate_hz = 100.0;
    p.axes_B = {Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ()};
    p.noise_density_m_s2_sqrt_hz = 0.002;
    p.seed = seed;
    return AccelerometerModel(p);
  }
  static GyroModel MakeGyro(const Eigen::Vector3d& axis, std::uint64_t seed) {
    GyroParams p;
    p.rate_hz = 100.0;
    p.axis_B = axis;
    p.noise_density_rad_s_sqrt_hz = 1e-4;
    p.seed = seed;
    return GyroModel(p);
  }

  explicit Impl(const Paper002DeviceSetOptions& o)
      : options(o),
        imu_accel(MakeImuAccel(o.seed + 10)),
        imu_gyros{MakeGyro(Eigen::Vector3d::UnitX(), o.seed + 11),
                  MakeGyro(Eigen::Vector3d::UnitY(), o.seed + 12),
                  MakeGyro(Eigen::Vector3d::UnitZ(), o.seed + 13)},
        bus(CanBusConfig{o.bitrate_bps, StuffingMode::kExact}) {
    if (o.cycle_ns <= 0 || o.imu_every_cycles <= 0 || o.response_delay_ns < 0) {
      throw std::invalid_argument(
          "Paper002DeviceSetOptions: cycle_ns and imu_every_cycles must be > 0, "
          "response_delay_ns >= 0");
    }
    const std::string dbc_dir = o.source_dir + "/bus/dbc/";
    const std::string cia_file = dbc_dir + "cia406_encoder.dbc";
    const std::string acc_file = dbc_dir + "wheelhil_accel4.dbc";
    const std::string imu_file = dbc_dir + "bosch_mm5_10.dbc";
    cia406_db = bus::DbcDatabase::LoadFile(cia_file);
    accel_db = bus::DbcDatabase::LoadFile(acc_file);
    imu_db = bus::DbcDatabase::LoadFile(imu_file);
    codec = std::make_shared<const DbcCia406Codec>(cia406_db);

    sync = bus::EncodeMessage(NeedMessage(cia406_db, bus::canopen::kSyncCobId, cia_file), {});
    acc4 = &NeedMessage(accel_db, 0x170, acc_file);
    const char* channel_names[] = {"ACC4_A1", "ACC4_A2", "ACC4_A3", "ACC4_A4"};
    for (int i = 0; i < 4; ++i) acc4_channels[i] = &NeedSignal(*acc4, channel_names[i], acc_file);
    acc4_counter = &NeedSignal(*acc4, "ACC4_Counter", acc_file);
    acc4_checksum = &NeedSignal(*acc4, "ACC4_Checksum", acc_file);
    const std::array<std::uint32_t, 3> mm5_ids = {0x174, 0x178, 0x17C};
    const char* rate_names[] = {"MM5_YawRate", "MM5_RollRate", "MM5_PitchRate"};
    const char* accel_names[] = {"MM5_AccelY", "MM5_AccelX", "MM5_AccelZ"};
    for (int i = 0; i < 3; ++i) {
      mm5[i] = &NeedMessage(imu_db, mm5_ids[i], imu_file);
      mm5_rate[i] = &NeedSignal(*mm5[i], rate_names[i], imu_file);
      mm5_accel[i] = &NeedSignal(*mm5[i], accel_names[i], imu_file);
    }

    master_node = bus.AddNode("master");
    for (int i = 0; i < 3; ++i) {
      Cia406NodeConfig c;
      c.node_id = static_cast<std::uint8_t>(i + 1);
      c.power_on_delay_ns = 0;
      c.tpdo1_transmission_type = 1;
      c.response_delay_ns = o.response_delay_ns;
      nodes.emplace_back(c, codec, 0);
      EncoderParams e;
      e.lines_per_rev = kLinesPerRev;
      e.seed = o.seed + 20 + static_cast<std::uint64_t>(i);
      encoders.emplace_back(e);
      encoder_bus_nodes[i] = bus.AddNode(fmt::format("encoder{}", i + 1));
    }
    accel_node = bus.AddNode("accel4");
    imu_node = bus.AddNode("mm5_10");
    // Paper 002 eq 3 mounting: a1 = ax - ath R, a2 = ay + ath R, a3 = -ay + ath R, a4 = -ax - ath
    // R.
    const double r = kAccelMountRadiusM;
    const std::array<std::pair<Eigen::Vector3d, Eigen::Vector3d>, 4> mounts = {{
        {Eigen::Vector3d(0, r, 0), Eigen::Vector3d::UnitX()},
        {Eigen::Vector3d(r, 0, 0), Eigen::Vector3d::UnitY()},
        {Eigen::Vector3d(-r, 0, 0), -Eigen::Vector3d::UnitY()},
        {Eigen::Vector3d(0, -r, 0), -Eigen::Vector3d::UnitX()},
    }};
    for (int i = 0; i < 4; ++i) {
      AccelerometerParams p;
      p.rate_hz = 1e9 / static_cast<double>(o.cycle_ns);
      p.r_BP_B = mounts[i].first;
      p.axes_B = {mounts[i].second};
      p.noise_density_m_s2_sqrt_hz = 0.002;
      p.seed = o.seed + static_cast<std::uint64_t>(i);
      accels.emplace_back(p);
    }
    // Boot the encoders and start them (NMT start all) before the first cycle; these set-up
    // frames are not part of the paced stream.
    bus::CanFrame start;
    const bus::DbcMessage& nmt = NeedMessage(cia406_db, bus::canopen::kNmtCobId, cia_file);
    const double start_cs = bus::canopen::nmt::kStart;
    if (!bus::EncodeMessage(nmt, {{"NMT_CommandSpecifier", start_cs}, {"NMT_NodeId", 0.0}},
                            start)) {
      throw std::invalid_argument(cia_file + ": cannot encode NMT start");
    }
    for (auto& n : nodes) {
      n.Poll(0);
      n.OnFrame(start, 0);
      if (n.state() != CanopenEncoderNode::NmtState::kOperational) {
        throw std::invalid_argument("Paper002DeviceSet: an encoder node did not start");
      }
    }
  }

  void Enqueue(int node, const bus::CanFrame& f, std::int64_t ready_ns) {
    if (!bus.Enqueue(node, f, std::max(ready_ns, bus.now_ns()))) ++problems;
  }

  bus::CanFrame AccelFrame(const BodyKinematics& k) {
    bus::CanFrame f;
    f.id = acc4->id;
    f.len = static_cast<std::uint8_t>(acc4->length);
    const std::span<std::uint8_t> payload(f.data.data(), f.len);
    for (int i = 0; i < 4; ++i) {
      const double a = accels[i].Sample(k)[0];
      // Out-of-range readings are sent saturated (the DBC comment); that is not a problem.
      bus::EncodeSignal(*acc4_channels[i], a, payload);
    }
    bus::InsertRaw(*acc4_counter, accel_counter++ & 0xF, payload);
    std::uint8_t x = static_cast<std::uint8_t>(f.data[7] & 0x0F);
    for (int i = 0; i < 7; ++i) {
      x ^= static_cast<std::uint8_t>((f.data[i] & 0x0F) ^ (f.data[i] >> 4));
    }
    bus::InsertRaw(*acc4_checksum, x, payload);
    return f;
  }

  void ImuFrames(const BodyKinematics& k, std::int64_t t_ns) {
    const std::vector<double>& a = imu_accel.Sample(k);  // x, y, z
    const std::array<double, 3> rate_deg_s = {
        imu_gyros[2].Sample(k.omega_WB_B) * 180.0 / std::numbers::pi,
        imu_gyros[0].Sample(k.omega_WB_B) * 180.0 / std::numbers::pi,
        imu_gyros[1].Sample(k.omega_WB_B) * 180.0 / std::numbers::pi};
    const std::array<double, 3> accel_g = {a[1] / kGravity, a[0] / kGravity, a[2] / kGravity};
    for (int i = 0; i < 3; ++i) {
      bus::CanFrame f;
      f.id = mm5[i]->id;
      f.len = static_cast<std::uint8_t>(mm5[i]->length);
      const std::span<std::uint8_t> payload(f.data.data(), f.len);
      if (!bus::EncodeSignal(*mm5_rate[i], rate_deg_s[i], payload) ||
          !bus::EncodeSignal(*mm5_accel[i], accel_g[i], payload)) {
        ++problems;
      }
      Enqueue(imu_node, f, t_ns);
    }
  }

  void Append(const std::vector<WireFrame>& wires, std::vector<PacedFrame>& out) {
    for (const WireFrame& w : wires) out.push_back(PacedFrame{w.frame, w.start_ns});
  }

  void NextCycle(std::vector<PacedFrame>& out) {
    const std::int64_t t_ns = cycle * options.cycle_ns;
    const double t_s = static_cast<double>(t_ns) * 1e-9;
    const Motion m = MotionAt(t_s);
    BodyKinematics k;
    k.a_WBo_B = Eigen::Vector3d(m.a_m_s2, 0.0, 0.0);
    for (int i = 0; i < 3; ++i) {
      // Each orthogonal-wheel assembly rolls along its CCW tangent (-sin, cos).
      const double along_m = -std::sin(kWheelAngleRad[i]) * m.x_m;
      const double along_m_s = -std::sin(kWheelAngleRad[i]) * m.v_m_s;
      const std::uint32_t counts = encoders[i].Sample(along_m / kWheelRadiusM);
      const double speed =
          along_m_s / kWheelRadiusM * encoders[i].counts_per_rev() / (2.0 * std::numbers::pi);
      nodes[i].SetMeasurement(counts, speed);
      for (const NodeFrame& f : nodes[i].Poll(t_ns))
        Enqueue(encoder_bus_nodes[i], f.frame, f.due_ns);
    }
    Enqueue(master_node, sync, t_ns);
    Enqueue(accel_node, AccelFrame(k), t_ns);
    if (cycle % options.imu_every_cycles == 0) ImuFrames(k, t_ns);

    // Run the bus until the SYNC is complete; the encoders answer it then.
    const std::int64_t end_ns = t_ns + options.cycle_ns;
    std::int64_t probe_ns =
        t_ns +
        static_cast<std::int64_t>(CanFrameBits(sync, StuffingMode::kExact) - 3) * bus.bit_time_ns();
    bool sync_seen = false;
    while (!sync_seen && probe_ns < end_ns) {
      const std::vector<WireFrame> wires = bus.AdvanceTo(probe_ns);
      for (const WireFrame& w : wires) {
        if (w.node == master_node && w.frame.id == sync.id) {
          sync_seen = true;
          for (int i = 0; i < 3; ++i) {
            for (const NodeFrame& f : nodes[i].OnFrame(w.frame, w.complete_ns)) {
              Enqueue(encoder_bus_nodes[i], f.frame, f.due_ns);
            }
          }
        }
      }
      Append(wires, out);
      probe_ns += 10 * bus.bit_time_ns();
    }
    if (!sync_seen) ++problems;  // the bus was saturated for a whole cycle
    Append(bus.AdvanceTo(end_ns), out);
    ++cycle;
  }
};

Paper002DeviceSet::Paper002DeviceSet(const Paper002DeviceSetOptions& options)
    : impl_(std::make_unique<Impl>(options)) {}
Paper002DeviceSet::~Paper002DeviceSet() = default;
void Paper002DeviceSet::NextCycle(std::vector<PacedFrame>& out) { impl_->NextCycle(out); }
std::int64_t Paper002DeviceSet::cycle_ns() const noexcept { return impl_->options.cycle_ns; }
std::int64_t Paper002DeviceSet::cycles() const noexcept { return impl_->cycle; }
std::uint64_t Paper002DeviceSet::problems() const noexcept { return impl_->problems; }

}  // namespace wheelhil::emulator::bench
