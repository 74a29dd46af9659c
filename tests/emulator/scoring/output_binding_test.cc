// Firmware outputs from the firmware's own DBC (emulator/scoring/output_binding.h,
// estimate_decoder.h) and the DBC unit table (bus/dbc_units.h): a binding's errors name the file,
// line and field; values are converted from the DBC's units; samples are time-stamped by
// arrival, SYNC cycle or timestamp signal; the bus checks count what a broken frame gets wrong.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <string>

#include "bus/dbc_codec.h"
#include "bus/dbc_units.h"
#include "emulator/scoring/estimate_decoder.h"
#include "emulator/scoring/metrics.h"

namespace wheelhil::emulator::scoring {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

constexpr const char* kDbc = R"(VERSION ""
BU_: Fw Robot
BO_ 768 EST_Pose: 8 Fw
 SG_ X : 0|24@1- (0.1,0) [0|0] "mm" Robot
 SG_ Y : 24|24@1- (0.1,0) [0|0] "mm" Robot
 SG_ Theta : 48|16@1- (0.01,0) [0|0] "deg" Robot
BO_ 769 EST_Vel: 8 Fw
 SG_ Vx : 0|16@1- (1,0) [0|0] "mm/s" Robot
 SG_ Wz : 16|16@1- (0.1,0) [0|0] "deg/s" Robot
 SG_ Stamp : 32|32@1+ (1,0) [0|0] "ms" Robot
BO_ 770 EST_Slip: 4 Fw
 SG_ Flags : 0|4@1+ (1,0) [0|15] "" Robot
 SG_ Cnt : 8|4@1+ (1,0) [0|15] "" Robot
 SG_ Cyc : 12|4@1+ (1,0) [0|15] "" Robot
 SG_ Crc : 24|8@1+ (1,0) [0|255] "" Robot
 SG_ Temp : 16|8@1+ (1,0) [0|255] "degC" Robot
BA_DEF_ BO_ "GenMsgCycleTime" INT 0 65535;
BA_ "GenMsgCycleTime" BO_ 770 10;
)";

class OutputBindingTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("wheelhil-outputs-" +
            std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
    fs::create_directories(dir_);
    std::ofstream(dir_ / "fw.dbc") << kDbc;
  }
  void TearDown() override { fs::remove_all(dir_); }

  // `yaml` (a binding mapping) as if written at line 1 of dir/scenario.yaml.
  OutputsSpec Read(const std::string& yaml) const {
    const bus::yaml::FieldReader r((dir_ / "scenario.yaml").string());
    return ReadOutputs(r, r.Parse(yaml), "firmware.outputs", dir_.string());
  }
  OutputBinding Resolve(const std::string& yaml) const {
    return OutputBinding::Resolve(Read(yaml), dir_.string());
  }
  const bus::DbcMessage& Msg(const OutputBinding& b, const char* name) const {
    return *b.dbc()->FindMessage(name);
  }
  fs::path dir_;
};

TEST(DbcUnits, ConvertsTheSpellingsDbcFilesUseAndRefusesTheOthers) {
  using bus::PhysicalQuantity;
  EXPECT_DOUBLE_EQ(bus::ConvertUnit("mm", PhysicalQuantity::kLength)->scale, 1e-3);
  EXPECT_DOUBLE_EQ(bus::ConvertUnit(" deg/s ", PhysicalQuantity::kAngularRate)->scale,
                   std::numbers::pi / 180);
  EXPECT_DOUBLE_EQ(bus::ConvertUnit("rpm", PhysicalQuantity::kAngularRate)->ToSi(60.0),
                   2 * std::numbers::pi);
  EXPECT_DOUBLE_EQ(bus::ConvertUnit("g", PhysicalQuantity::kAcceleration)->scale, 9.80665);
  EXPECT_DOUBLE_EQ(bus::ConvertUnit("km/h", PhysicalQuantity::kSpeed)->ToSi(36.0), 10.0);
  EXPECT_DOUBLE_EQ(bus::ConvertUnit("degC", PhysicalQuantity::kTemperature)->ToSi(25.0), 298.15);
  EXPECT_FALSE(bus::ConvertUnit("mm", PhysicalQuantity::kAngle));
  EXPECT_FALSE(bus::ConvertUnit("MM", PhysicalQuantity::kLength));
  EXPECT_FALSE(bus::ConvertUnit("m", PhysicalQuantity::kSpeed));
}

