// Firmware supervision (emulator/firmware/firmware_process.h, process_scope.h,
// stale_run_dirs.h): at the end of a run no process the firmware started is left, whether it
// forked, ignored SIGTERM, left the process group with setsid or cleared its environment; a
// crash is reported with its signal; the runtime directories of killed runs are removed.

#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>
#include <utime.h>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "emulator/firmware/process_scope.h"
#include "emulator/firmware/stale_run_dirs.h"
#include "emulator/scenario/runner.h"
#include "emulator/scenario/scenario.h"
#include "tests/emulator/scenario/runner_test_support.h"

namespace wheelhil::emulator::scenario {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

Scenario ShortPaper000() {
  Scenario s = LoadScenarioFile(std::string(WHEELHIL_SOURCE_DIR) + "/scenarios/paper000_slip.yaml");
  s.timing.duration_s = 2.0;
  s.timing.timeout_s = 0.5;
  s.expectations.clear();
  return s;
}

// The pids whose command line holds `token`.
std::vector<pid_t> ProcessesWith(const std::string& token) {
  std::vector<pid_t> out;
  for (pid_t pid : firmware::ListPids()) {
    // ReadProcFile, not an ifstream: a process that ends while it is read makes the read fail
    // (ESRCH), which a stream buffer throws.
    const std::string cmd = firmware::ReadProcFile("/proc/" + std::to_string(pid) + "/cmdline");
    if (cmd.find(token) != std::string::npos && pid != ::getpid()) out.push_back(pid);
  }
  return out;
}

class FirmwareSupervision : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("wheelhil_supervision_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    // A sleep duration no other process on the machine has: how its helpers are found.
    token_ = "86400." + std::to_string(::getpid());
  }
  void TearDown() override {
    for (pid_t pid : ProcessesWith(token_)) ::kill(pid, SIGKILL);
    fs::remove_all(dir_);
  }
  // Three helpers that ignore SIGTERM: a forked one, a setsid one, and a setsid one with an
  // empty environment (no marker); then the firmware itself waits.
  std::string HostileCommand(const std::string& then) const {
    const std::string helper = "sh -c 'trap \"\" TERM; exec sleep " + token_ + "'";
    return "sh -c \"" + helper + " & setsid " + helper + " & env -i /usr/bin/setsid " + helper +
           " & sleep 0.2; " + then + "\"";
  }
  // Runs the hostile firmware ending in `then`: the run fails with `failure` and leaves none of
  // its helpers.
  void ExpectFailureAndNoHelperLeft(const std::string& then, const std::string& failure) {
    Scenario s = ShortPaper000();
    s.firmware.command = HostileCommand(then);
    const RunResult r = RunScenario(s, testing::BuildTreeRunOptions(dir_ / "run"));
    EXPECT_EQ(r.exit_code, 1);
    EXPECT_THAT(r.failure, HasSubstr(failure));
    EXPECT_THAT(ProcessesWith(token_), ::testing::IsEmpty());
  }
  fs::path dir_;
  std::string token_;
};

TEST_F(FirmwareSupervision, HelpersThatForkIgnoreSigtermAndSetsidAreGoneAfterTheRun) {
  ExpectFailureAndNoHelperLeft("exec sleep 30", "did not open ucan0");
}

TEST_F(FirmwareSupervision, HelpersOfAFirmwareThatExitsAreGoneToo) {
  ExpectFailureAndNoHelperLeft("exit 3", "the firmware exited with status 3 before opening ucan0");
}

TEST_F(FirmwareSupervision, ACrashIsReportedWithItsSignal) {
  Scenario s = ShortPaper000();
  s.firmware.command = "sh -c 'kill -SEGV $$'";
  const RunResult r = RunScenario(s, testing::BuildTreeRunOptions(dir_ / "crash"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.failure,
              HasSubstr("the firmware was killed by signal 11 (SIGSEGV) before opening ucan0"));
}

TEST_F(FirmwareSupervision, ACrashWithACoreIsReportedWithItsFirstFrames) {
  std::ifstream pattern_file("/proc/sys/kernel/core_pattern");
  std::string pattern;
  std::getline(pattern_file, pattern);
  rlimit core{};
  ::getrlimit(RLIMIT_CORE, &core);
  if (pattern.empty() || pattern[0] == '|' || core.rlim_max == 0 ||
      std::system("command -v gdb >/dev/null 2>&1") != 0) {
    GTEST_SKIP() << "needs core files (core_pattern '" << pattern
                 << "', a hard core limit above 0) and gdb";
  }
  Scenario s = ShortPaper000();
  s.firmware.command = std::string("sh -c 'ulimit -c unlimited; exec ") + CRASH_FIRMWARE + "'";
  const fs::path out = dir_ / "core";
  const RunResult r = RunScenario(s, testing::BuildTreeRunOptions(out));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.failure, HasSubstr("the firmware was killed by signal 11 (SIGSEGV), core dumped"));
  EXPECT_THAT(r.failure, HasSubstr("; first frames: crash_here (p=0x0) at "));
  EXPECT_THAT(r.failure, HasSubstr("crash_firmware.c:8 <- caller () at "));
  EXPECT_TRUE(fs::exists(out / "firmware.core"));
  std::ifstream log(out / "firmware.log");
  const std::string text((std::istreambuf_iterator<char>(log)), std::istreambuf_iterator<char>());
  EXPECT_THAT(text, HasSubstr("#2 "));
  EXPECT_THAT(text, HasSubstr("main () at "));
}

