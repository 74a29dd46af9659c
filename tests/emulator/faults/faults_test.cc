// Tests of emulator/faults: every fault kind is visible in the frames it should touch and
// nowhere else (a small device set run through the frame filter + CanBusModel, with and without
// the fault), same seed -> same frames, every fault recorded with its time.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <functional>
#include <map>
#include <array>
#include <memory>
#include <string>
#include <vector>

#include "bus/can_frame.h"
#include "bus/dbc.h"
#include "bus/dbc_codec.h"
#include "emulator/devices/accel4_node.h"
#include "emulator/devices/can_bus_model.h"
#include "emulator/devices/canopen_encoder_node.h"
#include "emulator/devices/dbc_cia406_codec.h"
#include "emulator/faults/bus_faults.h"
#include "emulator/faults/device_faults.h"
#include "emulator/faults/fault_event.h"
#include "emulator/faults/frame_faults.h"
#include "emulator/faults/sensor_faults.h"

namespace wheelhil::emulator {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

constexpr std::int64_t kMs = 1'000'000;
constexpr std::int64_t kStep = 100'000;  // 100 us
constexpr std::int64_t kEnd = 60 * kMs;
constexpr FaultWindow kWindow{20 * kMs, 40 * kMs};
constexpr std::int64_t kStuffTolerance = 10'000;  // 10 bit times at 1 Mbit/s

std::shared_ptr<const bus::DbcDatabase> Accel4Dbc() {
  static const auto db = std::make_shared<const bus::DbcDatabase>(
      bus::DbcDatabase::LoadFile(WHEELHIL_SOURCE_DIR "/bus/dbc/wheelhil_accel4.dbc"));
  return db;
}
const bus::DbcDatabase& CiaDbc() {
  static const bus::DbcDatabase db =
      bus::DbcDatabase::LoadFile(WHEELHIL_SOURCE_DIR "/bus/dbc/cia406_encoder.dbc");
  return db;
}

struct RunOptions {
  std::vector<FrameFault> frame;    // applied to both devices' outputs
  std::vector<DeviceFault> device;  // on the encoder node
  std::vector<BusFault> bus;
  std::uint64_t seed = 42;
};

struct RunResult {
  std::vector<WireFrame> wire;
  FaultEventLog log;
};

// The device set: paper 002's accelerometer node (0x170, 1 kHz, bus node 0) and a CiA 406
// encoder (node 1: TPDO1 0x181 every 2 ms, heartbeat 0x701 every 10 ms, bus node 1), started
// at 2 ms; 60 ms on a 1 Mbit/s bus, stepped every 100 us.
RunResult RunDevices(const RunOptions& o) {
  RunResult r;
  CanBusModel bus_model(CanBusConfig{});
  const int accel_node = bus_model.AddNode("accel4");
  const int enc_node = bus_model.AddNode("encoder1");
  FaultyCanBus bus(bus_model, o.bus, StuffingMode::kExact, &r.log);

  auto params = Paper002AccelParams(0.15, 1000.0, 3);
  for (auto& p : params) p.noise_density_m_s2_sqrt_hz = 0.01;
  Accel4Node accel(Accel4Dbc(), params, 0);

  Cia406NodeConfig cfg;
  cfg.node_id = 1;
  cfg.power_on_delay_ns = 1 * kMs;
  cfg.heartbeat_ms = 10;
  cfg.tpdo1_transmission_type = 254;
  cfg.cyclic_timer_ms = 2;
  const auto codec = std::make_shared<const DbcCia406Codec>(CiaDbc());
  CanopenEncoderNode enc(cfg, codec, 0);
  DeviceFaultInjector dev("encoder1", 1, o.device, &r.log);
  FrameFaultFilter accel_filter(o.frame, Accel4Dbc(), o.seed, &r.log);
  FrameFaultFilter enc_filter(o.frame, Accel4Dbc(), o.seed + 1, nullptr);

  bus::CanFrame nmt_start;
  EXPECT_TRUE(bus::EncodeMessage(*CiaDbc().FindMessage("NMT_Command"),
                                 {{"NMT_CommandSpecifier", 1.0}, {"NMT_NodeId", 0.0}}, nmt_start));

  auto enqueue = [&](int node, const std::vector<NodeFrame>& frames) {
    for (const NodeFrame& f : frames) {
      if (!bus.Enqueue(node, f.frame, std::max(f.due_ns, bus_model.now_ns()))) {
        // Bus-off drops are expected; nothing else may fail.
        EXPECT_FALSE(o.bus.empty()) << "enqueue failed at " << f.due_ns;
      }
    }
  };
  for (std::int64_t t = 0; t <= kEnd; t += kStep) {
    std::vector<NodeFrame> af;
    while (accel.next_sample_ns() <= t) {
      const double ts = static_cast<double>(accel.next_sample_ns()) * 1e-9;
      BodyKinematics k;
      k.a_WBo_B = {std::sin(30 * ts), 0.5 * std::cos(20 * ts), 0.0};
      k.omega_WB_B = {0, 0, 2.0 * ts};
      k.alpha_WB_B = {0, 0, 2.0};
      NodeFrame nf;
      nf.due_ns = accel.next_sample_ns();
      accel.Sample(k, nf.frame);
      af.push_back(nf);
    }
    enqueue(accel_node, accel_filter.Process(af, t));

    dev.ApplyTo(enc, cfg, codec, t);
    enc.SetMeasurement(static_cast<std::uint32_t>(t / 10'000), 100.0);
    std::vector<NodeFrame> ef = enc.Poll(t);
    if (t == 2 * kMs) {
      const std::vector<NodeFrame> answer = enc.OnFrame(nmt_start, t);
      ef.insert(ef.end(), answer.begin(), answer.end());
    }
    dev.FilterOutputs(ef);
    enqueue(enc_node, enc_filter.Process(ef, t));

    const std::vector<WireFrame> w = bus.AdvanceTo(t);
    r.wire.insert(r.wire.end(), w.begin(), w.end());
  }
  const std::vector<WireFrame> rest = bus.AdvanceTo(kEnd + 5 * kMs);
  r.wire.insert(r.wire.end(), rest.begin(), rest.end());
  return r;
}

std::vector<std::uint8_t> Bytes(const bus::CanFrame& f) {
  return {f.data.begin(), f.data.begin() + f.len};
}

// Frames of one id (error frames: id "err"), in wire order.
std::vector<WireFrame> OfId(const std::vector<WireFrame>& wire, std::uint32_t id) {
  std::vector<WireFrame> out;
  for (const WireFrame& w : wire) {
    if (!w.frame.error && w.frame.id == id) out.push_back(w);
  }
  return out;
}

std::vector<std::uint32_t> Ids(const std::vector<WireFrame>& wire) {
  std::vector<std::uint32_t> ids;
  for (const WireFrame& w : wire) {
    if (!w.frame.error) ids.push_back(w.frame.id);
  }
  std::sort(ids.begin(), ids.end());
  ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
  return ids;
}

// Every id except `targeted` carries the same frames (content and count) in both runs, each
// completing within `tolerance_ns` of its unfaulted instant.
void ExpectUntouchedExcept(const RunResult& base, const RunResult& faulted,
                           const std::vector<std::uint32_t>& targeted,
                           std::int64_t tolerance_ns = 0) {
  for (std::uint32_t id : Ids(base.wire)) {
    if (std::find(targeted.begin(), targeted.end(), id) != targeted.end()) continue;
    const auto a = OfId(base.wire, id);
    const auto b = OfId(faulted.wire, id);
    ASSERT_EQ(a.size(), b.size()) << "id 0x" << std::hex << id;
    for (std::size_t i = 0; i < a.size(); ++i) {
      EXPECT_EQ(a[i].frame, b[i].frame) << "id 0x" << std::hex << id << " #" << std::dec << i;
      EXPECT_LE(std::llabs(a[i].complete_ns - b[i].complete_ns), tolerance_ns)
          << "id 0x" << std::hex << id << " #" << std::dec << i;
    }
  }
}

// For the targeted id: frames sent (ready) outside the window are identical in content.
void ExpectSameOutsideWindow(const std::vector<WireFrame>& a, const std::vector<WireFrame>& b,
                             const FaultWindow& w) {
  std::vector<std::vector<std::uint8_t>> x, y;
  for (const WireFrame& f : a) {
    if (!w.Contains(f.ready_ns)) x.push_back(Bytes(f.frame));
  }
  for (const WireFrame& f : b) {
    if (!w.Contains(f.ready_ns)) y.push_back(Bytes(f.frame));
  }
  EXPECT_EQ(x, y);
}

std::vector<WireFrame> InWindow(const std::vector<WireFrame>& v, const FaultWindow& w) {
  std::vector<WireFrame> out;
  for (const WireFrame& f : v) {
    if (w.Contains(f.ready_ns)) out.push_back(f);
  }
  return out;
}

bool Recorded(const FaultEventLog& log, std::string_view kind, std::string_view phase,
              std::int64_t t_ns) {
  for (const FaultEvent& e : log.events()) {
    if (e.kind == kind && e.phase == phase && e.t_ns == t_ns) return true;
  }
  return false;
}

std::uint8_t NibbleXorOf15(const bus::CanFrame& f) {
  std::uint8_t x = f.data[7] & 0x0F;
  for (int i = 0; i < 7; ++i) x ^= static_cast<std::uint8_t>((f.data[i] & 0x0F) ^ (f.data[i] >> 4));
  return x;
}

const RunResult& Base() {
  static const RunResult r = RunDevices({});
  return r;
}

FrameFault AccelFault(FrameFaultKind kind) {
  FrameFault f;
  f.kind = kind;
  f.window = kWindow;
  f.id = 0x170;
  f.mask = 0x7FF;
  return f;
}

TEST(FaultHarness, BaseRunHasTheExpectedFrameSet) {
  const RunResult& b = Base();
  EXPECT_EQ(Ids(b.wire), (std::vector<std::uint32_t>{0x170, 0x181, 0x701}));
  EXPECT_EQ(OfId(b.wire, 0x170).size(), 61u);
  EXPECT_GE(OfId(b.wire, 0x181).size(), 28u);
  EXPECT_TRUE(b.log.events().empty());
}

TEST(FrameFaults, DropOnlyTouchesTheTargetedIdInTheWindowAndIsSeeded) {
  RunOptions o;
  o.frame = {AccelFault(FrameFaultKind::kDrop)};
  o.frame[0].probability = 0.5;
  const RunResult f = RunDevices(o);
  ExpectUntouchedExcept(Base(), f, {0x170}, 200'000);
  const auto a = OfId(Base().wire, 0x170), b = OfId(f.wire, 0x170);
  ExpectSameOutsideWindow(a, b, kWindow);
  const auto in_a = InWindow(a, kWindow), in_b = InWindow(b, kWindow);
  EXPECT_EQ(in_a.size(), 20u);
  EXPECT_GE(in_b.size(), 3u);
  EXPECT_LE(in_b.size(), 17u);
  // The survivors are a subsequence of the unfaulted frames.
  std::size_t j = 0;
  for (const WireFrame& w : in_b) {
    while (j < in_a.size() && !(in_a[j].frame == w.frame)) ++j;
    EXPECT_LT(j, in_a.size());
  }
  EXPECT_TRUE(Recorded(f.log, "drop", "start", 20 * kMs));
  EXPECT_TRUE(Recorded(f.log, "drop", "end", 40 * kMs));
  // Same seed -> same frames, to the ns; another seed drops other frames.
  const RunResult again = RunDevices(o);
  ASSERT_EQ(again.wire.size(), f.wire.size());
  for (std::size_t i = 0; i < f.wire.size(); ++i) {
    EXPECT_EQ(again.wire[i].frame, f.wire[i].frame);
    EXPECT_EQ(again.wire[i].complete_ns, f.wire[i].complete_ns);
  }
  o.seed = 43;
  const RunResult other = RunDevices(o);
  std::vector<std::int64_t> ta, tb;
  for (const WireFrame& w : InWindow(OfId(other.wire, 0x170), kWindow)) ta.push_back(w.ready_ns);
  for (const WireFrame& w : in_b) tb.push_back(w.ready_ns);
  EXPECT_NE(ta, tb);
}

TEST(FrameFaults, DelayShiftsOnlyTheTargetedFrames) {
  RunOptions o;
  o.frame = {AccelFault(FrameFaultKind::kDelay)};
  o.frame[0].delay_ns = 300'000;
  const RunResult f = RunDevices(o);
  ExpectUntouchedExcept(Base(), f, {0x170}, 200'000);
  const auto a = OfId(Base().wire, 0x170), b = OfId(f.wire, 0x170);
  ASSERT_EQ(a.size(), b.size());
  int delayed = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].frame, b[i].frame);
    if (kWindow.Contains(a[i].ready_ns)) {
      EXPECT_EQ(b[i].ready_ns, a[i].ready_ns + 300'000);
      ++delayed;
    } else {
      EXPECT_EQ(b[i].ready_ns, a[i].ready_ns);
    }
  }
  EXPECT_EQ(delayed, 20);
}

TEST(FrameFaults, DuplicateSendsEachWindowFrameTwice) {
  RunOptions o;
  o.frame = {AccelFault(FrameFaultKind::kDuplicate)};
  o.frame[0].delay_ns = 50'000;
  const RunResult f = RunDevices(o);
  ExpectUntouchedExcept(Base(), f, {0x170}, 300'000);
  const auto a = OfId(Base().wire, 0x170), b = OfId(f.wire, 0x170);
  ASSERT_EQ(b.size(), a.size() + 20);
  ExpectSameOutsideWindow(a, b, kWindow);
  const auto in_b = InWindow(b, kWindow);  // the 39 ms frame's copy is ready at 39.05 ms
  ASSERT_EQ(in_b.size(), 40u);
  for (std::size_t i = 0; i < in_b.size(); i += 2) {
    EXPECT_EQ(in_b[i].frame, in_b[i + 1].frame);
    EXPECT_EQ(in_b[i + 1].ready_ns, in_b[i].ready_ns + 50'000);
  }
}

TEST(FrameFaults, CorruptFlipsExactlyTheGivenBitsSeeded) {
  RunOptions o;
  o.frame = {AccelFault(FrameFaultKind::kCorrupt)};
  o.frame[0].bit_flips = 2;
  const RunResult f = RunDevices(o);
  // Changed content changes the stuff bits: frames queued behind may move by a few bit times.
  ExpectUntouchedExcept(Base(), f, {0x170}, kStuffTolerance);
  const auto a = OfId(Base().wire, 0x170), b = OfId(f.wire, 0x170);
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    int diff = 0;
    for (int k = 0; k < 8; ++k)
      diff += std::popcount(static_cast<unsigned>(a[i].frame.data[k] ^ b[i].frame.data[k]));
    EXPECT_EQ(diff, kWindow.Contains(a[i].ready_ns) ? 2 : 0) << i;
  }
  const RunResult again = RunDevices(o);
  const auto c = OfId(again.wire, 0x170);
  for (std::size_t i = 0; i < b.size(); ++i) EXPECT_EQ(b[i].frame, c[i].frame);
}

TEST(FrameFaults, WrongCounterKeepsAValidChecksum) {
  RunOptions o;
  o.frame = {AccelFault(FrameFaultKind::kWrongCounter)};
  o.frame[0].counter_signal = "ACC4_Counter";
  o.frame[0].checksum_signal = "ACC4_Checksum";
  const RunResult f = RunDevices(o);
  ExpectUntouchedExcept(Base(), f, {0x170}, kStuffTolerance);
  const auto a = OfId(Base().wire, 0x170), b = OfId(f.wire, 0x170);
  ASSERT_EQ(a.size(), b.size());
  const bus::DbcMessage& m = *Accel4Dbc()->FindMessage("ACC4_Data");
  for (std::size_t i = 0; i < a.size(); ++i) {
    const auto va = bus::DecodeMessage(m, a[i].frame), vb = bus::DecodeMessage(m, b[i].frame);
    EXPECT_EQ(vb.at("ACC4_Checksum"), NibbleXorOf15(b[i].frame));
    for (const char* ch : {"ACC4_A1", "ACC4_A2", "ACC4_A3", "ACC4_A4"})
      EXPECT_EQ(va.at(ch), vb.at(ch));
    const double want = kWindow.Contains(a[i].ready_ns)
                            ? std::fmod(va.at("ACC4_Counter") + 15.0, 16.0)
                            : va.at("ACC4_Counter");
    EXPECT_EQ(vb.at("ACC4_Counter"), want) << i;
  }
}

TEST(FrameFaults, WrongChecksumAndWrongDlc) {
  RunOptions o;
  o.frame = {AccelFault(FrameFaultKind::kWrongChecksum)};
  o.frame[0].checksum_signal = "ACC4_Checksum";
  const RunResult f = RunDevices(o);
  ExpectUntouchedExcept(Base(), f, {0x170}, kStuffTolerance);
  auto a = OfId(Base().wire, 0x170), b = OfId(f.wire, 0x170);
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    const bool in = kWindow.Contains(a[i].ready_ns);
    EXPECT_EQ(NibbleXorOf15(b[i].frame) == (b[i].frame.data[7] >> 4), !in) << i;
    EXPECT_EQ(b[i].frame.data[7] >> 4,
              in ? ((a[i].frame.data[7] >> 4) + 1) % 16 : a[i].frame.data[7] >> 4);
    for (int k = 0; k < 7; ++k) EXPECT_EQ(a[i].frame.data[k], b[i].frame.data[k]);
  }

  o.frame = {AccelFault(FrameFaultKind::kWrongDlc)};
  o.frame[0].dlc = 6;
  const RunResult g = RunDevices(o);
  ExpectUntouchedExcept(Base(), g, {0x170}, 200'000);
  b = OfId(g.wire, 0x170);
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    const bool in = kWindow.Contains(a[i].ready_ns);
    EXPECT_EQ(b[i].frame.len, in ? 6 : 8);
    for (int k = 0; k < 6; ++k) EXPECT_EQ(a[i].frame.data[k], b[i].frame.data[k]);
    EXPECT_LE(b[i].complete_ns, a[i].complete_ns);  // shorter frames finish no later
  }
}

TEST(FrameFaults, MaskSelectsARange) {
  // id 0x100 mask 0x700 selects 0x170 and 0x181 (not 0x701).
  RunOptions o;
  FrameFault d = AccelFault(FrameFaultKind::kDrop);
  d.id = 0x100;
  d.mask = 0x700;
  o.frame = {d};
  const RunResult f = RunDevices(o);
  ExpectUntouchedExcept(Base(), f, {0x170, 0x181}, 200'000);
  EXPECT_TRUE(InWindow(OfId(f.wire, 0x170), kWindow).empty());
  EXPECT_TRUE(InWindow(OfId(f.wire, 0x181), kWindow).empty());
  EXPECT_FALSE(InWindow(OfId(Base().wire, 0x181), kWindow).empty());
}

TEST(DeviceFaults, SilentAndHeartbeatLost) {
  RunOptions o;
  o.device = {{DeviceFaultKind::kSilent, kWindow}};
  RunResult f = RunDevices(o);
  ExpectUntouchedExcept(Base(), f, {0x181, 0x701}, 200'000);
  for (std::uint32_t id : {0x181u, 0x701u}) {
    EXPECT_TRUE(InWindow(OfId(f.wire, id), kWindow).empty());
    EXPECT_FALSE(InWindow(OfId(Base().wire, id), kWindow).empty());
    ExpectSameOutsideWindow(OfId(Base().wire, id), OfId(f.wire, id), kWindow);
  }
  EXPECT_TRUE(Recorded(f.log, "silent", "start", 20 * kMs));
  EXPECT_TRUE(Recorded(f.log, "silent", "end", 40 * kMs));

  o.device = {{DeviceFaultKind::kHeartbeatLost, kWindow}};
  f = RunDevices(o);
  ExpectUntouchedExcept(Base(), f, {0x701});
  EXPECT_EQ(InWindow(OfId(Base().wire, 0x701), kWindow).size(), 2u);
  EXPECT_TRUE(InWindow(OfId(f.wire, 0x701), kWindow).empty());
  ExpectSameOutsideWindow(OfId(Base().wire, 0x701), OfId(f.wire, 0x701), kWindow);
}

TEST(DeviceFaults, RebootBootsUpAgainInPreOperational) {
  RunOptions o;
  o.device = {{DeviceFaultKind::kReboot, {20 * kMs, 25 * kMs}}};
  const RunResult f = RunDevices(o);
  ExpectUntouchedExcept(Base(), f, {0x181, 0x701});
  const FaultWindow before{0, 20 * kMs};
  for (std::uint32_t id : {0x181u, 0x701u}) {
    const auto a = InWindow(OfId(Base().wire, id), before);
    const auto b = InWindow(OfId(f.wire, id), before);
    ASSERT_EQ(a.size(), b.size());
  }
  // Off until power-on at 25 ms, boot-up after the 1 ms power-on delay, then pre-operational
  // heartbeats every 10 ms and no TPDO (nobody sent NMT start again).
  std::vector<std::pair<std::int64_t, std::uint8_t>> hb;
  for (const WireFrame& w : OfId(f.wire, 0x701)) {
    if (w.ready_ns >= 20 * kMs) hb.emplace_back(w.ready_ns, w.frame.data[0]);
  }
  const std::vector<std::pair<std::int64_t, std::uint8_t>> want = {
      {26 * kMs, 0x00}, {36 * kMs, 0x7F}, {46 * kMs, 0x7F}, {56 * kMs, 0x7F}};
  EXPECT_EQ(hb, want);
  EXPECT_TRUE(InWindow(OfId(f.wire, 0x181), {20 * kMs, kEnd + 1}).empty());
  EXPECT_TRUE(Recorded(f.log, "reboot", "start", 20 * kMs));
  EXPECT_TRUE(Recorded(f.log, "reboot", "end", 25 * kMs));
}

TEST(DeviceFaults, EmcyRaisedAndCleared) {
  RunOptions o;
  o.device = {{DeviceFaultKind::kEmcy, {20 * kMs, 30 * kMs}, 0x7305, 0x80}};
  const RunResult f = RunDevices(o);
  ExpectUntouchedExcept(Base(), f, {0x081}, 200'000);
  const auto e = OfId(f.wire, 0x081);
  ASSERT_EQ(e.size(), 2u);
  EXPECT_EQ(e[0].ready_ns, 20 * kMs);
  EXPECT_EQ(Bytes(e[0].frame), (std::vector<std::uint8_t>{0x05, 0x73, 0x81, 0, 0, 0, 0, 0}));
  EXPECT_EQ(e[1].ready_ns, 30 * kMs);
  EXPECT_EQ(Bytes(e[1].frame), (std::vector<std::uint8_t>{0, 0, 0, 0, 0, 0, 0, 0}));
  EXPECT_TRUE(Recorded(f.log, "emcy", "start", 20 * kMs));
  EXPECT_TRUE(Recorded(f.log, "emcy", "end", 30 * kMs));
}

TEST(BusFaults, ErrorBurstDelaysButChangesNoFrame) {
  RunOptions o;
  BusFault b;
  b.kind = BusFaultKind::kErrorBurst;
  b.window = {20 * kMs + 30'000, 21 * kMs};
  b.error_frames = 5;
  o.bus = {b};
  const RunResult f = RunDevices(o);
  ExpectUntouchedExcept(Base(), f, {}, 500'000);
  std::vector<WireFrame> errors;
  for (const WireFrame& w : f.wire) {
    if (w.frame.error) errors.push_back(w);
  }
  ASSERT_EQ(errors.size(), 5u);
  for (const WireFrame& w : errors) {
    EXPECT_EQ(w.frame.id, kCanErrProt | kCanErrBusError);
    EXPECT_GE(w.start_ns, 20 * kMs + 30'000);
    EXPECT_LT(w.complete_ns, 21 * kMs);
  }
  // Each error frame holds the bus as long as a zero-length id-0 frame (docs/faults.md).
  EXPECT_EQ(errors[0].bits, CanFrameBits(bus::CanFrame{}, StuffingMode::kExact));
  RecordProperty("error_frame_bits", static_cast<int>(errors[0].bits));
  // Back to back: the burst holds the bus.
  for (std::size_t i = 1; i < errors.size(); ++i) {
    EXPECT_EQ(errors[i].start_ns, errors[i - 1].start_ns + errors[i - 1].bits * 1000);
  }
  EXPECT_TRUE(Recorded(f.log, "error_burst", "start", 20 * kMs + 30'000));
}

TEST(BusFaults, BusOffSilencesOneNode) {
  RunOptions o;
  BusFault b;
  b.kind = BusFaultKind::kBusOff;
  b.window = kWindow;
  b.node = 1;  // encoder
  b.node_name = "encoder1";
  o.bus = {b};
  const RunResult f = RunDevices(o);
  ExpectUntouchedExcept(Base(), f, {0x181, 0x701}, 200'000);
  for (std::uint32_t id : {0x181u, 0x701u}) {
    EXPECT_TRUE(InWindow(OfId(f.wire, id), kWindow).empty());
    ExpectSameOutsideWindow(OfId(Base().wire, id), OfId(f.wire, id), kWindow);
  }
  EXPECT_TRUE(Recorded(f.log, "bus_off", "start", 20 * kMs));
}

TEST(BusFaults, FloodAtTheGivenLoad) {
  RunOptions o;
  BusFault b;
  b.kind = BusFaultKind::kFlood;
  b.window = kWindow;
  b.load = 0.4;
  o.bus = {b};
  const RunResult f = RunDevices(o);
  ExpectUntouchedExcept(Base(), f, {0x001}, 300'000);
  const auto flood = OfId(f.wire, 0x001);
  ASSERT_FALSE(flood.empty());
  std::int64_t busy = 0;
  for (const WireFrame& w : flood) {
    EXPECT_TRUE(kWindow.Contains(w.ready_ns));
    EXPECT_EQ(w.frame.len, 8);
    busy += w.bits * 1000;  // 1 Mbit/s
  }
  const double load = static_cast<double>(busy) / static_cast<double>(20 * kMs);
  EXPECT_NEAR(load, 0.4, 0.01);
  RecordProperty("flood_load_x1e4", static_cast<int>(std::lround(load * 1e4)));
  RecordProperty("flood_frames", static_cast<int>(flood.size()));
  EXPECT_TRUE(Recorded(f.log, "flood", "start", 20 * kMs));
  EXPECT_TRUE(Recorded(f.log, "flood", "end", 40 * kMs));
}

TEST(SensorFaults, EachKindModifiesOnlyItsWindow) {
  const FaultWindow w{10, 20};
  auto run = [&](SensorFault f, double nominal_noise = 0.0) {
    f.window = w;
    FaultEventLog log;
    SensorFaultInjector inj("gyro_z", {f}, nominal_noise, 9, &log);
    std::vector<std::optional<double>> out;
    for (std::int64_t t = 0; t < 30; ++t) out.push_back(inj.Apply(0.1 * static_cast<double>(t), t));
    EXPECT_TRUE(Recorded(log, SensorFaultKindName(f.kind), "start", 10));
    EXPECT_TRUE(Recorded(log, SensorFaultKindName(f.kind), "end", 20));
    for (std::int64_t t = 0; t < 30; ++t) {
      if (!w.Contains(t)) {
        EXPECT_EQ(out[t], 0.1 * static_cast<double>(t)) << t;
      }
    }
    return out;
  };
  auto v = run({SensorFaultKind::kBiasStep, {}, 0.5});
  for (int t = 10; t < 20; ++t) EXPECT_DOUBLE_EQ(*v[t], 0.1 * t + 0.5);
  v = run({SensorFaultKind::kDriftRamp, {}, 2e8});  // 2e8 units/s = 0.2 per ns
  for (int t = 10; t < 20; ++t) EXPECT_NEAR(*v[t], 0.1 * t + 0.2 * (t - 10), 1e-12);
  v = run({SensorFaultKind::kStuck, {}, 0.0});
  for (int t = 10; t < 20; ++t) EXPECT_DOUBLE_EQ(*v[t], 1.0);
  v = run({SensorFaultKind::kDropout, {}, 0.0});
  for (int t = 10; t < 20; ++t) EXPECT_FALSE(v[t].has_value());
  v = run({SensorFaultKind::kSaturation, {}, 1.25});
  for (int t = 10; t < 20; ++t) EXPECT_DOUBLE_EQ(*v[t], std::min(0.1 * t, 1.25));
}

TEST(SensorFaults, NoiseScaleGivesKTimesTheNoise) {
  // Nominal noise 0.2 per sample, k = 3: the added noise has std 0.2 * sqrt(8).
  SensorFaultInjector inj("accel1", {{SensorFaultKind::kNoiseScale, {0, 20000}, 3.0}}, 0.2, 5);
  double s = 0, s2 = 0;
  const int n = 20000;
  for (int t = 0; t < n; ++t) {
    const double x = *inj.Apply(0.0, t);
    s += x;
    s2 += x * x;
  }
  const double sd = std::sqrt(s2 / n - (s / n) * (s / n));
  EXPECT_NEAR(sd, 0.2 * std::sqrt(8.0), 0.2 * std::sqrt(8.0) * 0.03);
  SensorFaultInjector a("a", {{SensorFaultKind::kNoiseScale, {0, 100}, 2.0}}, 1.0, 77);
  SensorFaultInjector b("a", {{SensorFaultKind::kNoiseScale, {0, 100}, 2.0}}, 1.0, 77);
  for (int t = 0; t < 100; ++t) EXPECT_EQ(*a.Apply(1.0, t), *b.Apply(1.0, t));
}

TEST(SensorFaults, MissedCountsAreLostForGoodAndWrap) {
  SensorFaultInjector inj("encoder1", {{SensorFaultKind::kMissedCounts, {100, 200}, 0.25}}, 0.0,
                          11);
  // 16-bit counter counting 40 per sample from near the wrap.
  std::uint32_t truth = 65000;
  std::uint32_t out = 0;
  for (std::int64_t t = 0; t < 300; t += 1) {
    out = *inj.ApplyCounts(truth, t, 16);
    if (t < 100) {
      EXPECT_EQ(out, truth);
    }
    truth = (truth + 40) & 0xFFFF;
  }
  const std::int64_t lost = inj.missed_counts();
  EXPECT_NEAR(static_cast<double>(lost), 0.25 * 40 * 100, 150.0);
  // After the window the counter keeps its deficit.
  const std::uint32_t last_truth = (truth - 40) & 0xFFFF;
  EXPECT_EQ(out, (last_truth - static_cast<std::uint32_t>(lost)) & 0xFFFF);
  // Bias on counts, wrapping below zero of a 16-bit register.
  SensorFaultInjector bias("encoder2", {{SensorFaultKind::kBiasStep, {0}, -3.0}}, 0.0, 1);
  EXPECT_EQ(*bias.ApplyCounts(1, 0, 16), 0xFFFEu);
}

TEST(SensorFaults, ChannelsAreFaultedTogetherAndADropDropsTheSample) {
  std::array<std::unique_ptr<SensorFaultInjector>, 3> faults;
  faults[0] = std::make_unique<SensorFaultInjector>(
      "a", std::vector<SensorFault>{{SensorFaultKind::kBiasStep, {0, 10}, -1.0},
                                    {SensorFaultKind::kDropout, {5, 10}, 0.0}},
      0.0, 1);
  faults[2] = std::make_unique<SensorFaultInjector>(
      "c", std::vector<SensorFault>{{SensorFaultKind::kBiasStep, {0}, 0.5}}, 0.0, 2);
  std::array<double, 3> v{1.0, 2.0, 3.0};
  EXPECT_TRUE(ApplyToChannels(faults, v, 0));
  EXPECT_THAT(v, ::testing::ElementsAre(0.0, 2.0, 3.5));
  // Channel a drops: the sample is lost, and the channels after it are still faulted.
  v = {1.0, 2.0, 3.0};
  EXPECT_FALSE(ApplyToChannels(faults, v, 6));
  EXPECT_DOUBLE_EQ(v[1], 2.0);
  EXPECT_DOUBLE_EQ(v[2], 3.5);
}

TEST(SensorFaults, LoadErrorsNameTheField) {
  EXPECT_THAT(
      [] {
        SensorFaultInjector("g", {{SensorFaultKind::kNoiseScale, {0, 10}, 0.5}}, 0.1, 1);
      },
      ThrowsMessage<std::invalid_argument>(HasSubstr("sensor_faults[0].value")));
  EXPECT_THAT(
      [] {
        SensorFaultInjector("g", {{SensorFaultKind::kBiasStep, {10, 5}, 1.0}}, 0.1, 1);
      },
      ThrowsMessage<std::invalid_argument>(HasSubstr("sensor_faults[0].window")));
  EXPECT_THAT(
      [] {
        FrameFault f;
        f.kind = FrameFaultKind::kWrongCounter;
        FrameFaultFilter({f}, nullptr, 1);
      },
      ThrowsMessage<std::invalid_argument>(HasSubstr("frame_faults[0].counter_signal")));
  EXPECT_THAT(
      [] {
        DeviceFaultInjector("enc", 1, {{DeviceFaultKind::kReboot, {5}}});
      },
      ThrowsMessage<std::invalid_argument>(HasSubstr("needs an end")));
  EXPECT_EQ(ParseSensorFaultKind("missed_counts"), SensorFaultKind::kMissedCounts);
  EXPECT_EQ(ParseFrameFaultKind("wrong_dlc"), FrameFaultKind::kWrongDlc);
  EXPECT_EQ(ParseDeviceFaultKind("heartbeat_lost"), DeviceFaultKind::kHeartbeatLost);
  EXPECT_EQ(ParseBusFaultKind("flood"), BusFaultKind::kFlood);
  EXPECT_EQ(ParseBusFaultKind("fire"), std::nullopt);
}

TEST(FaultEventLog, JsonLines) {
  FaultEvent e{1'500'000, "frame", "drop", "start", "id 0x170 mask 0x7FF", "p=\"0.5\""};
  EXPECT_EQ(
      FaultEventJson(e),
      R"({"t_ns":1500000,"t_s":0.001500000,"category":"frame","kind":"drop","phase":"start","target":"id 0x170 mask 0x7FF","detail":"p=\"0.5\""})");
  FaultEventLog log;
  log.Record({5, "bus", "flood", "start", "", ""});
  log.Record({2, "bus", "flood", "end", "", ""});
  EXPECT_EQ(log.SortedByTime().front().t_ns, 2);
}

}  // namespace
}  // namespace wheelhil::emulator
