// Tests of emulator/devices/accel4_node.h, dbc_imu_node.h and frame_checksum.h.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <map>
#include <memory>
#include <numbers>
#include <string>
#include <vector>

#include "bus/dbc.h"
#include "bus/dbc_codec.h"
#include "emulator/devices/accel4_node.h"
#include "emulator/devices/dbc_imu_node.h"
#include "emulator/devices/frame_checksum.h"
#include "emulator/faults/frame_faults.h"
#include "emulator/sensors/accelerometer_model.h"

namespace wheelhil::emulator {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

std::shared_ptr<const bus::DbcDatabase> Accel4Dbc() {
  return std::make_shared<const bus::DbcDatabase>(
      bus::DbcDatabase::LoadFile(WHEELHIL_SOURCE_DIR "/bus/dbc/wheelhil_accel4.dbc"));
}

std::uint8_t NibbleXorOf15(const bus::CanFrame& f) {
  std::uint8_t x = f.data[7] & 0x0F;
  for (int i = 0; i < 7; ++i) x ^= static_cast<std::uint8_t>((f.data[i] & 0x0F) ^ (f.data[i] >> 4));
  return x;
}

TEST(FrameChecksum, Crc8SaeJ1850CheckValue) {
  const std::string s = "123456789";
  const std::vector<std::uint8_t> bytes(s.begin(), s.end());
  EXPECT_EQ(Crc8SaeJ1850(bytes), 0x4B);
  EXPECT_EQ(ParseChecksumKind("crc8_sae_j1850"), ChecksumKind::kCrc8SaeJ1850);
  EXPECT_EQ(ParseChecksumKind("md5"), std::nullopt);
}

// The CRC engine against the reveng catalogue's check values of "123456789" (reflected and
// 32-bit models included) and the examples of AUTOSAR's CRC library specification
// (SWS_CrcLibrary, CRC-8 SAE J1850 and CRC-8H2F tables).
TEST(FrameChecksum, CrcPresetsMatchPublishedCheckValues) {
  const std::string s = "123456789";
  const std::vector<std::uint8_t> check(s.begin(), s.end());
  EXPECT_EQ(Crc(kCrc8SaeJ1850Params, check), 0x4Bu);
  EXPECT_EQ(Crc(kCrc8H2FParams, check), 0xDFu);
  EXPECT_EQ(Crc(kCrc16CcittFalseParams, check), 0x29B1u);
  EXPECT_EQ(Crc(CrcParams{16, 0x1021, 0x0000, true, true, 0x0000}, check), 0x2189u);  // KERMIT
  EXPECT_EQ(Crc(CrcParams{32, 0x04C11DB7, 0xFFFFFFFF, true, true, 0xFFFFFFFF}, check),
            0xCBF43926u);  // CRC-32/ISO-HDLC
  struct Example {
    std::vector<std::uint8_t> data;
    std::uint32_t j1850, h2f;
  };
  const Example autosar[] = {
      {{0x00, 0x00, 0x00, 0x00}, 0x59, 0x12},
      {{0xF2, 0x01, 0x83}, 0x37, 0xC2},
      {{0x0F, 0xAA, 0x00, 0x55}, 0x79, 0xC6},
      {{0x00, 0xFF, 0x55, 0x11}, 0xB8, 0x77},
      {{0x33, 0x22, 0x55, 0xAA, 0xBB, 0xCC, 0xDD, 0xEE, 0xFF}, 0xCB, 0x11},
      {{0x92, 0x6B, 0x55}, 0x8C, 0x33},
      {{0xFF, 0xFF, 0xFF, 0xFF}, 0x74, 0x6C},
  };
  for (const Example& e : autosar) {
    EXPECT_EQ(Crc(kCrc8SaeJ1850Params, e.data), e.j1850);
    EXPECT_EQ(Crc8SaeJ1850(e.data), e.j1850);
    EXPECT_EQ(Crc(kCrc8H2FParams, e.data), e.h2f);
  }
  EXPECT_EQ(ParseChecksumKind("crc8_h2f"), ChecksumKind::kCrc8H2F);
  EXPECT_EQ(ParseChecksumKind("crc16_ccitt"), ChecksumKind::kCrc16Ccitt);
}

// AUTOSAR E2E profiles 11 and 22 against the test vectors of the autosar-e2e library
// (zariiii9003/autosar-e2e test_p11.py, and test_p02.py for profile 2, whose CRC profile 22
// keeps): CRC in byte 0, counter in the low nibble of byte 1.
TEST(FrameChecksum, E2eProfilesMatchPublishedVectors) {
  auto signal = [](int start_bit) {
    bus::DbcSignal s;
    s.name = "CRC";
    s.start_bit = start_bit;
    s.length = 8;
    return s;
  };
  const bus::DbcSignal crc = signal(0);
  auto compute = [&](const ChecksumSpec& spec, std::vector<std::uint8_t> data) {
    return ComputeChecksum(spec, crc, data);
  };
  ChecksumSpec p11;
  p11.kind = ChecksumKind::kE2eP11;
  p11.data_id = 0x123;
  EXPECT_EQ(compute(p11, {0, 0x00, 0, 0, 0, 0, 0, 0}), 0xCCu);
  EXPECT_EQ(compute(p11, {0, 0x01, 0, 0, 0, 0, 0, 0}), 0x91u);
  p11.data_id_nibble = true;  // the id's bits 8..11 ride in byte 1's high nibble
  EXPECT_EQ(compute(p11, {0, 0x10, 0, 0, 0, 0, 0, 0}), 0x2Au);
  EXPECT_EQ(compute(p11, {0, 0x11, 0, 0, 0, 0, 0, 0}), 0x77u);
  ChecksumSpec p22;
  p22.kind = ChecksumKind::kE2eP22;
  EXPECT_EQ(compute(p22, {0, 0x01, 0, 0, 0, 0, 0, 0}), 0x45u);
  for (std::uint8_t i = 0; i < 16; ++i) p22.data_id_list[i] = i;
  EXPECT_EQ(compute(p22, {0, 2, 2, 3, 4, 5, 6, 7}), 0xBCu);
  EXPECT_EQ(compute(p22, {0, 1, 2, 3, 4, 5, 6, 7}), 0x61u);
  // The CRC byte itself is left out, so whatever it holds the result is the same; written, it
  // checks.
  std::vector<std::uint8_t> frame{0x5A, 1, 2, 3, 4, 5, 6, 7};
  EXPECT_EQ(compute(p22, frame), 0x61u);
  ASSERT_TRUE(WriteChecksum(p22, crc, frame));
  EXPECT_EQ(frame[0], 0x61);
  // An E2E CRC sits on a byte boundary and needs its counter byte.
  EXPECT_FALSE(ChecksumFits(ChecksumKind::kE2eP11, signal(4)));
  EXPECT_EQ(compute(p11, {0}), 0u);
}

// A custom CRC (the Rocksoft model): CRC-8/MAXIM-DOW (reflected, 0x31) and CRC-16/KERMIT as a
// scenario would declare them reproduce reveng's check values over "123456789" placed before a
// zeroed checksum field.
TEST(FrameChecksum, CustomCrcOverTheZeroedPayload) {
  bus::DbcSignal sig;
  sig.name = "C";
  sig.start_bit = 72;
  sig.length = 8;
  std::vector<std::uint8_t> payload{'1', '2', '3', '4', '5', '6', '7', '8', '9', 0xEE};
  ChecksumSpec maxim;
  maxim.kind = ChecksumKind::kCrcCustom;
  maxim.crc = CrcParams{8, 0x31, 0x00, true, true, 0x00};
  // Over the ten bytes with the last zeroed: the check value's CRC continued by one zero byte.
  const std::vector<std::uint8_t> with_zero{'1', '2', '3', '4', '5', '6', '7', '8', '9', 0};
  EXPECT_EQ(Crc(maxim.crc, std::span<const std::uint8_t>(with_zero.data(), 9)), 0xA1u);
  EXPECT_EQ(ComputeChecksum(maxim, sig, payload), Crc(maxim.crc, with_zero));
  ASSERT_TRUE(WriteChecksum(maxim, sig, payload));
  EXPECT_EQ(payload[9], Crc(maxim.crc, with_zero));
  maxim.crc.width = 16;  // no longer the signal's width
  EXPECT_FALSE(WriteChecksum(maxim, sig, payload));
  bus::DbcMessage msg;
  msg.name = "M";
  msg.length = 10;
  EXPECT_EQ(WhyChecksumDoesNotFit(maxim, sig, msg), "C has 8 bits, the crc 16");
}

// A spinning, accelerating, slightly tilted body: every frame decodes (through the DBC) to the
// analytic specific force along each sensor axis within half a quantisation step.
TEST(Accel4Node, FramesDecodeToSpecificForceWithinQuantisation) {
  const auto dbc = Accel4Dbc();
  const double R = 0.15;
  Accel4Node node(dbc, Paper002AccelParams(R, 1000.0, 7), 0);
  EXPECT_EQ(node.period_ns(), 1'000'000);
  const bus::DbcMessage& msg = node.message();
  EXPECT_EQ(msg.id, 0x170u);
  const double lsb = msg.FindSignal("ACC4_A1")->factor;
  const auto params = Paper002AccelParams(R, 1000.0, 7);
  for (int k = 0; k < 40; ++k) {
    const double t = 1e-3 * k;
    BodyKinematics kin;
    kin.a_WBo_B = {1.2 * std::cos(5 * t), -0.7 + t, 0.1};
    kin.omega_WB_B = {0.0, 0.0, 3.0 + 5.0 * t};
    kin.alpha_WB_B = {0.0, 0.0, 5.0};
    kin.g_B = {0.3, 0.0, -9.8};
    EXPECT_EQ(node.next_sample_ns(), static_cast<std::int64_t>(k) * 1'000'000);
    bus::CanFrame f;
    ASSERT_TRUE(node.Sample(kin, f));
    ASSERT_EQ(f.len, 8);
    const bus::SignalValues v = bus::DecodeMessage(msg, f);
    const char* names[] = {"ACC4_A1", "ACC4_A2", "ACC4_A3", "ACC4_A4"};
    for (int i = 0; i < 4; ++i) {
      const Eigen::Vector3d f_B = SpecificForceAt(kin, params[i].r_BP_B);
      const double expected = params[i].axes_B[0].dot(f_B);
      EXPECT_NEAR(v.at(names[i]), expected, 0.5 * lsb + 1e-9) << "channel " << i + 1 << " k " << k;
    }
    // Paper 002 eq. 3 (tangential terms) + the centripetal terms the sensors really see.
    const double w2 = kin.omega_WB_B.z() * kin.omega_WB_B.z();
    const double ax = kin.a_WBo_B.x() - kin.g_B.x(), ay = kin.a_WBo_B.y() - kin.g_B.y();
    EXPECT_NEAR(v.at("ACC4_A1"), ax - 5.0 * R, 0.5 * lsb + 1e-9);  // r = (0, R): no x centripetal
    EXPECT_NEAR(v.at("ACC4_A2"), ay + 5.0 * R, 0.5 * lsb + 1e-9);
    EXPECT_NEAR(v.at("ACC4_A3"), -ay + 5.0 * R, 0.5 * lsb + 1e-9);
    EXPECT_NEAR(v.at("ACC4_A4"), -ax - 5.0 * R, 0.5 * lsb + 1e-9);
    (void)w2;
    EXPECT_EQ(v.at("ACC4_Counter"), k % 16);
    EXPECT_EQ(v.at("ACC4_Checksum"), NibbleXorOf15(f));
  }
  EXPECT_EQ(node.samples(), 40u);
  EXPECT_EQ(node.saturated(), 0u);
}

TEST(Accel4Node, OutOfRangeReadingsAreSentSaturated) {
  Accel4Node node(Accel4Dbc(), Paper002AccelParams(0.15, 1000.0, 1), 5);
  bus::CanFrame f;
  EXPECT_FALSE(node.EncodeSample({100.0, -100.0, 0.0, 1.0}, f));
  std::uint64_t raw = 0;
  ASSERT_TRUE(bus::ExtractRaw(*node.message().FindSignal("ACC4_A1"), f.payload(), raw));
  EXPECT_EQ(raw, 8191u);
  ASSERT_TRUE(bus::ExtractRaw(*node.message().FindSignal("ACC4_A2"), f.payload(), raw));
  EXPECT_EQ(raw, 0x2000u);  // -8192 in 14 bits
  EXPECT_EQ(node.saturated(), 1u);
  EXPECT_EQ(node.next_sample_ns(), 5 + 1'000'000);
}

TEST(Accel4Node, RejectsBadConfiguration) {
  auto p = Paper002AccelParams(0.15, 1000.0, 1);
  p[2].rate_hz = 500.0;
  EXPECT_THAT([&] { Accel4Node(Accel4Dbc(), p, 0); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("sensors[2].rate_hz")));
  p = Paper002AccelParams(0.15, 1000.0, 1);
  p[1].axes_B.push_back(Eigen::Vector3d::UnitZ());
  EXPECT_THAT([&] { Accel4Node(Accel4Dbc(), p, 0); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("sensors[1].axes")));
  const auto other = std::make_shared<const bus::DbcDatabase>(
      bus::DbcDatabase::LoadFile(WHEELHIL_SOURCE_DIR "/bus/dbc/bosch_mm5_10.dbc"));
  EXPECT_THAT([&] { Accel4Node(other, Paper002AccelParams(0.15, 1000.0, 1), 0); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("ACC4_Data")));
}

// A user's IMU, written here: rates in deg/s (Intel) with an 8-bit counter and CRC-8 every
// 10 ms; accelerations in m/s^2 and g (Motorola) with a 4-bit counter and a byte sum every
// 20 ms; a z rate in rad/s with a 4-bit counter and a nibble XOR every 5 ms.
constexpr char kUserImuDbc[] = R"(VERSION ""
NS_ :
BS_:
BU_: Imu Fw
BO_ 1280 IMU_Rates: 8 Imu
 SG_ IMU_RateX : 0|16@1- (0.01,0) [-327.68|327.67] "deg/s" Fw
 SG_ IMU_RateY : 16|16@1- (0.01,0) [-327.68|327.67] "deg/s" Fw
 SG_ IMU_RateZ : 32|16@1- (0.01,0) [-327.68|327.67] "deg/s" Fw
 SG_ IMU_Counter : 48|8@1+ (1,0) [0|255] "" Fw
 SG_ IMU_Crc : 56|8@1+ (1,0) [0|255] "" Fw
BO_ 1281 IMU_Accel: 8 Imu
 SG_ IMU_AccX : 7|16@0- (0.001,0) [-32.768|32.767] "m/s^2" Fw
 SG_ IMU_AccY : 23|16@0- (0.001,0) [-32.768|32.767] "m/s^2" Fw
 SG_ IMU_AccZ : 39|16@0- (0.0001,0) [-3.2768|3.2767] "g" Fw
 SG_ IMU_Cnt : 48|4@1+ (1,0) [0|15] "" Fw
 SG_ IMU_Sum : 56|8@1+ (1,0) [0|255] "" Fw
BO_ 1282 IMU_RadRateZ: 8 Imu
 SG_ RR_Z : 0|32@1- (1E-006,0) [-2147|2147] "rad/s" Fw
 SG_ RR_Cnt : 32|4@1+ (1,0) [0|15] "" Fw
 SG_ RR_Xor : 36|4@1+ (1,0) [0|15] "" Fw
BO_ 1283 IMU_NoCycle: 2 Imu
 SG_ NC_RateZ : 0|16@1- (0.01,0) [-327.68|327.67] "deg/s" Fw
BA_DEF_ BO_ "GenMsgCycleTime" INT 0 65535;
BA_DEF_DEF_ "GenMsgCycleTime" 0;
BA_ "GenMsgCycleTime" BO_ 1280 10;
BA_ "GenMsgCycleTime" BO_ 1281 20;
BA_ "GenMsgCycleTime" BO_ 1282 5;
)";

