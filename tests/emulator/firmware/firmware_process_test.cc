// The firmware's process start (emulator/firmware/firmware_process.h): the environment it is
// given (made before the fork, since the child of the run's threaded process may not allocate).
#include "emulator/firmware/firmware_process.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>

namespace wheelhil::emulator::firmware {
namespace {

namespace fs = std::filesystem;

// Polls until `p` exited, at most `limit`; its status, or -1.
int WaitExit(FirmwareProcess& p, std::chrono::seconds limit) {
  const auto until = std::chrono::steady_clock::now() + limit;
  while (std::chrono::steady_clock::now() < until) {
    if (const auto status = p.Exited()) return *status;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return -1;
}

class FirmwareProcessTest : public ::testing::Test {
 protected:
  void SetUp() override {
    log_ = (fs::temp_directory_path() / ("wheelhil_fwproc_" + std::to_string(::getpid()))).string();
  }
  void TearDown() override { fs::remove(log_); }
  std::string Log() const {
    std::ifstream in(log_);
    std::stringstream text;
    text << in.rdbuf();
    return text.str();
  }
  std::string log_;
};

TEST_F(FirmwareProcessTest, TheEnvironmentIsOursWithTheRunsEntriesSetOrReplaced) {
  ::setenv("WHEELHIL_FWPROC_KEPT", "kept", 1);
  ::setenv("WHEELHIL_FWPROC_REPLACED", "old", 1);
  FirmwareProcess p;
  // The command is exec'd: the test runs in a shell of its own.
  p.Start(R"(sh -c 'test "$WHEELHIL_FWPROC_KEPT" = kept && )"
          R"(test "$WHEELHIL_FWPROC_REPLACED" = new && test "$WHEELHIL_FWPROC_ADDED" = "a b" && )"
          R"(exit 3')",
          {{"WHEELHIL_FWPROC_REPLACED", "new"}, {"WHEELHIL_FWPROC_ADDED", "a b"}}, log_);
  EXPECT_EQ(WaitExit(p, std::chrono::seconds(30)), 3) << Log();
  ::unsetenv("WHEELHIL_FWPROC_KEPT");
  ::unsetenv("WHEELHIL_FWPROC_REPLACED");
}

}  // namespace
}  // namespace wheelhil::emulator::firmware
