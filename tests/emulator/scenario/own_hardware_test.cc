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

#include "emulator/scenario/runner.h"
#include "emulator/scenario/scenario.h"
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

}  // namespace
}  // namespace wheelhil::emulator::scenario
