#include "emulator/firmware/virtual_clock.h"

#include <elf.h>
#include <fcntl.h>
#include <linux/can.h>
#include <linux/futex.h>
#include <sched.h>
#include <signal.h>
#include <sys/eventfd.h>
#include <sys/mman.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <new>
#include <string_view>
#include <system_error>

#include <fmt/format.h>

#include "bus/vtime_protocol.h"
#include "emulator/firmware/process_scope.h"

namespace wheelhil::emulator::firmware {

namespace vt = bus::vtime;

namespace {

void FutexWake(std::atomic<std::uint32_t>* word) {
  ::syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(word), FUTEX_WAKE, 1, nullptr, nullptr,
            0);
}

// Reads a /proc file from its start; "" when it is gone.
std::string ReadAt0(int fd) {
  char buf[512];
  const ssize_t n = ::pread(fd, buf, sizeof(buf) - 1, 0);
  return n > 0 ? std::string(buf, static_cast<std::size_t>(n)) : std::string();
}

// The state letter of a /proc .../stat line (after the command in parentheses, which may hold
// spaces); '\0' when the line is not one.
char TaskState(const std::string& stat) {
  const auto close_paren = stat.rfind(')');
  if (close_paren == std::string::npos || close_paren + 2 >= stat.size()) return '\0';
  return stat[close_paren + 2];
}

bool Gone(char state) { return state == '\0' || state == 'Z' || state == 'X'; }

// The timeslices of a /proc .../schedstat line ("run ns, wait ns, timeslices"): the count of
// times the task got a CPU; 0 when the line is not one.
std::uint64_t Timeslices(const std::string& schedstat) {
  const auto last_space = schedstat.rfind(' ');
  return last_space == std::string::npos
             ? 0
             : std::strtoull(schedstat.c_str() + last_space + 1, nullptr, 10);
}

const char* LastCallName(std::uint32_t c) {
  switch (c) {
    case vt::kCallClock: return "a clock read";
    case vt::kCallPollZero: return "a poll/select/epoll with zero timeout";
    case vt::kCallPastDeadline: return "a wait for a deadline already past";
    default: return "nothing the library sees";
  }
}

}  // namespace

