#include "emulator/firmware/stale_run_dirs.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <ctime>
#include <filesystem>
#include <system_error>

#include "bus/ucan_protocol.h"
#include "bus/ucan_runtime_dir.h"
#include "emulator/firmware/process_scope.h"

namespace wheelhil::emulator::firmware {

std::vector<std::string> RemoveStaleRunDirs(const std::string& prefix, double min_age_s) {
  namespace fs = std::filesystem;
  std::vector<std::string> removed;
  std::error_code ec;
  fs::directory_iterator it(bus::UcanTempRoot(), ec);
  if (ec) return removed;
  const std::time_t now = std::time(nullptr);
  for (const auto& entry : it) {
    const std::string name = entry.path().filename().string();
    if (name.compare(0, prefix.size(), prefix) != 0) continue;
    const std::string dir = entry.path().string();
    if (bus::VerifyUcanRuntimeDir(dir)) continue;  // not ours, not 0700, or a symlink
    struct stat st {};
    if (::lstat(dir.c_str(), &st) != 0 || static_cast<double>(now - st.st_mtime) < min_age_s) {
      continue;
    }
    const std::string lock = dir + "/" + bus::ucan::kLockName;
    const int fd = ::open(lock.c_str(), O_RDWR | O_CLOEXEC | O_NOFOLLOW);
    if (fd >= 0 && ::flock(fd, LOCK_EX | LOCK_NB) != 0) {
      ::close(fd);  // a live broker
      continue;
    }
    for (pid_t pid : ListPids()) {
      if (pid != ::getpid() && EnvironHas(pid, "WHEELHIL_UCAN_DIR", dir)) (void)::kill(pid, SIGKILL);
    }
    fs::remove_all(dir, ec);
    if (fd >= 0) ::close(fd);
    if (!ec) removed.push_back(dir);
  }
  return removed;
}

}  // namespace wheelhil::emulator::firmware
