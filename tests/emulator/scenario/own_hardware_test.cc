// Own hardware (docs/own-hardware.md) end to end: scenarios/own_hardware/robot_mm7_imu.yaml runs
// a Bosch MM7.10 IMU built from its DBC (a `dbc` device), CiA 406 encoders from the devices
// list and a customer firmware scored through its own DBC. Its IMU frames are decoded by
// Debian's python3-canmatrix (mm7_frames_check.py), independently of wheelhil's codec, and
// compared with the ground truth; counters and CRCs are recomputed there.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <string>

#include "bus/dbc.h"
#include "bus/dbc_codec.h"
#include "emulator/scenario/device_registry.h"
#include "emulator/scenario/runner.h"
#include "emulator/scenario/scenario.h"
#include "tests/emulator/devices/recording_port.h"
#include "tests/emulator/scenario/runner_test_support.h"

namespace wheelhil::emulator::scenario {
namespace {

namespace fs = std::filesystem;

const std::string kScenario =
    std::string(WHEELHIL_SOURCE_DIR) + "/scenarios/own_hardware/robot_mm7_imu.yaml";

bool HaveCanmatrix() {
  return std::system("/usr/bin/python3 -c 'import canmatrix' >/dev/null 2>&1") == 0;
}

TEST(OwnHardwareRun, Mm7ImuFramesDecodeToTheTruthAndTheFirmwareIsScoredFromItsDbc) {
  const fs::path dir = fs::temp_directory_path() / ("wheelhil_own_hw_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  const Scenario s = LoadScenarioFile(kScenario);
  ASSERT_EQ(s.devices.size(), 3u);
  const RunResult r = RunScenario(s, testing::BuildTreeRunOptions(dir));
  EXPECT_EQ(r.failure, "");
  EXPECT_EQ(r.report["verdict"], "pass") << r.report["expectations"].dump(1);
  EXPECT_GE(r.report["metrics"]["pose"]["frames"].get<int>(), 100);
  if (!HaveCanmatrix()) {
    fs::remove_all(dir);
    GTEST_SKIP() << "python3-canmatrix is not installed (./hil setup installs it)";
  }
  const std::string cmd = "/usr/bin/python3 " + std::string(WHEELHIL_SOURCE_DIR) +
                          "/tests/emulator/scenario/mm7_frames_check.py " + dir.string() + " " +
                          std::string(WHEELHIL_SOURCE_DIR) +
                          "/scenarios/own_hardware/bosch_mm7_10.dbc 2>/dev/null";
  EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
  fs::remove_all(dir);
}

// Faults address a `devices` entry by its name: a silent window drops its frames, a bias step
// on one of its channels shifts what that signal reads.
TEST(OwnHardwareRun, FaultsAddressADeviceByItsName) {
  const fs::path dir =
      fs::temp_directory_path() / ("wheelhil_own_hw_faults_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  const std::string text = testing::Slurp(kScenario) +
                           "faults:\n"
                           "  - {type: device, kind: silent, node: imu, start_s: 0.5, end_s: 1.0}\n"
                           "  - {type: sensor, kind: bias_step, sensor: imu.rate_z, value: 0.5,\n"
                           "     start_s: 0.0}\n";
  const Scenario s = ParseScenario(text, kScenario);
  ASSERT_EQ(s.faults.size(), 2u);
  const RunResult r = RunScenario(s, testing::BuildTreeRunOptions(dir));
  EXPECT_EQ(r.failure, "");
  // 10 ms frames: a 0.5 s window keeps 50 instants of three frames off the bus.
  EXPECT_EQ(r.report["metrics"]["faults"]["device_suppressed_frames"].get<int>(), 150)
      << r.report["metrics"]["faults"].dump(1);
  // At rest after the motion the yaw rate reads the bias: 0.5 rad/s = 28.65 deg/s (the MM7.10's
  // YawRate: bits 0..15, 0.005 deg/s, offset -163.84), within 6 sigma of its noise.
  const std::string log = testing::Slurp(dir / "can.log");
  const auto at = log.rfind(" 174#");
  ASSERT_NE(at, std::string::npos);
  const std::string hex = log.substr(at + 5, 4);
  const unsigned raw = std::stoul(hex.substr(2, 2) + hex.substr(0, 2), nullptr, 16);
  EXPECT_NEAR(raw * 0.005 - 163.84, 28.648, 0.7);
  fs::remove_all(dir);
  EXPECT_THAT([&] {
    (void)ParseScenario(testing::Slurp(kScenario) +
                            "faults:\n  - {type: sensor, kind: stuck, sensor: imu.yaw, start_s: 0}\n",
                        kScenario);
  }, ::testing::ThrowsMessage<std::invalid_argument>(::testing::HasSubstr(
         "'imu.yaw' is not one of gyro, encoder, accel4, DEVICE.rate_x")));
}

using emulator::testing::RecordingPort;

// `kind: mm5_10` is the shipped MM5.10 DBC as a dbc device: its three frames every 10 ms, the
// yaw rate in deg/s, the specific force in g (mounted upside down, z reads -1 g at rest).
TEST(OwnHardwareDevices, Mm5IsADbcDeviceOverTheShippedDbc) {
  const Scenario s = ParseScenario(
      "name: t\nplatform: platforms/diff2.yaml\nmotion:\n"
      "  - {type: hold, duration_s: 1}\n"
      "devices:\n"
      "  - {kind: canopen_cia406, wheel: left, node_id: 1}\n"
      "  - {kind: mm5_10, mount: {rpy_deg: [180, 0, 0]}}\n",
      std::string(WHEELHIL_SOURCE_DIR) + "/scenarios/inline.yaml");
  const std::string dbc_dir = std::string(WHEELHIL_SOURCE_DIR) + "/bus/dbc";
  std::vector<physics::WheelTruth> wheels(4);
  auto devices = BuildScenarioDevices(DeviceBuildContext{s, 1, dbc_dir, wheels});
  ASSERT_EQ(devices.size(), 2u);
  EXPECT_EQ(devices[1]->name(), "mm5_10");
  physics::BodyTruth body;
  body.omega_WB_W = {0, 0, 0.3};
  DeviceWorld world{&body, &wheels, {}};
  RecordingPort port;
  devices[1]->Poll(25'000'000, world, port);
  ASSERT_EQ(port.sent.size(), 9u);  // 0, 10, 20 ms x three frames
  const auto db = bus::DbcDatabase::LoadFile(dbc_dir + "/bosch_mm5_10.dbc");
  const auto yaw = bus::DecodeMessage(*db.FindMessage(0x174, false), port.sent[3].frame);
  EXPECT_NEAR(yaw.at("MM5_YawRate"), -0.3 * 180 / 3.141592653589793, 0.005);  // upside down
  const auto z = bus::DecodeMessage(*db.FindMessage(0x17C, false), port.sent[5].frame);
  EXPECT_NEAR(z.at("MM5_AccelZ"), -1.0, 0.0002);
}

}  // namespace
}  // namespace wheelhil::emulator::scenario