VirtualClock::VirtualClock(const std::string& dir) : path_(dir + "/" + vt::kPageName) {
  const int fd = ::open(path_.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
  if (fd < 0) throw std::system_error(errno, std::generic_category(), "create " + path_);
  if (::ftruncate(fd, sizeof(vt::Page)) != 0) {
    const int err = errno;
    ::close(fd);
    throw std::system_error(err, std::generic_category(), "ftruncate " + path_);
  }
  void* p = ::mmap(nullptr, sizeof(vt::Page), PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  const int err = errno;
  ::close(fd);
  if (p == MAP_FAILED) throw std::system_error(err, std::generic_category(), "mmap " + path_);
  page_ = new (p) vt::Page();
  page_->size = sizeof(vt::Page);
  page_->now_ns.store(kMonotonicAtStartNs);
  page_->realtime_offset_ns.store(kRealtimeAtStartNs - kMonotonicAtStartNs);
  files_.resize(vt::kMaxThreads);
}

VirtualClock::~VirtualClock() {
  for (const FdCopy& c : fd_copies_) ::close(c.local_fd);
  for (const auto& [pid, fd] : pidfds_) ::close(fd);
  for (auto& f : files_) {
    if (f.stat_fd >= 0) ::close(f.stat_fd);
    if (f.schedstat_fd >= 0) ::close(f.schedstat_fd);
    if (f.syscall_fd >= 0) ::close(f.syscall_fd);
  }
  if (page_ != nullptr) ::munmap(page_, sizeof(vt::Page));
  ::unlink(path_.c_str());
}

std::vector<std::pair<std::string, std::string>> VirtualClock::ChildEnvironment(
    const std::string& vtime_library) const {
  return {{vt::kPageEnv, path_}, {"WHEELHIL_VTIME_LIB", vtime_library}};
}

void VirtualClock::ExpectFirstProcess() {
  for (int i = 0; i < vt::kMaxProcesses; ++i) {
    vt::ProcessSlot& p = page_->processes[i];
    std::uint32_t expect = vt::kProcFree;
    if (p.state.compare_exchange_strong(expect, vt::kProcStarting)) {
      p.exec_pending.store(0);
      p.pid.store(vt::kFirstProcessPid);
      first_process_slot_ = i;
      return;
    }
  }
}

void VirtualClock::SetFirstProcessPid(pid_t pid) {
  first_pid_ = pid;
  if (first_process_slot_ < 0) return;
  std::int32_t expect = vt::kFirstProcessPid;
  page_->processes[first_process_slot_].pid.compare_exchange_strong(expect, pid);
}

void VirtualClock::SetSpinCost(std::int64_t ns) {
  page_->spin_cost_ns.store(std::max<std::int64_t>(0, ns));
}

void VirtualClock::SetNow(std::int64_t t_ns) {
  const std::int64_t mono = kMonotonicAtStartNs + t_ns;
  if (mono > page_->now_ns.load()) page_->now_ns.store(mono, std::memory_order_release);
}

std::int64_t VirtualClock::now_ns() const { return page_->now_ns.load() - kMonotonicAtStartNs; }

std::int64_t VirtualClock::RealtimeNs() const {
  return page_->now_ns.load() + page_->realtime_offset_ns.load();
}

std::int64_t VirtualClock::NextDeadlineNs() const {
  std::int64_t next = vt::kNoDeadline;
  const int threads = page_->threads_used.load();
  for (int i = 0; i < threads; ++i) {
    const vt::ThreadSlot& s = page_->threads[i];
    if (s.state.load() == vt::kWaiting) next = std::min(next, s.deadline_ns.load());
  }
  const int timers = page_->timers_used.load();
  for (int i = 0; i < timers; ++i) {
    const vt::TimerSlot& t = page_->timers[i];
    if (t.state.load() == vt::kTimerArmed && t.fired.load() == 0) {
      next = std::min(next, t.next_ns.load());
    }
  }
  if (next == vt::kNoDeadline) return next;
  return std::max(next, page_->now_ns.load()) - kMonotonicAtStartNs;
}

void VirtualClock::SendTimerSignal(const vt::TimerSlot& t, pid_t pid) {
  // Any thread of the process may take it, also one the library has waiting on a futex.
  if (std::find(signalled_.begin(), signalled_.end(), pid) == signalled_.end()) {
    signalled_.push_back(pid);
  }
  if (t.notify.load() == vt::kNotifyAlarm) {
    ::kill(pid, SIGALRM);
    return;
  }
  siginfo_t info{};
  info.si_signo = t.signo;
  info.si_code = SI_TIMER;
  info.si_value.sival_ptr = reinterpret_cast<void*>(t.sigval);
  info.si_overrun = static_cast<int>(t.overrun.load());
  if (t.target_tid != 0) {
    ::syscall(SYS_rt_tgsigqueueinfo, pid, t.target_tid, t.signo, &info);
  } else {
    ::syscall(SYS_rt_sigqueueinfo, pid, t.signo, &info);
  }
}

int VirtualClock::WakeDue() {
  // While the firmware holds the clock (runahead), it ends its own waits.
  if (vt::RunaheadStateOf(page_->runahead.load()) != vt::kHostClock) return 0;
  const std::int64_t now = page_->now_ns.load();
  signalled_.clear();
  int ended = 0;
  std::uint32_t channels = 0;  // of the writes and signals that may end a vouched fd wait
  pid_t agents[vt::kMaxProcesses];
  int n_agents = 0;
  auto need_agent = [&](pid_t pid) {
    if (std::find(agents, agents + n_agents, pid) == agents + n_agents) agents[n_agents++] = pid;
  };
  // Timers first: a thread whose wait ends at this instant must find every timer of the
  // instant already fired (a super loop's next look at its timerfd), whichever CPU it wakes on.
  const int timers = page_->timers_used.load();
  for (int i = 0; i < timers; ++i) {
    vt::TimerSlot& t = page_->timers[i];
    if (t.state.load() != vt::kTimerArmed || t.fired.load() != 0 || t.next_ns.load() > now) {
      continue;
    }
    ++ended;
    const pid_t pid = t.pid.load();
    switch (t.notify.load()) {
      case vt::kNotifyEventFd: {
        const std::uint64_t tag = std::uint64_t{1} << 32 | t.generation.load();
        const int copy = CopyOfFd(pid, t.fd, tag);
        if (copy >= 0) {
          eventfd_write(copy, vt::ExpireTimer(t, now));
          channels |= vt::TimerChannel(i);
          continue;
        }
        break;  // the agent writes it
      }
      case vt::kNotifySignal:
      case vt::kNotifyAlarm:
        vt::ExpireTimer(t, now);
        SendTimerSignal(t, pid);
        channels |= vt::kAnyChannel;
        continue;
      case vt::kNotifyNone:
        vt::ExpireTimer(t, now);
        continue;
      default:
        break;  // kNotifyThread: the agent starts the thread
    }
    t.fired.store(1);
    need_agent(pid);
  }
  const int threads = page_->threads_used.load();
  for (int i = 0; i < threads; ++i) {
    vt::ThreadSlot& s = page_->threads[i];
    if (s.state.load() != vt::kWaiting || s.deadline_ns.load() > now) continue;
    std::uint32_t expect = vt::kWaiting;
    if (!s.state.compare_exchange_strong(expect, vt::kRunning)) continue;  // it woke itself
    ++ended;
    const std::uint32_t kind = s.kind.load();
    if (kind == vt::kFdWait) {
      // Its eventfd written here saves the hop through the agent.
      const int copy = s.wake_fd >= 0 ? CopyOfFd(s.pid.load(), s.wake_fd, s.tid.load()) : -1;
      if (copy >= 0 && eventfd_write(copy, 1) == 0) continue;
      s.fired.store(1);
      need_agent(s.pid.load());
    } else if (kind == vt::kCondWait || kind == vt::kFutexWait) {
      // A condition variable or a futex word of the firmware's memory: its agent wakes it.
      s.fired.store(1);
      need_agent(s.pid.load());
    } else if (kind == vt::kSignalWait) {
      ::syscall(SYS_tgkill, s.pid.load(), s.tid.load(), vt::kWakeSignal);
      channels |= vt::kAnyChannel;
    } else {
      s.wake.fetch_add(1);
      FutexWake(&s.wake);
    }
  }
  for (int a = 0; a < n_agents; ++a) {
    for (int p = 0; p < vt::kMaxProcesses; ++p) {
      vt::ProcessSlot& proc = page_->processes[p];
      if (proc.state.load() != vt::kProcAlive || proc.pid.load() != agents[a]) continue;
      const int slot = proc.agent.load();
      if (slot < 0) break;
      vt::ThreadSlot& s = page_->threads[slot];
      s.wake.fetch_add(1);
      std::uint32_t expect = vt::kWaiting;
      s.state.compare_exchange_strong(expect, vt::kRunning);
      FutexWake(&s.wake);
      break;
    }
  }
  // Timerfds written, signals sent: a vouched wait on them may have ended.
  if (channels != 0) NoteFdWakes(channels);
  return ended;
}

void VirtualClock::NoteFdWakes(std::uint32_t channels) { unnoted_channels_ |= channels; }

void VirtualClock::CountFdWakes() {
  if (unnoted_channels_ == 0) return;
  vt::NoteWake(*page_, unnoted_channels_);
  unnoted_channels_ = 0;
}

std::uint64_t VirtualClock::socket_activity() const {
  return page_->bus_calls.load() + threads_freed_;
}

int VirtualClock::CopyOfFd(pid_t pid, int fd, std::uint64_t tag) {
  if (!fd_copies_work_ || pid <= 0 || fd < 0) return -1;
  for (const FdCopy& c : fd_copies_) {
    if (c.pid == pid && c.remote_fd == fd && c.tag == tag) return c.local_fd;
  }
  int pidfd = -1;
  for (const auto& [p, f] : pidfds_) {
    if (p == pid) pidfd = f;
  }
  if (pidfd < 0) {
    pidfd = static_cast<int>(::syscall(SYS_pidfd_open, pid, 0));
    if (pidfd < 0) {
      fd_copies_work_ = false;  // no pidfds here: the agents write
      return -1;
    }
    pidfds_.emplace_back(pid, pidfd);
  }
  const int local = static_cast<int>(::syscall(SYS_pidfd_getfd, pidfd, fd, 0));
  if (local < 0) {
    // EPERM (ptrace policy), ENOSYS: the agents write, for the whole run.
    if (errno != EBADF && errno != ESRCH) fd_copies_work_ = false;
    return -1;
  }
  // A copy for the same fd number with an older tag is another object now.
  for (FdCopy& c : fd_copies_) {
    if (c.pid == pid && c.remote_fd == fd) {
      ::close(c.local_fd);
      c = FdCopy{pid, fd, tag, local};
      return local;
    }
  }
  fd_copies_.push_back(FdCopy{pid, fd, tag, local});
  return local;
}

bool VirtualClock::ProcessAlive(pid_t pid) const {
  return pid > 0 && !Gone(TaskState(ReadProcFile(fmt::format("/proc/{}/stat", pid))));
}

VirtualClock::Kernel VirtualClock::KernelState(int slot, pid_t pid, pid_t tid,
                                               std::uint64_t* runs) {
  ProcFiles& f = files_[static_cast<std::size_t>(slot)];
  if (f.tid != tid) {
    if (f.stat_fd >= 0) ::close(f.stat_fd);
    if (f.schedstat_fd >= 0) ::close(f.schedstat_fd);
    if (f.syscall_fd >= 0) ::close(f.syscall_fd);
    f = ProcFiles{};
    f.tid = tid;
    const std::string dir = fmt::format("/proc/{}/task/{}/", pid, tid);
    f.stat_fd = ::open((dir + "stat").c_str(), O_RDONLY | O_CLOEXEC);
    f.schedstat_fd = ::open((dir + "schedstat").c_str(), O_RDONLY | O_CLOEXEC);
  }
  if (f.stat_fd < 0) return Kernel::kGone;
  ++kernel_looks_;
  const char state = TaskState(ReadAt0(f.stat_fd));
  if (Gone(state)) return Kernel::kGone;
  if (state == 'T' || state == 't') stopped_seen_ = true;
  if (runs != nullptr) {
    *runs = Timeslices(f.schedstat_fd >= 0 ? ReadAt0(f.schedstat_fd) : std::string());
  }
  return state == 'S' ? Kernel::kAsleep : Kernel::kRunning;
}

void VirtualClock::FreeDeadThread(int slot) {
  // A process that ends signals its parent (SIGCHLD), which may end a wait the library vouched
  // for: the next look asks the kernel about every fd wait once.
  NoteFdWakes(vt::kAnyChannel);
  ++threads_freed_;  // its process may have closed its sockets
  vt::ThreadSlot& s = page_->threads[slot];
  if (s.pid.load() == first_pid_) threads_gone_ = true;
  // A thread gone: perhaps its whole process (the slot of an exited process is freed here,
  // not looked at on every check).
  const pid_t pid = s.pid.load();
  if (!ProcessAlive(pid)) {
    for (auto& proc : page_->processes) {
      if (proc.state.load() == vt::kProcAlive && proc.pid.load() == pid) {
        proc.state.store(vt::kProcFree);
      }
    }
  }
  s.tid.store(0);
  s.pid.store(0);
  s.state.store(vt::kFree);
}

void VirtualClock::GrantRunahead(std::int64_t until_ns, std::int64_t step_ns, std::int64_t phase_ns,
                                 const SendPlan* sends) {
  CountFdWakes();
  // A vouched fd wait that a write of the host's came after (the host counts its writes after
  // making them, when the thread may have begun its next wait already) is no longer vouched
  // for, and the firmware's library would take its thread for on its way out of it and never
  // move the clock. Asleep in the kernel now, after all of the host's writes, none of its fds
  // is ready: it is vouched for again, from here.
  const int threads = page_->threads_used.load();
  for (int i = 0; i < threads; ++i) {
    vt::ThreadSlot& s = page_->threads[i];
    if (s.state.load() != vt::kWaiting || s.kind.load() != vt::kFdWait || s.vouched.load() == 0 ||
        vt::VouchHolds(*page_, s)) {
      continue;
    }
    const std::uint32_t wakes = page_->fd_wakes.load();
    if (KernelState(i, s.pid.load(), s.tid.load(), nullptr) == Kernel::kAsleep &&
        s.state.load() == vt::kWaiting) {
      s.entry_wakes.store(wakes);
    }
  }
  page_->runahead_until_ns.store(kMonotonicAtStartNs + until_ns);
  page_->runahead_step_ns.store(step_ns);
  page_->runahead_phase_ns.store(kMonotonicAtStartNs + phase_ns);
  page_->runahead_sends.store(page_->bus_sends.load());
  WriteSendRules(sends);
  page_->runahead.store(vt::NextRunaheadWord(page_->runahead.load(), vt::kGranted));
  // A thread that published its wait before the grant does not look again: a wake-up makes
  // the last thread to block look (its wait ends, it waits again).
}

void VirtualClock::WriteSendRules(const SendPlan* plan) {
  vt::SendRules& r = page_->sends;
  r.enabled.store(0);
  r.foreseen_taken.store(0);
  r.free_ns.store(0);
  r.sent_count.store(0);
  if (plan == nullptr) return;
  r.foreseen_count = 0;
  for (const auto& [t_ns, f] : plan->foreseen) {
    if (r.foreseen_count == vt::kMaxForeseenSends) break;
    vt::ForeseenSend& e = r.foreseen[r.foreseen_count++];
    e.instant_ns = kMonotonicAtStartNs + t_ns;
    e.can_id = f.id | (f.extended ? CAN_EFF_FLAG : 0u) | (f.rtr ? CAN_RTR_FLAG : 0u);
    e.len = f.len;
    std::memset(e.data, 0, sizeof(e.data));
    std::memcpy(e.data, f.data.data(), std::min<std::size_t>(f.len, sizeof(e.data)));
  }
  r.gap_count =
      static_cast<std::uint32_t>(std::min<std::size_t>(plan->gaps.size(), vt::kMaxSendGaps));
  r.gap_first_ns = kMonotonicAtStartNs + plan->gaps_first_ns;
  for (std::uint32_t i = 0; i < r.gap_count; ++i) {
    r.gaps[i].idle_ns = kMonotonicAtStartNs + plan->gaps[i].idle_ns;
    r.gaps[i].busy_ns = kMonotonicAtStartNs + plan->gaps[i].busy_ns;
    r.gaps[i].max_key = plan->gaps[i].max_key;
  }
  r.bit_ns = plan->bit_ns;
  for (int w = 0; w < vt::kStandardIds / 64; ++w) {
    std::uint64_t bits = 0;
    for (int b = 0; b < 64; ++b) {
      if (plan->unread_ids.test(static_cast<std::size_t>(w * 64 + b)))
        bits |= std::uint64_t{1} << b;
    }
    r.unread_ids[w] = bits;
  }
  r.enabled.store(1);
}

std::uint64_t VirtualClock::KernelCanSends() const { return page_->kernel_can_sends.load(); }

std::uint64_t VirtualClock::sends_through() const { return page_->sends.through.load(); }

void VirtualClock::TakeSendsThroughAt(std::vector<std::int64_t>& instants_ns) const {
  const vt::SendRules& r = page_->sends;
  const std::uint32_t n = std::min<std::uint32_t>(r.sent_count.load(), vt::kMaxSendsThrough);
  instants_ns.clear();
  for (std::uint32_t i = 0; i < n; ++i) instants_ns.push_back(r.sent_at[i] - kMonotonicAtStartNs);
}

bool VirtualClock::KickRunahead() {
  CountFdWakes();
  for (int p = 0; p < vt::kMaxProcesses; ++p) {
    vt::ProcessSlot& proc = page_->processes[p];
    if (proc.state.load() != vt::kProcAlive) continue;
    const int slot = proc.agent.load();
    if (slot < 0 || page_->threads[slot].tid.load() == 0) return false;
    vt::ThreadSlot& s = page_->threads[slot];
    // Running already, it waits again soon, and moves the clock on then.
    std::uint32_t expect = vt::kWaiting;
    if (!s.state.compare_exchange_strong(expect, vt::kRunning)) return expect == vt::kRunning;
    s.wake.fetch_add(1);
    FutexWake(&s.wake);
    return true;
  }
  return false;
}

void VirtualClock::RevokeRunahead() {
  page_->runahead.store(vt::NextRunaheadWord(page_->runahead.load(), vt::kHostClock));
}

bool VirtualClock::RunaheadGranted() const {
  return vt::RunaheadStateOf(page_->runahead.load()) != vt::kHostClock;
}

std::uint64_t VirtualClock::local_advances() const { return page_->local_advances.load(); }

bool VirtualClock::Blocked() {
  CountFdWakes();
  bool unvouchable = false;
  std::uint32_t word = page_->runahead.load();
  const bool all_blocked = AllThreadsBlocked(&unvouchable);
  if (all_blocked && unvouchable) ++blocked_seen_in_kernel_;
  if (vt::RunaheadStateOf(word) == vt::kHostClock) return all_blocked;
  if (!all_blocked || vt::RunaheadStateOf(word) != vt::kGranted) return false;
  // Every thread blocked with the clock granted and nobody holding it since before the look:
  // a thread holds it (kLocalAdvance) from before it publishes its wait until it has moved the
  // clock or given it back, so nobody will (a thread asleep outside the library's waits, or
  // waits published before the grant that no kick woke). The swap fails if a thread held the
  // clock since `word` was read.
  return page_->runahead.compare_exchange_strong(word, vt::NextRunaheadWord(word, vt::kHostClock));
}

bool VirtualClock::AllThreadsBlocked(bool* unvouchable) {
  stopped_seen_ = false;
  const std::uint32_t t0 = page_->transitions.load();
  transitions_seen_ = t0;
  for (int p = 0; p < vt::kMaxProcesses; ++p) {
    vt::ProcessSlot& proc = page_->processes[p];
    const std::uint32_t st = proc.state.load();
    if (st == vt::kProcFree) continue;
    const pid_t pid = proc.pid.load();
    if (st == vt::kProcStarting || st == vt::kProcOutside) {
      if (pid > 0 && !ProcessAlive(pid)) {
        proc.state.store(vt::kProcFree);
        continue;
      }
      if (st == vt::kProcOutside) continue;  // its threads' slots say whether it is blocked
      if (pid > 0 && proc.exec_pending.load() != 0 && FoundOffTheClock(pid)) {
        std::uint32_t expect = vt::kProcStarting;
        proc.state.compare_exchange_strong(expect, vt::kProcOutside);
        continue;
      }
      return false;  // forked or started, its library not there yet
    }
  }
  const int threads = page_->threads_used.load();
  bool blocked = true;
  for (int i = 0; i < threads; ++i) {
    vt::ThreadSlot& s = page_->threads[i];
    const std::uint32_t st = s.state.load();
    if (st == vt::kFree) continue;
    const pid_t pid = s.pid.load();
    const pid_t tid = s.tid.load();
    if (tid == 0) return false;  // created, not started
    if (st == vt::kWaiting) {
      const std::uint32_t kind = s.kind.load();
      // Only WakeDue ends these, unless it sent a signal to their process at this instant. A
      // vouched fd wait: nothing that could end it happened since it found its fds not ready.
      const bool only_host_ends =
          kind == vt::kSleep || kind == vt::kAgent ||
          (kind == vt::kFdWait && s.vouched.load() != 0 && vt::VouchHolds(*page_, s));
      if (only_host_ends && s.resumed.load() == 0 &&
          (signalled_.empty() ||
           std::find(signalled_.begin(), signalled_.end(), pid) == signalled_.end())) {
        continue;
      }
      // An fd or a condition variable may have woken it before it could say so.
      if (kind != vt::kFdWait || s.vouched.load() == 0 || s.resumed.load() != 0) {
        *unvouchable = true;
      }
      const Kernel k = KernelState(i, pid, tid, nullptr);
      if (k == Kernel::kGone) {
        FreeDeadThread(i);
        blocked = false;  // look again (FreeDeadThread)
      } else if (k == Kernel::kRunning) {
        return false;
      }
      continue;
    }
    // Running as far as the library knows: blocked only if asleep in the kernel and it did not
    // run since it was last seen asleep. A wait another firmware thread ended (runahead) was
    // not seen ending by the host: it runs, whatever the kernel says yet.
    if (vt::LocallyWoken(*page_, i)) return false;
    *unvouchable = true;
    std::uint64_t runs = 0;
    const Kernel k = KernelState(i, pid, tid, &runs);
    ProcFiles& f = files_[static_cast<std::size_t>(i)];
    if (k == Kernel::kGone) {
      FreeDeadThread(i);
      blocked = false;  // look again (FreeDeadThread)
    } else if (k == Kernel::kRunning) {
      f.runs_seen = UINT64_MAX;
      return false;
    } else if (f.runs_seen != runs) {
      f.runs_seen = runs;
      blocked = false;  // look again
      CheckKernelWait(i, pid, tid);
    }
  }
  return blocked && page_->transitions.load() == t0;
}

void VirtualClock::WaitWhileGranted(int timeout_us) {
  CountFdWakes();
  const std::uint32_t word = page_->runahead.load();
  if (vt::RunaheadStateOf(word) == vt::kHostClock) return;
  // The word also changes while a thread holds the clock (no wake then): a changed word makes
  // the wait return at once, and the caller looks and comes back.
  const timespec ts{timeout_us / 1000000, static_cast<long>(timeout_us % 1000000) * 1000};
  ::syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(&page_->runahead), FUTEX_WAIT, word, &ts,
            nullptr, 0);
}

void VirtualClock::WaitForChange(int timeout_us) {
  CountFdWakes();
  if (shares_cpu_ && yields_in_vain_ < kYieldsBeforeSleep) {
    // The firmware runs on this CPU once this thread makes way, and the host is back when it
    // blocks: no wake-up for it to send (a system call on its side).
    if (page_->transitions.load() == transitions_seen_) ::sched_yield();
    yields_in_vain_ = page_->transitions.load() == transitions_seen_ ? yields_in_vain_ + 1 : 0;
    return;
  }
  yields_in_vain_ = 0;
  page_->host_waiting.store(1);
  if (page_->transitions.load() == transitions_seen_) {
    const timespec ts{0, static_cast<long>(timeout_us) * 1000};
    ::syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(&page_->transitions), FUTEX_WAIT,
              transitions_seen_, &ts, nullptr, 0);
  }
  page_->host_waiting.store(0);
}

