#pragma once
/// The firmware under test as a child process: started through `/bin/sh -c "exec COMMAND"` in a
/// process group of its own, with extra environment variables and its stdout/stderr in a log
/// file. Stop() ends the whole group (the firmware and any helper it started in it): SIGTERM,
/// up to 2 s of grace, then SIGKILL; the firmware is reaped. Exited() polls without blocking.
/// A child that leaves the group (setsid) is not reached. Thread-compatible.

#include <sys/types.h>

#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace wheelhil::emulator::firmware {

class FirmwareProcess {
 public:
  FirmwareProcess() = default;
  ~FirmwareProcess() { Stop(); }
  FirmwareProcess(const FirmwareProcess&) = delete;
  FirmwareProcess& operator=(const FirmwareProcess&) = delete;

  /// Throws std::runtime_error when fork fails.
  void Start(const std::string& command,
             const std::vector<std::pair<std::string, std::string>>& env,
             const std::string& log_path);
  /// The exit status once it has exited (128 + signal for a signal), else nullopt.
  std::optional<int> Exited();
  /// Ends the process group (see above). Idempotent. `while_waiting` (each call short) runs
  /// in the grace period instead of a sleep: a firmware on the virtual clock needs its time to
  /// go on to see its own shutdown through.
  void Stop(const std::function<void()>& while_waiting = nullptr);
  bool running() const { return pid_ > 0; }
  pid_t pid() const { return pid_; }

 private:
  pid_t pid_ = -1;
  int exit_status_ = 0;
};

/// Replaces every `key` in `s` by `value` (the command line's ${CAN}, ${CONFIG}, ${BIN}).
std::string Substitute(std::string s, const std::string& key, const std::string& value);

}  // namespace wheelhil::emulator::firmware
