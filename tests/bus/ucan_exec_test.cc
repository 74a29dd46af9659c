// Unmodified third-party SocketCAN programs on a ucan bus through `wheelhil exec`: can-utils
// (candump, cansend, cangen), Python's socket module and python-can. Each test runs its own
// broker in a temp runtime dir; programs run under `timeout` so a bug cannot hang the suite.
// Readiness (a candump has bound) is read from the broker's client count, not from sleeps.

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <chrono>
#include <regex>
#include <sstream>
#include <thread>

#include "bus/ucan_broker.h"
#include "tests/bus/ucan_test_util.h"

namespace wheelhil::bus {
namespace {

const std::string kWheelhil = std::string(WHEELHIL_BINARY_DIR) + "/bin/wheelhil";
const std::string kScripts = std::string(WHEELHIL_SOURCE_DIR) + "/tests/bus/scripts";

/// A child process with its stdout captured.
class Child {
 public:
  explicit Child(const std::vector<std::string>& argv) {
    int fds[2];
    if (::pipe2(fds, O_CLOEXEC) != 0) throw std::runtime_error("pipe");
    pid_ = ::fork();
    if (pid_ == 0) {
      ::dup2(fds[1], 1);
      std::vector<char*> args;
      for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
      args.push_back(nullptr);
      ::execvp(args[0], args.data());
      ::_exit(127);
    }
    ::close(fds[1]);
    out_fd_ = fds[0];
  }
  ~Child() {
    if (pid_ > 0) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
    if (out_fd_ >= 0) ::close(out_fd_);
  }
  /// Reads stdout to EOF and returns the exit code (128 + signal when killed).
  int Wait(std::string* out) {
    char buf[4096];
    ssize_t n = 0;
    while ((n = ::read(out_fd_, buf, sizeof(buf))) > 0) out->append(buf, static_cast<size_t>(n));
    int status = 0;
    ::waitpid(pid_, &status, 0);
    pid_ = -1;
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  }