std::string VirtualClock::ThreadName(pid_t pid, pid_t tid) {
  std::string name = ReadProcFile(fmt::format("/proc/{}/task/{}/comm", pid, tid));
  while (!name.empty() && name.back() == '\n') name.pop_back();
  return name.empty() ? std::string("?") : name;
}

void VirtualClock::CheckKernelWait(int slot, pid_t pid, pid_t tid) {
  ProcFiles& f = files_[static_cast<std::size_t>(slot)];
  if (f.syscall_fd == -1) {
    // Readable with ptrace access: the firmware is our descendant.
    f.syscall_fd = ::open(fmt::format("/proc/{}/task/{}/syscall", pid, tid).c_str(),
                          O_RDONLY | O_CLOEXEC);
    if (f.syscall_fd < 0) f.syscall_fd = -2;
  }
  if (f.syscall_fd < 0) return;
  const HostClockWait w = ClassifyKernelWait(ReadAt0(f.syscall_fd));
  if (w.call == nullptr) return;
  if (std::find(f.calls_reported.begin(), f.calls_reported.end(), w.number) !=
      f.calls_reported.end()) {
    return;
  }
  f.calls_reported.push_back(w.number);
  host_clock_waits_.push_back(fmt::format(
      "thread '{}' (pid {}, tid {}) is in {}, a timed wait that bypassed libwheelhil_vtime.so "
      "(a raw system call or a libc-internal wait): it ends on the host's clock, so this run may "
      "not be deterministic (docs/virtual-time.md, \"Limits\")",
      ThreadName(pid, tid), pid, tid, w.call));
}

