#pragma once
/// Every process a firmware started, found through /proc, so that none outlives its run. A
/// process is in the scope when it is in the firmware's process group, carries the scope's
/// marker in its environment (WHEELHIL_FIRMWARE_SCOPE=<token>, inherited by everything the
/// firmware starts, `setsid` children included), descends from a process in the scope, or is
/// a child of this process started after the firmware: this process is a subreaper
/// (BecomeSubreaper), so an orphan of the firmware's is re-parented here, and it starts no
/// other children while a firmware runs. Linux only; thread-compatible.

#include <sys/types.h>

#include <cstddef>
#include <string>
#include <utility>
#include <vector>

namespace wheelhil::emulator::firmware {

class ProcessScope {
 public:
  /// A token unique to this process and scope (pid, a counter and the time).
  ProcessScope();

  /// The environment entry that marks the scope's processes.
  std::pair<std::string, std::string> EnvironmentEntry() const;
  /// The process group the firmware leads (its pid), once started.
  void set_group(pid_t group);

  /// The pids in the scope now (this process excluded).
  std::vector<pid_t> Members();
  /// Sends `signal` to every member; returns how many it reached.
  std::size_t Signal(int signal);
  /// SIGKILLs the members until a scan finds none (members that fork while being killed are
  /// caught by the next pass), reaping those that are this process's children. Gives up after
  /// `max_passes` passes of 10 ms; returns how many processes it killed.
  std::size_t KillAll(int max_passes = 100);

  /// Makes this process adopt its orphaned descendants (PR_SET_CHILD_SUBREAPER), so a
  /// firmware's helper whose parent exits stays findable. Idempotent, process-wide.
  static void BecomeSubreaper();

 private:
  std::string token_;
  pid_t group_ = -1;
  unsigned long long started_ = 0;  // the firmware's start time, clock ticks after boot
};

/// One line of /proc/<pid>/stat: what a scan needs. False when the process is gone.
struct ProcStat {
  pid_t pid = 0;
  pid_t ppid = 0;
  pid_t pgrp = 0;
  char state = '?';
  unsigned long long start_time = 0;  ///< clock ticks after boot
};
bool ReadProcStat(pid_t pid, ProcStat& out);
/// The whole of a small /proc file (at most about 1 MiB); empty when it cannot be read.
std::string ReadProcFile(const std::string& path);
/// The pids under /proc.
std::vector<pid_t> ListPids();
/// Whether /proc/<pid>/environ holds the entry `key=value` (false when it cannot be read).
bool EnvironHas(pid_t pid, const std::string& key, const std::string& value);
/// The file `program` names as the shell would find it: as it is when it holds a '/', else the
/// first executable (not a directory) of that name in PATH's directories (an empty one is the
/// current directory; "/usr/bin:/bin" when PATH is unset). Empty when there is none.
std::string FindOnPath(const std::string& program);
/// This process's environment with `set` applied as setenv would (a key present replaced where
/// it is, a new one appended), as "KEY=VALUE" strings: for a child's execve, made before its
/// fork (the child of a threaded process may not allocate before its exec).
std::vector<std::string> EnvironmentWith(
    const std::vector<std::pair<std::string, std::string>>& set);

}  // namespace wheelhil::emulator::firmware
