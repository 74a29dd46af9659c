// The firmware's process start (emulator/firmware/firmware_process.h): the environment it is
// given (made before the fork, since the child of the run's threaded process may not allocate),
// and a command the shell would only split at spaces run without a shell.
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

// `env`'s output has a PWD entry.
bool HasPwd(const std::string& env) {
  return env.rfind("PWD=", 0) == 0 || env.find("\nPWD=") != std::string::npos;
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

// A plain command (words, no quoting or expansion) is its program, found on PATH, exec'd with
// no shell before it: it gets exactly the environment it is given (a shell adds PWD when there
// is none). A command that needs the shell (here a quoted word) still gets one; a program not
// found is the shell's "not found" (status 127), as before.
TEST_F(FirmwareProcessTest, APlainCommandRunsWithoutAShellAndAnyOtherThroughOne) {
  const char* pwd = std::getenv("PWD");
  const std::string saved_pwd = pwd != nullptr ? pwd : "";
  ::unsetenv("PWD");
  FirmwareProcess plain;
  plain.Start("env", {{"WHEELHIL_FWPROC_PLAIN", "1"}}, log_);
  EXPECT_EQ(WaitExit(plain, std::chrono::seconds(30)), 0) << Log();
  EXPECT_NE(Log().find("WHEELHIL_FWPROC_PLAIN=1\n"), std::string::npos) << Log();
  EXPECT_FALSE(HasPwd(Log())) << Log();

  FirmwareProcess shell;
  shell.Start("env 'WHEELHIL_FWPROC_QUOTED=a b'", {}, log_);
  EXPECT_EQ(WaitExit(shell, std::chrono::seconds(30)), 0) << Log();
  EXPECT_NE(Log().find("WHEELHIL_FWPROC_QUOTED=a b\n"), std::string::npos) << Log();
  EXPECT_TRUE(HasPwd(Log())) << Log();
  if (pwd != nullptr) ::setenv("PWD", saved_pwd.c_str(), 1);

  FirmwareProcess missing;
  missing.Start("wheelhil-no-such-program --can ucan0", {}, log_);
  EXPECT_EQ(WaitExit(missing, std::chrono::seconds(30)), 127) << Log();
  EXPECT_NE(Log().find("not found"), std::string::npos) << Log();
}

}  // namespace
}  // namespace wheelhil::emulator::firmware