std::vector<std::string> VirtualClock::RunningThreads() {
  std::vector<std::string> out;
  const int threads = page_->threads_used.load();
  for (int i = 0; i < threads; ++i) {
    vt::ThreadSlot& s = page_->threads[i];
    if (s.state.load() != vt::kRunning) continue;
    const pid_t pid = s.pid.load();
    const pid_t tid = s.tid.load();
    if (KernelState(i, pid, tid, nullptr) != Kernel::kRunning) continue;
    out.push_back(fmt::format("thread '{}' (pid {}, tid {}) last called {} ({} such calls since "
                              "its last wait)",
                              ThreadName(pid, tid), pid, tid, LastCallName(s.last_call.load()),
                              s.calls.load()));
  }
  return out;
}

pid_t VirtualClock::UnregisteredProcess() const {
  pid_t outside = 0;
  for (int p = 0; p < vt::kMaxProcesses; ++p) {
    const vt::ProcessSlot& proc = page_->processes[p];
    if (proc.state.load() == vt::kProcStarting) return proc.pid.load();
    if (proc.state.load() == vt::kProcOutside && outside == 0) outside = proc.pid.load();
  }
  return outside;
}

std::string VirtualClock::DescribeProcess(pid_t pid) {
  const std::string stat = ReadProcFile(fmt::format("/proc/{}/stat", pid));
  const char state = TaskState(stat);
  if (stat.empty() || Gone(state)) return "gone";
  std::string out = fmt::format("'{}', {} ({})", ThreadName(pid, pid),
                                state == 'R'                   ? "running"
                                : state == 'T' || state == 't' ? "stopped"
                                                               : "asleep",
                                state);
  if (state != 'R') {
    const std::string wchan = ReadProcFile(fmt::format("/proc/{}/wchan", pid));
    if (!wchan.empty() && wchan != "0") out += " in " + wchan;
    const std::string call = ReadProcFile(fmt::format("/proc/{}/syscall", pid));
    if (!call.empty() && call.find_first_of(" \n") > 0) {
      out += ", system call " + call.substr(0, call.find_first_of(" \n"));
    }
  }
  const std::string maps = ReadProcFile(fmt::format("/proc/{}/maps", pid));
  out += maps.find("libwheelhil_vtime") != std::string::npos ? ", libwheelhil_vtime.so loaded"
                                                             : ", libwheelhil_vtime.so not loaded";
  return out;
}