TEST_F(OutputBindingTest, ValuesAreConvertedFromTheDbcUnitsAndStampedByArrival) {
  EstimateDecoder d(Resolve(
      "dbc: fw.dbc\nstreams:\n"
      "  pose: {kind: pose, message: EST_Pose, x: X, y: {signal: Y, gain: -1}, theta: Theta}\n"));
  const OutputBinding& b = d.binding();
  bus::CanFrame f = bus::EncodeMessage(Msg(b, "EST_Pose"),
                                       {{"X", 1234.5}, {"Y", -20.0}, {"Theta", 90.0}});
  d.OnFrame(f, -0.5);  // before the motion start: counted, not scored
  d.OnFrame(f, 0.25);
  const auto& pose = d.pose_streams().at("pose");
  ASSERT_EQ(pose.size(), 1u);
  EXPECT_DOUBLE_EQ(pose[0].t_s, 0.25);
  EXPECT_NEAR(pose[0].x_m, 1.2345, 1e-12);
  EXPECT_NEAR(pose[0].y_m, 0.020, 1e-12);  // gain -1
  EXPECT_NEAR(pose[0].theta_rad, std::numbers::pi / 2, 1e-12);
  EXPECT_EQ(d.frame_checks().at("pose").frames, 2u);
  EXPECT_TRUE(d.position_only().empty());
}

TEST_F(OutputBindingTest, ATimestampSignalGivesTheTimeWithItsOriginAtTheFirstFrame) {
  EstimateDecoder d(Resolve("dbc: fw.dbc\nstreams:\n"
                            "  twist: {kind: velocity, message: EST_Vel, vx: Vx, omega: Wz, "
                            "timestamp: Stamp}\n"));
  const auto& msg = Msg(d.binding(), "EST_Vel");
  d.OnFrame(bus::EncodeMessage(msg, {{"Vx", 250}, {"Wz", 9.0}, {"Stamp", 100000}}), 1.0);
  // Sent 30 ms after the first on the firmware's clock, arriving late: the stamp counts.
  d.OnFrame(bus::EncodeMessage(msg, {{"Vx", 260}, {"Wz", 9.0}, {"Stamp", 100030}}), 1.5);
  const auto& v = d.velocity_streams().at("twist");
  ASSERT_EQ(v.size(), 2u);
  EXPECT_DOUBLE_EQ(v[0].t_s, 1.0);
  EXPECT_NEAR(v[1].t_s, 1.03, 1e-12);
  EXPECT_NEAR(v[1].vx_m_s, 0.26, 1e-12);
  EXPECT_DOUBLE_EQ(v[1].vy_m_s, 0.0);  // not bound
  EXPECT_NEAR(v[1].omega_rad_s, 0.9 * std::numbers::pi / 180 * 10, 1e-12);
}

TEST_F(OutputBindingTest, ACycleSignalNamesItsSyncModuloItsRange) {
  EstimateDecoder d(Resolve("dbc: fw.dbc\nstreams:\n"
                            "  slip: {kind: slip, message: EST_Slip, flags: Flags, cycle: Cyc}\n"));
  for (int k = 0; k < 20; ++k) d.OnSync(0.01 * k);  // SYNC 19 is cycle 3 of a 4-bit counter
  const auto& msg = Msg(d.binding(), "EST_Slip");
  d.OnFrame(bus::EncodeMessage(msg, {{"Flags", 2}, {"Cyc", 3}}), 0.195);
  d.OnFrame(bus::EncodeMessage(msg, {{"Flags", 0}, {"Cyc", 2}}), 0.196);  // SYNC 18
  const auto& det = d.detections().at("slip");
  ASSERT_EQ(det.size(), 2u);
  EXPECT_DOUBLE_EQ(det[0].t_s, 0.19);
  EXPECT_TRUE(det[0].detected);
  EXPECT_DOUBLE_EQ(det[1].t_s, 0.18);
  EXPECT_FALSE(det[1].detected);
}