TEST_F(FirmwareSupervision, AFirmwareOpeningHundredsOfSocketsEndsWithANamedReason) {
  Scenario s = ShortPaper000();
  s.firmware.command =
      "/usr/bin/python3 -c \"import socket, time\n"
      "held = []\n"
      "for i in range(400):\n"
      "    c = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)\n"
      "    c.bind(('ucan0',))\n"
      "    held.append(c)\n"
      "time.sleep(30)\"";
  const RunResult r = RunScenario(s, testing::BuildTreeRunOptions(dir_ / "sockets"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.failure, HasSubstr("the firmware opened too many connections to the bus"));
  EXPECT_THAT(r.failure, HasSubstr("connections to the bus open, the limit per process"));
}

TEST_F(FirmwareSupervision, StaleRunDirectoriesAreRemovedLiveAndFreshOnesKept) {
  const fs::path tmp = dir_ / "tmp";
  fs::create_directories(tmp);
  auto make = [&](const std::string& name, bool old) {
    const fs::path d = tmp / name;
    fs::create_directory(d);
    fs::permissions(d, fs::perms::owner_all, fs::perm_options::replace);
    std::ofstream(d / "ucan.lock").put('x');
    std::ofstream(d / "ucan.sock").put('x');
    if (old) {
      const utimbuf t{std::time(nullptr) - 60, std::time(nullptr) - 60};
      ::utime(d.c_str(), &t);
    }
    return d;
  };
  const fs::path stale = make("wheelhil-run-stale", true);
  const fs::path live = make("wheelhil-run-live", true);
  const fs::path fresh = make("wheelhil-run-fresh", false);
  const fs::path other = make("someone-else", true);
  const int held = ::open((live / "ucan.lock").c_str(), O_RDWR | O_CLOEXEC);
  ASSERT_EQ(::flock(held, LOCK_EX | LOCK_NB), 0);
  // What the killed run left running on its bus.
  const pid_t orphan = ::fork();
  if (orphan == 0) {
    ::setenv("WHEELHIL_UCAN_DIR", stale.c_str(), 1);
    ::execl("/bin/sleep", "sleep", token_.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(100));  // exec'd, environ readable
  // Touch the stale dir's time back: the fork did not change it, but be explicit.
  const utimbuf t{std::time(nullptr) - 60, std::time(nullptr) - 60};
  ::utime(stale.c_str(), &t);

  const char* old_tmp = std::getenv("TMPDIR");
  const std::string saved = old_tmp ? old_tmp : "";
  ::setenv("TMPDIR", tmp.c_str(), 1);
  const auto removed = firmware::RemoveStaleRunDirs("wheelhil-run-");
  if (old_tmp) {
    ::setenv("TMPDIR", saved.c_str(), 1);
  } else {
    ::unsetenv("TMPDIR");
  }
  ::close(held);

  EXPECT_EQ(removed, std::vector<std::string>{stale.string()});
  EXPECT_FALSE(fs::exists(stale));
  EXPECT_TRUE(fs::exists(live));
  EXPECT_TRUE(fs::exists(fresh));
  EXPECT_TRUE(fs::exists(other));
  int status = 0;
  ASSERT_EQ(::waitpid(orphan, &status, 0), orphan);
  EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL);
}

TEST(ProcessScope, FindsTheGroupTheMarkedAndTheirDescendants) {
  firmware::ProcessScope scope;
  const auto [key, value] = scope.EnvironmentEntry();
  const std::string token = "86401." + std::to_string(::getpid());
  const pid_t child = ::fork();
  if (child == 0) {
    ::setenv(key.c_str(), value.c_str(), 1);
    // A grandchild that clears its environment: found as a descendant.
    ::execl("/bin/sh", "sh", "-c", ("env -i sleep " + token + " & exec sleep " + token).c_str(),
            static_cast<char*>(nullptr));
    ::_exit(127);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  EXPECT_EQ(scope.Members().size(), 2u);
  EXPECT_GE(scope.KillAll(), 2u);
  EXPECT_THAT(ProcessesWith(token), ::testing::IsEmpty());
  EXPECT_EQ(::waitpid(child, nullptr, WNOHANG), -1);  // reaped by KillAll
}

}  // namespace
}  // namespace wheelhil::emulator::scenario