bool VirtualClock::FoundOffTheClock(pid_t pid) {
  // Until its exec is done the process has the old program's environment, which has the
  // library; after it, a program that has it registers soon, one without it never does.
  const std::string env = ReadProcFile(fmt::format("/proc/{}/environ", pid));
  const std::string page_var = std::string(vt::kPageEnv) + "=";
  std::string preload;
  bool page = false;
  for (std::size_t at = 0; at < env.size();) {
    const std::size_t end = std::min(env.find('\0', at), env.size());
    const std::string_view var(env.data() + at, end - at);
    if (var.substr(0, 11) == "LD_PRELOAD=") preload = std::string(var.substr(11));
    if (var.substr(0, page_var.size()) == page_var) page = true;
    at = end + 1;
  }
  // (An empty environment is one: `env -i`; but so reads a process in the middle of its exec,
  // whose new program's memory has no environment yet.)
  std::string why;
  if (!page || preload.find("libwheelhil_vtime") == std::string::npos) {
    why = "its LD_PRELOAD no longer has it";
  } else if (IsStaticExecutable(fmt::format("/proc/{}/exe", pid))) {
    why = "a statically linked executable, into which nothing can be preloaded";
  } else {
    return false;
  }
  // Judged only once it waits: asleep in the kernel twice without running in between, which a
  // program whose library is on its way to register it does not do (exec, loading and the
  // library's start-up do not sleep).
  const std::uint64_t runs = Timeslices(ReadProcFile(fmt::format("/proc/{}/schedstat", pid)));
  const bool asleep = TaskState(ReadProcFile(fmt::format("/proc/{}/stat", pid))) == 'S';
  auto seen = std::find_if(starting_asleep_.begin(), starting_asleep_.end(),
                           [pid](const auto& p) { return p.first == pid; });
  if (!asleep || seen == starting_asleep_.end() || seen->second != runs) {
    if (seen != starting_asleep_.end()) starting_asleep_.erase(seen);
    if (asleep) starting_asleep_.emplace_back(pid, runs);
    return false;
  }
  starting_asleep_.erase(seen);
  off_the_clock_.push_back(fmt::format(
      "process {} ('{}') exec'd a program without libwheelhil_vtime.so ({}): it runs on the "
      "host's clock, so this run may not be deterministic (docs/virtual-time.md, \"Reading a "
      "run that does not advance\")",
      pid, ThreadName(pid, pid), why));
  return true;
}