std::shared_ptr<const bus::DbcDatabase> UserImuDbc() {
  return std::make_shared<const bus::DbcDatabase>(
      bus::DbcDatabase::Parse(kUserImuDbc, "user_imu.dbc"));
}

DbcImuConfig UserImuConfig() {
  DbcImuConfig c;
  c.channels = {
      {ImuQuantity::kRateX, "IMU_Rates", "IMU_RateX"},
      {ImuQuantity::kRateY, "IMU_Rates", "IMU_RateY"},
      {ImuQuantity::kRateZ, "IMU_Rates", "IMU_RateZ"},
      {ImuQuantity::kAccelX, "IMU_Accel", "IMU_AccX"},
      {ImuQuantity::kAccelY, "IMU_Accel", "IMU_AccY"},
      {ImuQuantity::kAccelZ, "IMU_Accel", "IMU_AccZ"},
      {ImuQuantity::kRateZ, "IMU_RadRateZ", "RR_Z"},
  };
  c.message_options = {
      {"IMU_Rates", "IMU_Counter", "IMU_Crc", ChecksumKind::kCrc8SaeJ1850},
      {"IMU_Accel", "IMU_Cnt", "IMU_Sum", ChecksumKind::kSum},
      {"IMU_RadRateZ", "RR_Cnt", "RR_Xor", ChecksumKind::kXor},
  };
  return c;
}