TEST_F(OutputBindingTest, BusChecksCountDlcCounterChecksumAndCycleTimeErrors) {
  EstimateDecoder d(Resolve(
      "dbc: fw.dbc\nstreams:\n"
      "  slip: {kind: slip, message: EST_Slip, detected: Flags, counter: {signal: Cnt, step: 1},\n"
      "         checksum: {signal: Crc, type: crc8_sae_j1850}}\n"));
  const auto& msg = Msg(d.binding(), "EST_Slip");
  auto frame = [&](int cnt) {
    bus::CanFrame f = bus::EncodeMessage(msg, {{"Cnt", cnt}});
    WriteChecksum(ChecksumKind::kCrc8SaeJ1850, *msg.FindSignal("Crc"),
                  std::span<std::uint8_t>(f.data.data(), f.len));
    return f;
  };
  d.OnFrame(frame(14), 0.00);
  d.OnFrame(frame(15), 0.01);
  d.OnFrame(frame(0), 0.02);   // wraps at 2^4
  d.OnFrame(frame(2), 0.03);   // one lost: a counter error
  bus::CanFrame bad = frame(3);
  bad.data[0] ^= 0x01;         // a flipped bit: checksum error
  d.OnFrame(bad, 0.04);
  bus::CanFrame shortf = frame(4);
  shortf.len = 3;              // DLC 3 of 4, the checksum byte missing
  d.OnFrame(shortf, 0.08);     // 40 ms after the last: cycle time 10 ms violated
  const FrameChecks& c = d.frame_checks().at("slip");
  EXPECT_EQ(c.frames, 6u);
  EXPECT_EQ(c.counter_errors, 1u);
  EXPECT_EQ(c.checksum_errors, 2u);
  EXPECT_EQ(c.dlc_errors, 1u);
  EXPECT_EQ(c.cycle_violations, 1u);
  EXPECT_NEAR(c.max_interval_s, 0.04, 1e-12);
  EXPECT_NEAR(c.min_interval_s, 0.01, 1e-12);
}

TEST_F(OutputBindingTest, ErrorsNameFileLineAndField) {
  const std::string file = (dir_ / "scenario.yaml").string();
  auto throws = [&](const std::string& yaml, const std::string& what) {
    EXPECT_THAT([&] { (void)Resolve(yaml); }, ThrowsMessage<std::invalid_argument>(HasSubstr(what)))
        << yaml;
  };
  const std::string head = "dbc: fw.dbc\nstreams:\n";
  throws(head + "  pose: {kind: pose, message: EST_Poze, x: X, y: Y}\n",
         file + ":3:9: firmware.outputs.streams.pose.message: fw.dbc has no message 'EST_Poze'");
  throws(head + "  pose: {kind: pose, message: EST_Pose, x: X, y: Yy}\n",
         file + ":3:50: firmware.outputs.streams.pose.y: message EST_Pose of fw.dbc has no "
                "signal 'Yy' (it has: X, Y, Theta)");
  throws(head + "  pose: {kind: pose, message: EST_Pose, x: X, y: Y, theta: X}\n",
         "firmware.outputs.streams.pose.theta: X's unit 'mm' (in fw.dbc) is not a unit of angle");
  throws(head + "  pose: {kind: pose, message: EST_Pose, x: {signal: X, unit: furlong}, y: Y}\n",
         "pose.x: X's unit 'furlong' is not a unit of length (m, mm, cm, km)");
  throws(head + "  pose: {kind: pose, message: EST_Pose, x: X}\n",
         "firmware.outputs.streams.pose.y: is required");
  throws(head + "  pose: {kind: pos, message: EST_Pose, x: X, y: Y}\n",
         "pose.kind: 'pos' is not pose, velocity or slip");
  throws(head + "  truth: {kind: pose, message: EST_Pose, x: X, y: Y}\n",
         "'truth' is a block of the report's metrics");
  throws(head + "  s: {kind: slip, message: EST_Slip}\n", "needs exactly one of flags");
  throws(head + "  s: {kind: slip, message: EST_Slip, flags: Flags, checksum: {signal: Cnt, "
                "type: crc8_sae_j1850}}\n",
         "Cnt (4 bits) cannot carry a crc8_sae_j1850 checksum");
  throws(head + "  s: {kind: slip, message: EST_Slip, flags: Flags, cycle: Cyc, timestamp: Cnt}\n",
         "cycle and timestamp both give the sample's time");
  throws(head + "  p: {kind: pose, message: EST_Pose, x: X, y: Y, counter: X}\n",
         "p.counter: the counter X must be an integer signal with factor 1 and offset 0");
  throws(head + "  p: {kind: pose, message: EST_Pose, x: X, y: Y, speed: X}\n",
         "p.speed: unknown key");
  throws("dbc: nowhere.dbc\nstreams: {}\n", file + ":1:6: firmware.outputs.dbc: ");
  throws(head + "  p: {kind: pose, message: EST_Pose, x: X, y: Y}\n"
                "  p: {kind: pose, message: EST_Pose, x: X, y: Y}\n",
         file + ":4:3: streams.p: duplicate key (first at line 3)");
}

