#pragma once
/// The first frames of a crashed firmware's stack, from its core file and gdb, for the crash
/// report. Only when the kernel wrote a core (the firmware's RLIMIT_CORE, which the run
/// inherits from the user's `ulimit -c`, is not 0) to a file (`/proc/sys/kernel/core_pattern`
/// a path with at most %p and %%, not a pipe to systemd-coredump or apport), and gdb is
/// installed. The core is moved next to the firmware's log (`firmware.core`): it is the run's.
/// Thread-compatible; runs gdb (up to 20 s) as a child process.

#include <sys/types.h>

#include <string>
#include <vector>

namespace wheelhil::emulator::firmware {

struct CrashFrames {
  std::vector<std::string> frames;  ///< gdb's "#0 ..." lines, at most 8.
  std::string core_path;            ///< Where the core is now; empty when none was found.
  std::string note;                 ///< Why there are no frames, when there are none.
};

/// `pid` crashed with a core (WCOREDUMP); `cwd`: its working directory; `keep_dir`: where the
/// core goes. Never throws.
CrashFrames ReadCrashFrames(pid_t pid, const std::string& cwd, const std::string& keep_dir);

}  // namespace wheelhil::emulator::firmware