namespace {

// The program a shell command line runs: its first word after `exec`, `env` and assignments.
std::string ProgramOf(const std::string& command) {
  std::size_t i = 0;
  for (;;) {
    while (i < command.size() && std::isspace(static_cast<unsigned char>(command[i]))) ++i;
    std::size_t j = i;
    while (j < command.size() && !std::isspace(static_cast<unsigned char>(command[j]))) ++j;
    const std::string word = command.substr(i, j - i);
    if (word.empty()) return word;
    if (word == "exec" || word == "env" || word.find('=') != std::string::npos) {
      i = j;
      continue;
    }
    return word;
  }
}

}  // namespace

HostClockWait ClassifyKernelWait(const std::string& line) {
  char* end = nullptr;
  const long nr = std::strtol(line.c_str(), &end, 10);
  if (end == line.c_str() || nr < 0) return {};
  std::uint64_t a[6] = {};
  const char* p = end;
  for (auto& arg : a) {
    char* next = nullptr;
    arg = std::strtoull(p, &next, 16);
    if (next == p) return {};
    p = next;
  }
  auto timed = [&](bool t, const char* name) {
    return t ? HostClockWait{nr, name} : HostClockWait{};
  };
  auto as_int = [](std::uint64_t v) { return static_cast<std::int32_t>(v & 0xffffffffu); };
  switch (nr) {
    case SYS_nanosleep: return {nr, "nanosleep"};
    case SYS_clock_nanosleep: return {nr, "clock_nanosleep"};
    case SYS_futex: {
      const auto cmd = static_cast<int>(a[1]) & FUTEX_CMD_MASK;
      const bool waits = cmd == FUTEX_WAIT || cmd == FUTEX_WAIT_BITSET || cmd == FUTEX_LOCK_PI ||
                         cmd == FUTEX_WAIT_REQUEUE_PI;
      return timed(waits && a[3] != 0, "futex");
    }
    case SYS_poll: return timed(as_int(a[2]) > 0, "poll");
    case SYS_ppoll: return timed(a[2] != 0, "ppoll");
    case SYS_select: return timed(a[4] != 0, "select");
    case SYS_pselect6: return timed(a[4] != 0, "pselect6");
    case SYS_epoll_wait: return timed(as_int(a[3]) > 0, "epoll_wait");
    case SYS_epoll_pwait: return timed(as_int(a[3]) > 0, "epoll_pwait");
#ifdef SYS_epoll_pwait2
    case SYS_epoll_pwait2: return timed(a[3] != 0, "epoll_pwait2");
#endif
    case SYS_rt_sigtimedwait: return timed(a[2] != 0, "rt_sigtimedwait");
    case SYS_mq_timedreceive: return timed(a[4] != 0, "mq_timedreceive");
    case SYS_mq_timedsend: return timed(a[4] != 0, "mq_timedsend");
    case SYS_recvmmsg: return timed(a[4] != 0, "recvmmsg");
    case SYS_semtimedop: return timed(a[3] != 0, "semtimedop");
    case SYS_io_getevents: return timed(a[4] != 0, "io_getevents");
    default: return {};
  }
}