TEST(DbcImuNode, InlineDbcFramesCarryTheQuantitiesInTheDbcUnits) {
  const auto dbc = UserImuDbc();
  DbcImuNode node(dbc, UserImuConfig(), 1'000);
  ASSERT_EQ(node.message_count(), 3u);
  EXPECT_EQ(node.period_ns(0), 10'000'000);
  EXPECT_EQ(node.period_ns(1), 20'000'000);
  EXPECT_EQ(node.period_ns(2), 5'000'000);
  std::map<std::uint32_t, std::vector<std::int64_t>> instants;
  std::map<std::uint32_t, int> counter;
  constexpr double kDeg = 180.0 / std::numbers::pi;
  for (std::int64_t t = node.NextEventNs(); t <= 100'000'000; t = node.NextEventNs()) {
    const double ts = static_cast<double>(t) * 1e-9;
    ImuSample s;
    s.rate_rad_s = {0.5 * std::sin(ts * 20), -0.25, 1.0 + ts};
    s.accel_m_s2 = {3.0 * ts, -1.5, 9.80665 * (1.0 + ts)};
    const std::vector<NodeFrame> frames = node.Poll(t, s);
    ASSERT_FALSE(frames.empty());
    for (const NodeFrame& nf : frames) {
      EXPECT_EQ(nf.due_ns, t);
      const bus::CanFrame& f = nf.frame;
      instants[f.id].push_back(nf.due_ns);
      const bus::DbcMessage* msg = dbc->FindMessage(f.id, false);
      ASSERT_NE(msg, nullptr);
      const bus::SignalValues v = bus::DecodeMessage(*msg, f);
      const int n = counter[f.id]++;
      if (f.id == 1280) {
        EXPECT_NEAR(v.at("IMU_RateX"), s.rate_rad_s.x() * kDeg, 0.005 + 1e-9);
        EXPECT_NEAR(v.at("IMU_RateY"), s.rate_rad_s.y() * kDeg, 0.005 + 1e-9);
        EXPECT_NEAR(v.at("IMU_RateZ"), s.rate_rad_s.z() * kDeg, 0.005 + 1e-9);
        EXPECT_EQ(v.at("IMU_Counter"), n % 256);
        std::array<std::uint8_t, 7> b{};
        std::copy(f.data.begin(), f.data.begin() + 7, b.begin());
        std::array<std::uint8_t, 8> with_zero{};
        std::copy(b.begin(), b.end(), with_zero.begin());
        EXPECT_EQ(v.at("IMU_Crc"), Crc8SaeJ1850(with_zero));
      } else if (f.id == 1281) {
        EXPECT_NEAR(v.at("IMU_AccX"), s.accel_m_s2.x(), 0.0005 + 1e-9);
        EXPECT_NEAR(v.at("IMU_AccY"), s.accel_m_s2.y(), 0.0005 + 1e-9);
        EXPECT_NEAR(v.at("IMU_AccZ"), s.accel_m_s2.z() / 9.80665, 0.00005 + 1e-9);
        // Motorola: AccX's MSB byte first.
        EXPECT_EQ(static_cast<std::int16_t>((f.data[0] << 8) | f.data[1]),
                  static_cast<std::int16_t>(std::lround(s.accel_m_s2.x() / 0.001)));
        EXPECT_EQ(v.at("IMU_Cnt"), n % 16);
        unsigned sum = 0;
        for (int i = 0; i < 7; ++i) sum += f.data[i];
        EXPECT_EQ(v.at("IMU_Sum"), sum % 256);
      } else {
        ASSERT_EQ(f.id, 1282u);
        EXPECT_NEAR(v.at("RR_Z"), s.rate_rad_s.z(), 0.5e-6 + 1e-12);
        EXPECT_EQ(v.at("RR_Cnt"), n % 16);
        std::uint8_t x = 0;
        for (int i = 0; i < 8; ++i) {
          const std::uint8_t byte = i == 4 ? (f.data[4] & 0x0F) : f.data[i];
          x ^= static_cast<std::uint8_t>((byte & 0x0F) ^ (byte >> 4));
        }
        EXPECT_EQ(v.at("RR_Xor"), x);
      }
    }
  }
  // First sample at 1 us, then every GenMsgCycleTime.
  ASSERT_EQ(instants[1280].size(), 10u);
  ASSERT_EQ(instants[1281].size(), 5u);
  ASSERT_EQ(instants[1282].size(), 20u);
  for (std::size_t i = 0; i < instants[1282].size(); ++i) {
    EXPECT_EQ(instants[1282][i], 1'000 + static_cast<std::int64_t>(i) * 5'000'000);
  }
  EXPECT_EQ(node.frames_sent(), 35u);
  EXPECT_EQ(node.saturated(), 0u);
}

TEST(DbcImuNode, PollCatchesUpInDueOrder) {
  DbcImuNode node(UserImuDbc(), UserImuConfig(), 0);
  const std::vector<NodeFrame> frames = node.Poll(20'000'000, ImuSample{});
  // 0x502 at 0, 5, 10, 15, 20 ms; 0x500 at 0, 10, 20; 0x501 at 0, 20: ties in config order.
  std::vector<std::pair<std::int64_t, std::uint32_t>> got;
  for (const NodeFrame& f : frames) got.emplace_back(f.due_ns, f.frame.id);
  const std::vector<std::pair<std::int64_t, std::uint32_t>> want = {
      {0, 1280},          {0, 1281},          {0, 1282},          {5'000'000, 1282},
      {10'000'000, 1280}, {10'000'000, 1282}, {15'000'000, 1282}, {20'000'000, 1280},
      {20'000'000, 1281}, {20'000'000, 1282}};
  EXPECT_EQ(got, want);
}

TEST(DbcImuNode, RejectsConfigurationsTheDbcCannotCarry) {
  const auto dbc = UserImuDbc();
  DbcImuConfig c = UserImuConfig();
  c.channels[3].quantity = ImuQuantity::kRateX;  // a rate on an m/s^2 signal
  EXPECT_THAT([&] { DbcImuNode(dbc, c, 0); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("channels[3].signal: unit 'm/s^2'")));
  c = UserImuConfig();
  c.channels.push_back({ImuQuantity::kRateZ, "IMU_NoCycle", "NC_RateZ"});
  EXPECT_THAT([&] { DbcImuNode(dbc, c, 0); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("GenMsgCycleTime")));
  c = UserImuConfig();
  c.channels[0].signal = "IMU_Nope";
  EXPECT_THAT([&] { DbcImuNode(dbc, c, 0); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("channels[0].signal")));
  c = UserImuConfig();
  c.message_options[1].checksum = ChecksumKind::kXor;
  c.message_options[1].checksum_signal = "IMU_Cnt";  // 4 bits fit XOR; use a CRC on it instead
  c.message_options[1].checksum = ChecksumKind::kCrc8SaeJ1850;
  EXPECT_THAT([&] { DbcImuNode(dbc, c, 0); }, ThrowsMessage<std::invalid_argument>(
                                                  HasSubstr("message_options[1].checksum_signal")));
  c = UserImuConfig();
  c.message_options.push_back({"IMU_NoCycle", "", "", ChecksumKind::kXor});
  EXPECT_THAT([&] { DbcImuNode(dbc, c, 0); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("carries no configured channel")));
  EXPECT_EQ(ParseImuQuantity("accel_z"), ImuQuantity::kAccelZ);
  EXPECT_EQ(ParseImuQuantity("yaw"), std::nullopt);
}

}  // namespace
}  // namespace wheelhil::emulator

