#include "emulator/firmware/firmware_process.h"

#include <fcntl.h>
#include <sched.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <stdexcept>
#include <string_view>
#include <thread>
#include <utility>

#include <fmt/format.h>

#include "emulator/firmware/crash_frames.h"
#include "emulator/sim/signal_name.h"

namespace wheelhil::emulator::firmware {

namespace {

// `command` as the words of a program and its arguments when the shell would do nothing with
// it but split it at spaces (no quoting, expansion, redirection or assignment), followed by the
// program's file, found on PATH as the shell would; empty when the shell is needed. The shell's
// start (its own exec, and the clock's and the bus's libraries loaded into it) is then saved:
// ~0.5 ms of every run.
std::vector<std::string> PlainCommand(const std::string& command) {
  auto plain = [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
           std::string_view("_-./,:+@%=").find(c) != std::string_view::npos;
  };
  std::vector<std::string> words;
  std::string word;
  for (const char c : command + ' ') {
    if (c == ' ') {
      if (!word.empty()) words.push_back(std::exchange(word, {}));
    } else if (plain(c)) {
      word += c;
    } else {
      return {};
    }
  }
  if (words.empty() || words[0].find('=') != std::string::npos) return {};
  // Without PATH each shell has a default of its own: it finds the program.
  if (words[0].find('/') == std::string::npos && std::getenv("PATH") == nullptr) return {};
  std::string file = FindOnPath(words[0]);
  if (file.empty()) return {};  // the shell says it is not found
  words.push_back(std::move(file));
  return words;
}

constexpr std::size_t kChildStackBytes = 64 * 1024;

// What the child needs, all made before the clone.
struct ChildStart {
  int log_fd = -1;
  pid_t parent = 0;
  const char* program = nullptr;  // nullptr: the shell
  char* const* argv = nullptr;
  char* const* sh_argv = nullptr;
  char* const* envp = nullptr;
  sigset_t mask;  // the run's thread's, restored before the exec
};

// The child, on its own stack in the run's memory until its exec: system calls only.
__attribute__((no_sanitize("address", "undefined"))) int ChildMain(void* raw) {
  const ChildStart& c = *static_cast<const ChildStart*>(raw);
  for (int sig = 1; sig < NSIG; ++sig) {
    struct sigaction sa {};
    if (::sigaction(sig, nullptr, &sa) != 0 || sa.sa_handler == SIG_IGN ||
        sa.sa_handler == SIG_DFL) {
      continue;
    }
    sa.sa_handler = SIG_DFL;
    sa.sa_flags = 0;
    ::sigemptyset(&sa.sa_mask);
    ::sigaction(sig, &sa, nullptr);
  }
  ::sigprocmask(SIG_SETMASK, &c.mask, nullptr);
  ::setpgid(0, 0);
  (void)::prctl(PR_SET_PDEATHSIG, SIGKILL);
  if (::getppid() != c.parent) ::_exit(127);  // the run died before the line above
  if (c.log_fd >= 0) {
    ::dup2(c.log_fd, 1);
    ::dup2(c.log_fd, 2);
  }
  if (c.program != nullptr) ::execve(c.program, c.argv, c.envp);
  // Also when that failed (a script without #!, a file that vanished): the shell runs it, or
  // says why not, as it would have.
  ::execve("/bin/sh", c.sh_argv, c.envp);
  ::_exit(127);
}

}  // namespace

void FirmwareProcess::Start(const std::string& command,
                            const std::vector<std::pair<std::string, std::string>>& env,
                            const std::string& log_path) {
  const int log_fd = ::open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  ProcessScope::BecomeSubreaper();
  scope_ = ProcessScope();
  wait_status_ = -1;
  log_path_ = log_path;
  crash_frames_.clear();
  std::error_code ec;
  cwd_ = std::filesystem::current_path(ec).string();
  // Everything the child needs is made here: it runs in the run's memory until its exec, and
  // a child of a threaded process may only make async-signal-safe calls before it (an
  // allocation could wait forever for a lock another thread held at the clone).
  std::vector<std::pair<std::string, std::string>> child_env = env;
  child_env.push_back(scope_.EnvironmentEntry());
  const std::vector<std::string> env_entries = EnvironmentWith(child_env);
  std::vector<char*> envp;
  for (const auto& e : env_entries) envp.push_back(const_cast<char*>(e.c_str()));
  envp.push_back(nullptr);
  const std::string sh = "exec " + command;
  const std::vector<std::string> words = PlainCommand(command);
  const char* sh_argv[] = {"sh", "-c", sh.c_str(), nullptr};
  std::vector<const char*> argv;
  for (std::size_t i = 0; i + 1 < words.size(); ++i) argv.push_back(words[i].c_str());
  argv.push_back(nullptr);
  ChildStart start;
  start.log_fd = log_fd;
  start.parent = ::getpid();
  start.program = words.empty() ? nullptr : words.back().c_str();
  start.argv = const_cast<char* const*>(argv.data());
  start.sh_argv = const_cast<char* const*>(sh_argv);
  start.envp = envp.data();
  // No signal handler of the run's may run in the child while it shares the run's memory: all
  // blocked around the clone, the child sets its handled ones to default before it unblocks.
  sigset_t all;
  ::sigfillset(&all);
  ::pthread_sigmask(SIG_BLOCK, &all, &start.mask);
  std::vector<char> stack(kChildStackBytes);
  // The run's memory is shared, not copied, until the child's exec (as posix_spawn does): a
  // fork copies the page tables of the run (~20 MB resident: ~1 ms).
  pid_ = ::clone(ChildMain, stack.data() + stack.size(), CLONE_VM | CLONE_VFORK | SIGCHLD, &start);
  ::pthread_sigmask(SIG_SETMASK, &start.mask, nullptr);
  started_pid_ = pid_;
  if (pid_ < 0) {
    if (log_fd >= 0) ::close(log_fd);
    throw std::runtime_error("fork failed");
  }
  // Also here: the group exists before the parent may signal it, whichever runs first.
  (void)::setpgid(pid_, pid_);
  scope_.set_group(pid_);
  if (log_fd >= 0) ::close(log_fd);
}

void FirmwareProcess::Reaped(int wait_status) {
  pid_ = -1;
  wait_status_ = wait_status;
  exit_status_ = WIFEXITED(wait_status) ? WEXITSTATUS(wait_status) : 128 + WTERMSIG(wait_status);
  // Helpers it left behind go with it.
  scope_.KillAll();
  if (WIFSIGNALED(wait_status)) NoteCrash(WTERMSIG(wait_status), WCOREDUMP(wait_status) != 0);
}

void FirmwareProcess::NoteCrash(int signal, bool core_dumped) {
  std::string note;
  if (core_dumped) {
    const std::string dir = std::filesystem::path(log_path_).parent_path().string();
    const CrashFrames crash = ReadCrashFrames(started_pid_, cwd_, dir.empty() ? "." : dir);
    crash_frames_ = crash.frames;
    note = crash.frames.empty() ? "no stack: " + crash.note : "";
    for (const std::string& f : crash.frames) note += f + "\n";
    if (!crash.core_path.empty()) note += "core: " + crash.core_path + "\n";
  } else if (signal == SIGSEGV || signal == SIGABRT || signal == SIGBUS || signal == SIGFPE ||
             signal == SIGILL || signal == SIGTRAP || signal == SIGSYS) {
    rlimit core{};
    if (::getrlimit(RLIMIT_CORE, &core) == 0 && core.rlim_cur == 0) {
      note = "no core dump (ulimit -c is 0): run with `ulimit -c unlimited` and gdb installed "
             "for the crash's first frames\n";
    }
  }
  if (note.empty() || log_path_.empty()) return;
  std::ofstream log(log_path_, std::ios::app);
  log << "wheelhil: the firmware was killed by " << sim::SignalName(signal) << "\n" << note;
}

std::string FirmwareProcess::CrashSummary() const {
  if (crash_frames_.empty()) return {};
  std::string shown;
  for (std::size_t i = 0; i < crash_frames_.size() && i < 3; ++i) {
    // "#0  0x000055d0c1 in crash_here (p=0x0) at fw.c:2" -> "crash_here (p=0x0) at fw.c:2"
    std::string f = crash_frames_[i];
    if (const std::size_t in = f.find(" in "); in != std::string::npos) {
      f = f.substr(in + 4);
    } else if (const std::size_t sp = f.find_first_of(' '); sp != std::string::npos) {
      f = f.substr(f.find_first_not_of(' ', sp));
    }
    shown += (i == 0 ? "" : " <- ") + f;
  }
  return fmt::format("; first frames: {} (firmware.core; {} frames in firmware.log)", shown,
                     crash_frames_.size());
}

std::string FirmwareProcess::ExitDescription() const {
  if (wait_status_ < 0) return {};
  if (WIFSIGNALED(wait_status_)) {
    return fmt::format("was killed by {}{}", sim::SignalName(WTERMSIG(wait_status_)),
                       WCOREDUMP(wait_status_) ? ", core dumped" : "");
  }
  return fmt::format("exited with status {}", WEXITSTATUS(wait_status_));
}

std::optional<int> FirmwareProcess::Exited() {
  if (pid_ <= 0) return std::nullopt;
  int status = 0;
  if (::waitpid(pid_, &status, WNOHANG) == pid_) {
    Reaped(status);
    return exit_status_;
  }
  return std::nullopt;
}

void FirmwareProcess::Stop(const std::function<void()>& while_waiting) {
  if (pid_ <= 0) return;
  const pid_t group = pid_;
  (void)::kill(-group, SIGTERM);
  scope_.Signal(SIGTERM);  // also what left the group
  const auto t0 = std::chrono::steady_clock::now();
  while (std::chrono::steady_clock::now() - t0 < std::chrono::seconds(2)) {
    if (Exited()) return;
    if (while_waiting) {
      while_waiting();
    } else {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }
  (void)::kill(-group, SIGKILL);
  int status = 0;
  ::waitpid(pid_, &status, 0);
  Reaped(status);
}

std::string Substitute(std::string s, const std::string& key, const std::string& value) {
  for (std::size_t pos = s.find(key); pos != std::string::npos; pos = s.find(key, pos)) {
    s.replace(pos, key.size(), value);
    pos += value.size();
  }
  return s;
}

}  // namespace wheelhil::emulator::firmware
