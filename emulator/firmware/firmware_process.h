#pragma once
/// The firmware under test as a child process: started through `/bin/sh -c "exec COMMAND"` (or,
/// for a COMMAND of plain words the shell would only split, its program exec'd directly) in a
/// process group of its own, with extra environment variables and its stdout/stderr in a log
/// file. Stop() ends every process the firmware started (its ProcessScope: the group, `setsid`
/// children, orphans): SIGTERM, up to 2 s of grace, then SIGKILL until none is left; the
/// firmware is reaped. When it exits by itself, what it left is killed as soon as Exited()
/// sees it. It dies with the thread that started it (PR_SET_PDEATHSIG), so a killed run does
/// not leave it running. Exited() polls without blocking. Thread-compatible.

#include <sys/types.h>

#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "emulator/firmware/process_scope.h"

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
  /// How it ended, for a failure reason: "exited with status 3", "was killed by signal 11
  /// (SIGSEGV)". Empty while it runs.
  std::string ExitDescription() const;
  /// After a crash with a core: "; first frames: crash_here (p=0x0) at fw.c:2 <- caller () at
  /// fw.c:3 <- main () at fw.c:4 (firmware.core; 8 frames in firmware.log)", else empty (the
  /// log says why there are none: core dumps off, gdb missing, ...). See crash_frames.h.
  std::string CrashSummary() const;
  /// Ends the process group (see above). Idempotent. `while_waiting` (each call short) runs
  /// in the grace period instead of a sleep: a firmware on the virtual clock needs its time to
  /// go on to see its own shutdown through.
  void Stop(const std::function<void()>& while_waiting = nullptr);
  bool running() const { return pid_ > 0; }
  pid_t pid() const { return pid_; }

 private:
  void Reaped(int wait_status);
  // Reads the core's first frames (or says in the log why there are none).
  void NoteCrash(int signal, bool core_dumped);

  pid_t pid_ = -1;
  pid_t started_pid_ = -1;
  std::string log_path_;
  std::string cwd_;
  std::vector<std::string> crash_frames_;
  int exit_status_ = 0;
  int wait_status_ = -1;  // as waitpid gave it; -1 before the end
  ProcessScope scope_;
};

/// Replaces every `key` in `s` by `value` (the command line's ${CAN}, ${CONFIG}, ${BIN}).
std::string Substitute(std::string s, const std::string& key, const std::string& value);

}  // namespace wheelhil::emulator::firmware