namespace wheelhil::emulator {
namespace {

// The frame faults work on a user's DBC too: a wrong counter on the CRC-8 protected message
// keeps a valid CRC; a wrong checksum breaks it; the other messages pass untouched.
TEST(DbcImuNode, WrongCounterAndChecksumFaultsOnAUserDbc) {
  const auto dbc = UserImuDbc();
  DbcImuNode node(dbc, UserImuConfig(), 0);
  FrameFault counter;
  counter.kind = FrameFaultKind::kWrongCounter;
  counter.window = {10'000'000, 30'000'000};
  counter.id = 1280;
  counter.counter_signal = "IMU_Counter";
  counter.counter_offset = 3;
  counter.checksum_signal = "IMU_Crc";
  counter.checksum = ChecksumKind::kCrc8SaeJ1850;
  FrameFault crc = counter;
  crc.kind = FrameFaultKind::kWrongChecksum;
  crc.window = {30'000'000, 50'000'000};
  FaultEventLog log;
  FrameFaultFilter filter({counter, crc}, dbc, 1, &log);
  const bus::DbcMessage& m = *dbc->FindMessage(1280, false);
  ImuSample s;
  s.rate_rad_s = {0.1, 0.2, 0.3};
  const std::vector<NodeFrame> clean = node.Poll(60'000'000, s);
  const std::vector<NodeFrame> out = filter.Process(clean, 60'000'000);
  ASSERT_EQ(out.size(), clean.size());
  int n1280 = 0;
  for (std::size_t i = 0; i < out.size(); ++i) {
    if (out[i].frame.id != 1280) {
      EXPECT_EQ(out[i].frame, clean[i].frame);
      continue;
    }
    const auto v = bus::DecodeMessage(m, out[i].frame);
    std::array<std::uint8_t, 8> zeroed{};
    std::copy(out[i].frame.data.begin(), out[i].frame.data.begin() + 7, zeroed.begin());
    const bool crc_ok = v.at("IMU_Crc") == Crc8SaeJ1850(zeroed);
    const std::int64_t t = out[i].due_ns;
    EXPECT_EQ(v.at("IMU_Counter"), (n1280 + (counter.window.Contains(t) ? 3 : 0)) % 256) << t;
    EXPECT_EQ(crc_ok, !crc.window.Contains(t)) << t;
    ++n1280;
  }
  EXPECT_EQ(n1280, 7);
  EXPECT_EQ(filter.affected(0), 2u);  // 10, 20 ms
  EXPECT_EQ(filter.affected(1), 2u);  // 30, 40 ms
  EXPECT_EQ(log.events().size(), 4u);
}

}  // namespace
}  // namespace wheelhil::emulator
