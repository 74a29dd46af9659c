#include "emulator/firmware/process_scope.h"

#include <dirent.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <map>
#include <set>
#include <string_view>
#include <system_error>
#include <thread>

#include <fmt/format.h>

namespace wheelhil::emulator::firmware {
namespace {

constexpr const char* kMarkerKey = "WHEELHIL_FIRMWARE_SCOPE";

}  // namespace

std::string ReadProcFile(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return {};
  std::string out;
  char buf[4096];
  for (;;) {
    const ssize_t n = ::read(fd, buf, sizeof buf);
    if (n <= 0) break;
    out.append(buf, static_cast<std::size_t>(n));
    if (out.size() > (std::size_t{1} << 20)) break;  // an environment larger than 1 MiB: enough
  }
  ::close(fd);
  return out;
}

bool ReadProcStat(pid_t pid, ProcStat& out) {
  const std::string text = ReadProcFile(fmt::format("/proc/{}/stat", pid));
  // "pid (comm) state ppid pgrp session tty tpgid flags minflt cminflt majflt cmajflt utime
  // stime cutime cstime priority nice threads itrealvalue starttime ..."; comm may hold spaces
  // and parentheses, so fields are counted from the last ')'.
  const auto close = text.rfind(')');
  if (close == std::string::npos || close + 2 >= text.size()) return false;
  const char* p = text.c_str() + close + 2;
  out.pid = pid;
  out.state = *p;
  char* end = nullptr;
  unsigned long long field[20] = {};
  p += 1;
  for (int i = 0; i < 20; ++i) {  // fields 4 (ppid) .. 23
    field[i] = std::strtoull(p, &end, 10);
    if (end == p) return false;
    p = end;
  }
  out.ppid = static_cast<pid_t>(field[0]);
  out.pgrp = static_cast<pid_t>(field[1]);
  out.start_time = field[18];  // field 22
  return true;
}

std::vector<pid_t> ListPids() {
  std::vector<pid_t> out;
  DIR* d = ::opendir("/proc");
  if (d == nullptr) return out;
  while (const dirent* e = ::readdir(d)) {
    char* end = nullptr;
    const long v = std::strtol(e->d_name, &end, 10);
    if (end != e->d_name && *end == '\0' && v > 0) out.push_back(static_cast<pid_t>(v));
  }
  ::closedir(d);
  return out;
}

std::string FindOnPath(const std::string& program) {
  if (program.find('/') != std::string::npos) return program;
  const char* path = std::getenv("PATH");
  std::string_view dirs(path != nullptr ? path : "/usr/bin:/bin");
  for (;;) {
    const std::size_t colon = dirs.find(':');
    const std::string_view dir = dirs.substr(0, colon);
    const std::string candidate =
        (dir.empty() ? std::string(".") : std::string(dir)) + "/" + program;
    std::error_code ec;
    if (::access(candidate.c_str(), X_OK) == 0 && !std::filesystem::is_directory(candidate, ec)) {
      return candidate;
    }
    if (colon == std::string_view::npos) return {};
    dirs.remove_prefix(colon + 1);
  }
}

std::vector<std::string> EnvironmentWith(
    const std::vector<std::pair<std::string, std::string>>& set) {
  std::vector<std::string> out;
  for (char** e = environ; e != nullptr && *e != nullptr; ++e) out.emplace_back(*e);
  for (const auto& [key, value] : set) {
    const std::string prefix = key + "=";
    const auto at = std::find_if(out.begin(), out.end(), [&](const std::string& e) {
      return e.compare(0, prefix.size(), prefix) == 0;
    });
    if (at != out.end()) {
      *at = prefix + value;
    } else {
      out.push_back(prefix + value);
    }
  }
  return out;
}

bool EnvironHas(pid_t pid, const std::string& key, const std::string& value) {
  const std::string env = ReadProcFile(fmt::format("/proc/{}/environ", pid));
  const std::string entry = key + "=" + value;
  for (std::size_t pos = 0; pos < env.size();) {
    const auto nul = env.find('\0', pos);
    const std::size_t len = (nul == std::string::npos ? env.size() : nul) - pos;
    if (len == entry.size() && env.compare(pos, len, entry) == 0) return true;
    if (nul == std::string::npos) break;
    pos = nul + 1;
  }
  return false;
}

ProcessScope::ProcessScope() {
  static std::atomic<unsigned> counter{0};
  const auto now = std::chrono::steady_clock::now().time_since_epoch();
  token_ = fmt::format("{}-{}-{}", ::getpid(), counter.fetch_add(1),
                       std::chrono::duration_cast<std::chrono::nanoseconds>(now).count());
}

void ProcessScope::set_group(pid_t group) {
  group_ = group;
  ProcStat st;
  // Its child has not exec'd yet, but has started: its start time is known.
  if (ReadProcStat(group, st)) started_ = st.start_time;
}

std::pair<std::string, std::string> ProcessScope::EnvironmentEntry() const {
  return {kMarkerKey, token_};
}

std::vector<pid_t> ProcessScope::Members() {
  const pid_t self = ::getpid();
  std::map<pid_t, ProcStat> all;
  for (pid_t pid : ListPids()) {
    ProcStat st;
    if (pid != self && ReadProcStat(pid, st)) all[pid] = st;
  }
  std::set<pid_t> in;
  for (const auto& [pid, st] : all) {
    if ((group_ > 0 && st.pgrp == group_) ||
        (group_ > 0 && st.ppid == self && st.start_time >= started_) ||
        EnvironHas(pid, kMarkerKey, token_)) {
      in.insert(pid);
    }
  }
  // Descendants of members, to a fixed point (a helper that cleared its environment).
  for (bool grew = true; grew;) {
    grew = false;
    for (const auto& [pid, st] : all) {
      if (in.count(pid) == 0 && in.count(st.ppid) != 0) grew = in.insert(pid).second || grew;
    }
  }
  return std::vector<pid_t>(in.begin(), in.end());
}

std::size_t ProcessScope::Signal(int signal) {
  std::size_t reached = 0;
  for (pid_t pid : Members()) reached += ::kill(pid, signal) == 0;
  return reached;
}

std::size_t ProcessScope::KillAll(int max_passes) {
  const pid_t self = ::getpid();
  std::size_t killed = 0;
  for (int pass = 0; pass < max_passes; ++pass) {
    const std::vector<pid_t> members = Members();
    bool pending = false;  // a member that runs, or a zombie of ours to reap
    for (pid_t pid : members) {
      ProcStat st;
      if (!ReadProcStat(pid, st)) continue;
      if (st.state != 'Z' && ::kill(pid, SIGKILL) == 0) ++killed;
      if (st.ppid == self) (void)::waitpid(pid, nullptr, WNOHANG);
      pending = pending || st.state != 'Z' || st.ppid == self;
    }
    if (!pending) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    // Reap what died in the meantime, so that its zombie does not count as a member.
    for (pid_t pid : members) {
      ProcStat st;
      if (ReadProcStat(pid, st) && st.ppid == self) (void)::waitpid(pid, nullptr, WNOHANG);
    }
  }
  return killed;
}

void ProcessScope::BecomeSubreaper() { (void)::prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0); }

}  // namespace wheelhil::emulator::firmware