TEST_F(OutputBindingTest, ABindingFileIsReadRelativeToTheScenarioAndItsDbcRelativeToItself) {
  fs::create_directories(dir_ / "outputs");
  fs::rename(dir_ / "fw.dbc", dir_ / "outputs" / "fw.dbc");
  std::ofstream(dir_ / "outputs" / "fw.yaml")
      << "dbc: fw.dbc\nstreams:\n  pose: {kind: pose, message: EST_Pose, x: X, y: Z}\n";
  const bus::yaml::FieldReader r((dir_ / "scenario.yaml").string());
  EXPECT_THAT(
      [&] {
        (void)OutputBinding::Resolve(
            ReadOutputs(r, YAML::Node("outputs/fw.yaml"), "firmware.outputs", dir_.string()),
            dir_.string());
      },
      ThrowsMessage<std::invalid_argument>(
          HasSubstr((dir_ / "outputs" / "fw.yaml").string() + ":3:")));
}

// evo's APE (nearest truth within max_diff, no alignment) and RPE per metre, on cases worked out
// by hand: a constant 10 cm lateral offset is all APE and no RPE; a 1 % scale error is 1 cm of
// RPE per metre, growing APE.
TEST(EvoMetrics, ApeAndRpeOfAnOffsetAndOfAScaleError) {
  std::vector<PoseSample> truth, offset, scaled;
  for (int i = 0; i <= 300; ++i) {
    const double t = 0.01 * i, x = 0.01 * i;  // 1 cm per 10 ms: 3 m
    truth.push_back({t, x, 0, 0});
    offset.push_back({t + 0.004, x, 0.1, 0});  // 4 ms late: still nearest to its truth sample
    scaled.push_back({t, 1.01 * x, 0, 0});
  }
  const auto po = AssociateNearest(truth, offset, 0.01);
  ASSERT_EQ(po.size(), truth.size());
  const ErrorStats ape = AbsolutePositionError(po);
  EXPECT_NEAR(ape.rmse, 0.1, 1e-12);
  EXPECT_NEAR(ape.std, 0.0, 1e-12);
  EXPECT_NEAR(ComputeRelativePoseError(po).translation_m.max, 0.0, 1e-12);

  const auto ps = AssociateNearest(truth, scaled, 0.01);
  const RelativePoseError rpe = ComputeRelativePoseError(ps, 1.0);
  EXPECT_EQ(rpe.translation_m.n, 3u);
  EXPECT_NEAR(rpe.translation_m.mean, 0.01, 1e-9);
  EXPECT_NEAR(AbsolutePositionError(ps).max, 0.03, 1e-9);
  EXPECT_NEAR(AbsolutePositionError(ps).median, 0.015, 1e-9);
  // Beyond max_diff nothing is paired.
  std::vector<PoseSample> late{{10.0, 0, 0, 0}};
  EXPECT_TRUE(AssociateNearest(truth, late, 0.01).empty());
}

}  // namespace
}  // namespace wheelhil::emulator::scoring
