#pragma once
/// What a killed run leaves behind, removed by the next one. A run's private bus lives in a
/// fresh runtime directory (`$TMPDIR/wheelhil-run-XXXXXX`, or /tmp) that its broker removes on
/// any exit but SIGKILL; the broker holds a lock on `ucan.lock` there for as long as it lives,
/// so a directory whose lock nobody holds is stale. Linux only; never throws.

#include <string>
#include <vector>

namespace wheelhil::emulator::firmware {

/// Removes each `<$TMPDIR or /tmp>/<prefix>*` directory that is owned by this user with mode
/// 0700, has not changed for `min_age_s` (a run that is just starting has not locked it yet)
/// and whose lock no process holds (or that has none). A process still running there (its
/// WHEELHIL_UCAN_DIR names the directory: a firmware its run could not stop) is killed first.
/// Returns the directories removed.
std::vector<std::string> RemoveStaleRunDirs(const std::string& prefix, double min_age_s = 10.0);

}  // namespace wheelhil::emulator::firmware