bool IsStaticExecutable(const std::string& file) {
  const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return false;
  Elf64_Ehdr eh{};
  bool is_static = false;
  if (::pread(fd, &eh, sizeof(eh), 0) == static_cast<ssize_t>(sizeof(eh)) &&
      std::memcmp(eh.e_ident, ELFMAG, SELFMAG) == 0 && eh.e_ident[EI_CLASS] == ELFCLASS64 &&
      eh.e_phentsize == sizeof(Elf64_Phdr)) {
    is_static = true;
    for (int i = 0; i < eh.e_phnum; ++i) {
      Elf64_Phdr ph{};
      if (::pread(fd, &ph, sizeof(ph),
                  static_cast<off_t>(eh.e_phoff + static_cast<std::uint64_t>(i) * sizeof(ph))) !=
          static_cast<ssize_t>(sizeof(ph))) {
        break;
      }
      if (ph.p_type == PT_INTERP) is_static = false;
    }
  }
  ::close(fd);
  return is_static;
}

std::string WhyNotVirtualClock(const std::string& command) {
  const std::string program = ProgramOf(command);
  const std::string file = program.empty() ? std::string() : FindOnPath(program);
  if (file.empty() || !IsStaticExecutable(file)) return {};
  return fmt::format("{} is a statically linked executable: no library can be preloaded into it, "
                     "so its clock cannot be the run's (link it dynamically, or run it with "
                     "--realtime)",
                     file);
}

}  // namespace wheelhil::emulator::firmware