 private:
  pid_t pid_ = -1;
  int out_fd_ = -1;
};

int RunCommand(const std::vector<std::string>& argv, std::string* out = nullptr) {
  std::string ignored;
  return Child(argv).Wait(out != nullptr ? out : &ignored);
}

std::vector<std::string> Exec(std::vector<std::string> program) {
  std::vector<std::string> argv = {"timeout", "20", kWheelhil, "exec", "--"};
  argv.insert(argv.end(), program.begin(), program.end());
  return argv;
}

/// Drops the "(seconds.micros) " prefix of candump -L lines.
std::vector<std::string> LogBodies(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  std::string line;
  const std::regex stamp(R"(^\(\d+\.\d{6}\) (.*)$)");
  std::smatch m;
  while (std::getline(in, line)) {
    lines.push_back(std::regex_match(line, m, stamp) ? m[1].str() : "BAD: " + line);
  }
  return lines;
}

class UcanExecTest : public ::testing::Test {
 protected:
  UcanExecTest() : broker_(Options(dir_.path())) { broker_.AddBus("ucan0"); }
  static UcanBrokerOptions Options(const std::string& dir) {
    UcanBrokerOptions o;
    o.runtime_dir = dir;
    return o;
  }
  /// Waits until `n` sockets are bound to ucan0 (10 s at most).
  bool WaitForClients(std::size_t n) {
    for (int i = 0; i < 1000; ++i) {
      if (broker_.Stats().at(0).clients >= n) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return false;
  }

  testing::TempRuntimeDir dir_;
  UcanBroker broker_;
};

TEST_F(UcanExecTest, CandumpLogsWhatCansendSends) {
  Child dump(Exec({"candump", "-L", "-n", "3", "ucan0"}));
  ASSERT_TRUE(WaitForClients(1));
  EXPECT_EQ(RunCommand(Exec({"cansend", "ucan0", "123#DEADBEEF"})), 0);
  EXPECT_EQ(RunCommand(Exec({"cansend", "ucan0", "12345678#0011"})), 0);
  EXPECT_EQ(RunCommand(Exec({"cansend", "ucan0", "7FF#R"})), 0);
  std::string out;
  EXPECT_EQ(dump.Wait(&out), 0);
  EXPECT_THAT(LogBodies(out),
              ::testing::ElementsAre("ucan0 123#DEADBEEF", "ucan0 12345678#0011", "ucan0 7FF#R"));
}

TEST_F(UcanExecTest, CangenBurstArrivesCompleteAndInOrder) {
  Child dump(Exec({"candump", "-L", "-n", "200", "ucan0"}));
  ASSERT_TRUE(WaitForClients(1));
  EXPECT_EQ(RunCommand(Exec(
                {"cangen", "ucan0", "-g", "0", "-n", "200", "-I", "42", "-L", "8", "-D", "i"})),
            0);
  std::string out;
  EXPECT_EQ(dump.Wait(&out), 0);
  const auto lines = LogBodies(out);
  ASSERT_EQ(lines.size(), 200u);
  // -D i: the payload is a counter in the first byte.
  for (std::size_t i = 0; i < lines.size(); ++i) {
    char expect[32];
    std::snprintf(expect, sizeof(expect), "ucan0 042#%02X", static_cast<unsigned>(i & 0xFF));
    EXPECT_EQ(lines[i].substr(0, 12), expect) << lines[i];
  }
  EXPECT_EQ(broker_.Stats().at(0).drops, 0u);
}

TEST_F(UcanExecTest, PythonSocketModule) {
  std::string out;
  EXPECT_EQ(
      RunCommand(Exec({"/usr/bin/python3", kScripts + "/ucan_socket_check.py", "ucan0"}), &out), 0)
      << out;
  EXPECT_THAT(out, ::testing::HasSubstr("OK"));
}

TEST_F(UcanExecTest, PythonCan) {
  std::string out;
  EXPECT_EQ(
      RunCommand(Exec({"/usr/bin/python3", kScripts + "/ucan_python_can_check.py", "ucan0"}), &out),
      0)
      << out;
  EXPECT_THAT(out, ::testing::HasSubstr("OK"));
}

TEST_F(UcanExecTest, KernelInterfaceNamesPassThrough) {
  // vcan0 is not a ucan bus: cansend gets the kernel's own answer and fails.
  EXPECT_NE(RunCommand(Exec({"cansend", "vcan0", "123#00"})), 0);
  std::string out;
  EXPECT_EQ(RunCommand(
                Exec({"/usr/bin/python3", kScripts + "/ucan_socket_check.py", "--kernel", "vcan0"}),
                &out),
            0)
      << out;
}

TEST_F(UcanExecTest, ExecReturnsTheProgramsExitCode) {
  EXPECT_EQ(RunCommand({kWheelhil, "exec", "--", "sh", "-c", "exit 7"}), 7);
  std::string out;
  EXPECT_EQ(RunCommand({kWheelhil, "exec", "--", "sh", "-c", "echo $WHEELHIL_UCAN_DIR"}, &out), 0);
  EXPECT_EQ(out, dir_.path() + "\n");
  EXPECT_EQ(RunCommand({kWheelhil, "exec", "--", "/nonexistent/program"}), 127);
}

TEST(UcanDaemon, BusUpListDown) {
  testing::TempRuntimeDir dir;
  std::string out;
  ASSERT_EQ(RunCommand({"timeout", "20", kWheelhil, "bus", "up", "ucan5"}, &out), 0) << out;
  EXPECT_THAT(out, ::testing::HasSubstr("ifindex 1005"));
  ASSERT_EQ(RunCommand({"timeout", "20", kWheelhil, "bus", "up", "ucan5"}), 0);  // idempotent
  ASSERT_EQ(RunCommand({"timeout", "20", kWheelhil, "bus", "up", "ucan6"}), 0);
  // A frame through the daemon, with exec --bus bringing up the bus it needs.
  Child dump(Exec({"candump", "-L", "-n", "1", "ucan6"}));
  std::vector<UcanBusStats> stats;
  for (int i = 0; i < 1000; ++i) {
    ASSERT_FALSE(UcanListBuses(dir.path(), &stats));
    if (stats.size() == 2 && stats[1].clients == 1) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_EQ(RunCommand({"timeout", "20", kWheelhil, "exec", "--bus", "ucan6", "--", "cansend",
                        "ucan6", "321#01"}),
            0);
  std::string dumped;
  EXPECT_EQ(dump.Wait(&dumped), 0);
  EXPECT_THAT(LogBodies(dumped), ::testing::ElementsAre("ucan6 321#01"));
  out.clear();
  ASSERT_EQ(RunCommand({kWheelhil, "bus", "list"}, &out), 0);
  EXPECT_THAT(out, ::testing::ContainsRegex("ucan5 +1005 +0 +0 +0"));
  EXPECT_THAT(out, ::testing::ContainsRegex("ucan6 +1006 +0 +1 +0"));
  EXPECT_EQ(RunCommand({kWheelhil, "bus", "down", "ucan5"}), 0);
  EXPECT_NE(RunCommand({kWheelhil, "bus", "down", "ucan5"}), 0);
  EXPECT_EQ(RunCommand({kWheelhil, "bus", "down", "ucan6"}), 0);  // last bus: the daemon exits
  bool gone = false;
  for (int i = 0; i < 1000 && !gone; ++i) {
    gone = static_cast<bool>(UcanListBuses(dir.path(), &stats));
    if (!gone) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_TRUE(gone);
}

}  // namespace
}  // namespace wheelhil::bus
