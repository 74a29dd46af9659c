#include "emulator/firmware/firmware_process.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <functional>
#include <cstdlib>
#include <stdexcept>
#include <thread>

#include <fmt/format.h>

#include "emulator/sim/signal_name.h"

namespace wheelhil::emulator::firmware {

void FirmwareProcess::Start(const std::string& command,
                            const std::vector<std::pair<std::string, std::string>>& env,
                            const std::string& log_path) {
  const int log_fd = ::open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  ProcessScope::BecomeSubreaper();
  scope_ = ProcessScope();
  wait_status_ = -1;
  const auto [marker_key, marker_value] = scope_.EnvironmentEntry();
  const pid_t parent = ::getpid();
  pid_ = ::fork();
  if (pid_ < 0) {
    if (log_fd >= 0) ::close(log_fd);
    throw std::runtime_error("fork failed");
  }
  if (pid_ == 0) {
    ::setpgid(0, 0);
    (void)::prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (::getppid() != parent) ::_exit(127);  // the run died before the line above
    for (const auto& [k, v] : env) ::setenv(k.c_str(), v.c_str(), 1);
    ::setenv(marker_key.c_str(), marker_value.c_str(), 1);
    if (log_fd >= 0) {
      ::dup2(log_fd, 1);
      ::dup2(log_fd, 2);
    }
    const std::string sh = "exec " + command;
    ::execl("/bin/sh", "sh", "-c", sh.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
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
