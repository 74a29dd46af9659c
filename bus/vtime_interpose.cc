// libwheelhil_vtime.so: runs a program on the emulator's virtual clock (bus/vtime_protocol.h,
// docs/virtual-time.md). Preloaded before libwheelhil_ucan.so; inactive unless
// $WHEELHIL_VTIME names the clock page of a run.
//
// Clock reads return the page's time. Every timed wait becomes a wait without timeout plus a
// deadline in the thread's slot: a sleep waits on the slot's futex, a poll/select/epoll adds
// the thread's eventfd to what it waits for, a condition variable waits untimed; the host ends
// the wait when virtual time reaches the deadline (directly, or through the process's agent
// thread for eventfds and condition variables). Virtual timerfds are eventfds the agent writes
// the expirations to, so read/poll/epoll on them work through the kernel.
//
// One file on purpose: an interposition library is one translation unit of exported libc
// symbols over one shared page; every wrapper depends on the slot helpers. No global objects
// with constructors (the library is loaded into python, sh, ...).

#include <dlfcn.h>
#include <fcntl.h>
#include <linux/can.h>
#include <linux/futex.h>
#include <poll.h>
#include <pthread.h>
#include <semaphore.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/mman.h>
#include <sys/select.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <sys/time.h>
#include <sys/timerfd.h>
#include <sys/timex.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdint>
#include <cstring>

#include "bus/internal/interpose_real.h"
#include "bus/internal/peer_symbol.h"
#include "bus/vtime_protocol.h"

#define VTIME_EXPORT extern "C" __attribute__((visibility("default")))

namespace {

namespace vt = wheelhil::bus::vtime;
namespace internal = wheelhil::bus::internal;

// ---- the real functions (bus/internal/interpose_real.h) ----

REAL_FN(clock_gettime, int, (clockid_t, timespec*))
REAL_FN(gettimeofday, int, (timeval*, void*))
REAL_FN(clock_nanosleep, int, (clockid_t, int, const timespec*, timespec*))
REAL_FN(nanosleep, int, (const timespec*, timespec*))
REAL_FN(poll, int, (pollfd*, nfds_t, int))
REAL_FN(ppoll, int, (pollfd*, nfds_t, const timespec*, const sigset_t*))
REAL_FN(select, int, (int, fd_set*, fd_set*, fd_set*, timeval*))
REAL_FN(pselect, int, (int, fd_set*, fd_set*, fd_set*, const timespec*, const sigset_t*))
REAL_FN(epoll_wait, int, (int, epoll_event*, int, int))
REAL_FN(epoll_pwait, int, (int, epoll_event*, int, int, const sigset_t*))
REAL_FN(epoll_create, int, (int))
REAL_FN(epoll_create1, int, (int))
REAL_FN(epoll_ctl, int, (int, int, int, epoll_event*))
REAL_FN(timerfd_create, int, (int, int))
REAL_FN(timerfd_settime, int, (int, int, const itimerspec*, itimerspec*))
REAL_FN(timerfd_gettime, int, (int, itimerspec*))
REAL_FN(close, int, (int))
REAL_FN(close_range, int, (unsigned, unsigned, int))
REAL_FN(dup2, int, (int, int))
REAL_FN(dup3, int, (int, int, int))
REAL_FN(fork, pid_t, ())
REAL_FN(execve, int, (const char*, char* const[], char* const[]))
REAL_FN(execv, int, (const char*, char* const[]))
REAL_FN(execvp, int, (const char*, char* const[]))
REAL_FN(execvpe, int, (const char*, char* const[], char* const[]))
REAL_FN(fexecve, int, (int, char* const[], char* const[]))
REAL_FN(pthread_create, int, (pthread_t*, const pthread_attr_t*, void* (*)(void*), void*))
REAL_FN_V(pthread_cond_wait, int, (pthread_cond_t*, pthread_mutex_t*), "GLIBC_2.3.2")
REAL_FN_V(pthread_cond_timedwait, int, (pthread_cond_t*, pthread_mutex_t*, const timespec*),
          "GLIBC_2.3.2")
REAL_FN(pthread_cond_clockwait, int,
        (pthread_cond_t*, pthread_mutex_t*, clockid_t, const timespec*))
REAL_FN(syscall, long, (long, ...))
REAL_FN(alarm, unsigned, (unsigned))
REAL_FN(clock_settime, int, (clockid_t, const timespec*))
REAL_FN(settimeofday, int, (const timeval*, const struct timezone*))
REAL_FN(adjtimex, int, (timex*))
REAL_FN(ntp_adjtime, int, (timex*))
REAL_FN(clock_adjtime, int, (clockid_t, timex*))
REAL_FN(adjtime, int, (const timeval*, timeval*))
REAL_FN_V(stime, int, (const time_t*), "GLIBC_2.2.5")
REAL_FN(closefrom, void, (int))
REAL_FN(setitimer, int, (int, const itimerval*, itimerval*))
REAL_FN(getitimer, int, (int, itimerval*))
REAL_FN(timer_create, int, (clockid_t, sigevent*, timer_t*))
REAL_FN(timer_settime, int, (timer_t, int, const itimerspec*, itimerspec*))
REAL_FN(timer_gettime, int, (timer_t, itimerspec*))
REAL_FN(timer_getoverrun, int, (timer_t))
REAL_FN(timer_delete, int, (timer_t))
REAL_FN(sem_wait, int, (sem_t*))
REAL_FN(sem_timedwait, int, (sem_t*, const timespec*))
REAL_FN(sem_clockwait, int, (sem_t*, clockid_t, const timespec*))
REAL_FN(pthread_mutex_timedlock, int, (pthread_mutex_t*, const timespec*))
REAL_FN(pthread_mutex_clocklock, int, (pthread_mutex_t*, clockid_t, const timespec*))
REAL_FN(kill, int, (pid_t, int))
REAL_FN(pthread_kill, int, (pthread_t, int))
REAL_FN(socket, int, (int, int, int))
REAL_FN(write, ssize_t, (int, const void*, size_t))
REAL_FN(send, ssize_t, (int, const void*, size_t, int))
REAL_FN(sendto, ssize_t, (int, const void*, size_t, int, const sockaddr*, socklen_t))
REAL_FN(sendmsg, ssize_t, (int, const msghdr*, int))
REAL_FN(sendmmsg, int, (int, mmsghdr*, unsigned int, int))
REAL_FN(recvmsg, ssize_t, (int, msghdr*, int))
REAL_FN(recvmmsg, int, (int, mmsghdr*, unsigned int, int, timespec*))
REAL_FN(sigqueue, int, (pid_t, int, const union sigval))

// ---- the page and this process's slots ----

vt::Page* g_page = nullptr;
int g_proc = -1;                 // this process's slot
pthread_key_t g_thread_key;      // frees a thread's slot when it exits
bool g_agent_started = false;    // this process has its agent (under g_agent_lock)
pthread_mutex_t g_agent_lock = PTHREAD_MUTEX_INITIALIZER;
thread_local int t_slot = -1;
// Each thread's wake eventfd, by thread slot, as fd + 1 (0: none): the library's own
// descriptors, which the program's close/close_range/closefrom/dup2 must not take.
std::atomic<int> g_wake_fd_plus1[vt::kMaxThreads];
// The wake eventfd number a thread polls (fd + 1), set from before its ppoll until after it:
// a dup2 onto that number signals the thread until it is out of that ppoll (MoveLibraryFd).
std::atomic<int> g_polling_wake_plus1[vt::kMaxThreads];
// Waits interrupted by a signal handler's own wait (a sleep in a SIGALRM handler during a
// condition wait): saved while the handler's wait has the slot, handed back after it, as the
// kernel's waits nest. Deeper nesting than kMaxNestedWaits is not saved.
constexpr int kMaxNestedWaits = 8;
struct SavedWait {
  std::uint32_t kind;
  std::int64_t deadline_ns;
  std::int32_t wake_fd;
  std::uint64_t cond, mutex;
};
thread_local int t_wait_depth = 0;  // waits this thread is in, interrupted ones included
thread_local SavedWait t_saved_waits[kMaxNestedWaits];
// The spin cost (Page::spin_cost_ns): this thread paid it since its last wait of its own, so
// each further call that does not block costs it at once; set while it sleeps that cost.
thread_local bool t_spinning = false;
thread_local bool t_in_spin_sleep = false;
// The clock of each virtual timerfd (index: timer slot), for absolute settings.
clockid_t g_timer_clock[vt::kMaxTimers];

pid_t Tid() { return static_cast<pid_t>(real_syscall()(SYS_gettid)); }

long Futex(std::atomic<std::uint32_t>* word, int op, std::uint32_t val) {
  return real_syscall()(SYS_futex, reinterpret_cast<std::uint32_t*>(word), op, val, nullptr,
                        nullptr, 0);
}

std::int64_t Now() { return g_page->now_ns.load(std::memory_order_acquire); }

bool IsVirtualClock(clockid_t c) {
  return c == CLOCK_MONOTONIC || c == CLOCK_MONOTONIC_RAW || c == CLOCK_MONOTONIC_COARSE ||
         c == CLOCK_BOOTTIME || c == CLOCK_REALTIME || c == CLOCK_REALTIME_COARSE ||
         c == CLOCK_TAI || c == CLOCK_BOOTTIME_ALARM || c == CLOCK_REALTIME_ALARM;
}
bool IsRealtimeClock(clockid_t c) {
  return c == CLOCK_REALTIME || c == CLOCK_REALTIME_COARSE || c == CLOCK_TAI ||
         c == CLOCK_REALTIME_ALARM;
}

std::int64_t RealtimeOffset() { return g_page->realtime_offset_ns.load(std::memory_order_relaxed); }
std::int64_t NowOn(clockid_t c) { return Now() + (IsRealtimeClock(c) ? RealtimeOffset() : 0); }

/// A socket of the kernel's CAN stack (the firmware on a kernel interface such as vcan0). Asked
/// of the kernel itself: the bus library's sockets, whose stamps are already the virtual
/// clock's, are unix sockets underneath.
bool KernelCanSocket(int fd) {
  int domain = 0;
  socklen_t len = sizeof(domain);
  return ::syscall(SYS_getsockopt, fd, SOL_SOCKET, SO_DOMAIN, &domain, &len) == 0 &&
         domain == AF_CAN;
}

/// The firmware's kernel CAN sockets (a kernel interface such as vcan0), by descriptor, marked
/// when it opens one and cleared when it closes it: the frames written to them are counted
/// (Page::kernel_can_sends), so the host knows when it has received all of them.
constexpr int kMaxCanFds = 4096;
std::atomic<std::uint64_t> g_kernel_can_fds[kMaxCanFds / 64];

bool MarkedKernelCan(int fd) {
  return fd >= 0 && fd < kMaxCanFds &&
         (g_kernel_can_fds[fd / 64].load(std::memory_order_relaxed) >> (fd % 64) & 1u) != 0;
}
void MarkKernelCan(int fd, bool can) {
  if (fd < 0 || fd >= kMaxCanFds) return;
  const std::uint64_t bit = std::uint64_t{1} << (fd % 64);
  if (can) {
    g_kernel_can_fds[fd / 64].fetch_or(bit);
  } else if (g_kernel_can_fds[fd / 64].load(std::memory_order_relaxed) & bit) {
    g_kernel_can_fds[fd / 64].fetch_and(~bit);
  }
}
/// An absolute time on clock c as a virtual monotonic deadline (saturated: a time beyond the
/// range of ns is no deadline).
std::int64_t DeadlineFromAbs(clockid_t c, const timespec& ts) {
  const std::int64_t abs = vt::ToNs(ts.tv_sec, ts.tv_nsec);
  return IsRealtimeClock(c) ? vt::AddNs(abs, -RealtimeOffset()) : abs;
}
std::int64_t DeadlineIn(std::int64_t ns) { return vt::AddNs(Now(), ns); }
bool ValidTimespec(const timespec& ts) {
  return ts.tv_sec >= 0 && ts.tv_nsec >= 0 && ts.tv_nsec < 1000000000;
}
timespec ToTimespec(std::int64_t ns) {
  if (ns < 0) ns = 0;
  return timespec{static_cast<time_t>(ns / 1000000000), static_cast<long>(ns % 1000000000)};
}

/// A thread entered or left a wait (or started, or ended). The host is woken only by a change
/// that may leave the whole firmware blocked (a wait entered, a thread gone): one that sets a
/// thread running cannot, and waking the host then costs it a look while the firmware runs
/// (two context switches on one CPU). Every change counts, so a look that raced one is retried.
void Transition(bool may_block = false) {
  g_page->transitions.fetch_add(1);
  // Only the first such change after the host went to sleep wakes it (one system call).
  if (may_block && g_page->host_waiting.load() != 0 && g_page->host_waiting.exchange(0) != 0) {
    Futex(&g_page->transitions, FUTEX_WAKE, 1);
  }
}

/// Slot `i` is in use: the host's scans (one past the highest slot ever claimed) include it.
void RaiseUsed(std::atomic<std::int32_t>& used, int i) {
  std::int32_t u = used.load();
  while (u < i + 1 && !used.compare_exchange_weak(u, i + 1)) {
  }
}

/// Claims a free thread slot for `tid` (0: a thread not started yet) in this process.
int ClaimThreadSlot(pid_t tid) {
  for (int i = 0; i < vt::kMaxThreads; ++i) {
    vt::ThreadSlot& s = g_page->threads[i];
    std::uint32_t expect = vt::kFree;
    if (s.state.load() != vt::kFree || !s.state.compare_exchange_strong(expect, vt::kRunning)) {
      continue;
    }
    s.kind.store(vt::kNone);
    s.fired.store(0);
    s.deadline_ns.store(vt::kNoDeadline);
    s.calls.store(0);
    s.last_call.store(vt::kCallNone);
    s.wake_fd = -1;
    s.pid.store(getpid());
    s.tid.store(tid);
    RaiseUsed(g_page->threads_used, i);
    return i;
  }
  ::fprintf(stderr, "wheelhil vtime: more than %d threads in the firmware's processes\n",
            vt::kMaxThreads);
  ::abort();
}

thread_local bool t_holds_clock = false;  // HoldClock
bool HoldClock();
void AdvanceHeldClock();

void FreeThreadSlot(int i) {
  // A thread that ends may leave every other one waiting: it moves the clock on, as the last
  // to wait would (holding it from before it is gone, as BeginWait does).
  const bool held = HoldClock();
  vt::ThreadSlot& s = g_page->threads[i];
  s.tid.store(0);
  s.pid.store(0);
  vt::MarkLocallyWoken(*g_page, i, false);
  s.state.store(vt::kFree);
  Transition(true);
  if (held) AdvanceHeldClock();
}

/// The calling thread's slot (claimed at its first call for a thread the library did not see
/// start: the main thread, threads created before the library was loaded).
vt::ThreadSlot& Self() {
  if (t_slot < 0) t_slot = ClaimThreadSlot(Tid());
  return g_page->threads[t_slot];
}

int SleepUntil(std::int64_t deadline);

void NoteCall(vt::LastCall what) {
  vt::ThreadSlot& s = Self();
  const std::uint32_t calls = s.calls.fetch_add(1, std::memory_order_relaxed) + 1;
  s.last_call.store(what, std::memory_order_relaxed);
  // The spin cost: a thread that keeps calling without blocking pays in virtual time, from its
  // kSpinCallsFree-th such call, then for every one until it waits of its own accord.
  const std::int64_t cost = g_page->spin_cost_ns.load(std::memory_order_relaxed);
  if (cost > 0 && (t_spinning || calls >= vt::kSpinCallsFree) && !t_in_spin_sleep) {
    t_in_spin_sleep = true;
    SleepUntil(Now() + cost);
    t_in_spin_sleep = false;
    t_spinning = true;
  }
}

/// True (and counted as a call that did not block) when virtual time is at `deadline` already.
bool DeadlinePassed(std::int64_t deadline) {
  if (Now() < deadline) return false;
  NoteCall(vt::kCallPastDeadline);
  return true;
}

/// What a wait needs besides its kind and deadline (process-local; see ThreadSlot).
struct WaitTarget {
  std::int32_t wake_fd = -1;  ///< kFdWait
  std::uint64_t cond = 0;     ///< kCondWait, kFutexWait
  std::uint64_t mutex = 0;
};

/// Publishes this thread's wait. A wait begun while the thread is in another (a signal
/// handler's, or the spin cost's sleep) saves the one it interrupts; EndWait hands it back.
/// `vouched`, `entry_wakes`: see ThreadSlot.
void BeginWait(vt::ThreadSlot& s, vt::WaitKind kind, std::int64_t deadline, WaitTarget target = {},
               bool vouched = false, std::uint32_t entry_wakes = 0, std::uint32_t channels = 0) {
  const int depth = t_wait_depth;
  // Runahead: the clock is held from before the wait is published until this thread has moved
  // it on (or found it cannot), so the host never sees every thread waiting with the clock
  // granted and nobody about to move it. A wait in a signal handler leaves the clock to the
  // one it interrupts.
  const bool held = depth == 0 && HoldClock();
  // Counted before the slot is written: a handler that runs from here on saves and restores
  // what it finds, and this wait then finishes writing its own.
  t_wait_depth = depth + 1;
  if (depth > 0 && depth <= kMaxNestedWaits) {
    t_saved_waits[depth - 1] = SavedWait{s.kind.load(), s.deadline_ns.load(), s.wake_fd, s.cond,
                                         s.mutex};
  }
  if (!t_in_spin_sleep) t_spinning = false;
  s.wake_fd = target.wake_fd;
  s.cond = target.cond;
  s.mutex = target.mutex;
  s.kind.store(kind);
  s.fired.store(0);
  s.resumed.store(0);
  s.entry_wakes.store(entry_wakes);
  s.wait_channels.store(channels);
  s.vouched.store(vouched ? 1 : 0);
  s.deadline_ns.store(deadline);
  s.calls.store(0, std::memory_order_relaxed);
  s.state.store(vt::kWaiting);
  Transition(true);
  if (held) AdvanceHeldClock();
}

void EndWait(vt::ThreadSlot& s) {
  const int depth = --t_wait_depth;
  if (depth > 0 && depth <= kMaxNestedWaits) {
    // Back into the wait this one interrupted: the slot is that wait's again (a deadline it
    // passed meanwhile is ended by the host once more). `resumed`: the thread may be on its
    // way out of it, so the host asks the kernel before it takes the thread for blocked.
    const SavedWait& w = t_saved_waits[depth - 1];
    s.wake_fd = w.wake_fd;
    s.cond = w.cond;
    s.mutex = w.mutex;
    s.kind.store(w.kind);
    s.fired.store(0);
    s.resumed.store(1);
    s.vouched.store(0);
    s.deadline_ns.store(w.deadline_ns);
    s.state.store(vt::kWaiting);
    Transition(true);
    return;
  }
  s.state.store(vt::kRunning);
  s.deadline_ns.store(vt::kNoDeadline);
  s.resumed.store(0);
  s.vouched.store(0);
  if (t_slot >= 0) vt::MarkLocallyWoken(*g_page, t_slot, false);
  Transition();
}

// ---- runahead: the firmware moves its clock itself (Page::runahead) ----

/// Gives the clock back to the host (this thread holds kLocalAdvance) and wakes it.
void YieldClock() {
  g_page->runahead.store(vt::NextRunaheadWord(g_page->runahead.load(), vt::kHostClock));
  Futex(&g_page->runahead, FUTEX_WAKE, 1);  // the host may sleep on it (WaitWhileGranted)
  Transition(true);
}

/// What is due at `t` can be ended here without the host: a sleep (its futex word), an fd
/// wait of this process with its wake eventfd, a timer of this process that writes its timerfd
/// or tells nobody. Signals, condition variables, futex words and thread timers go through the
/// agent or the kernel's signal rules: the host does those.
bool LocallyEndable(std::int64_t t, pid_t me) {
  const int timers = g_page->timers_used.load();
  for (int i = 0; i < timers; ++i) {
    const vt::TimerSlot& tm = g_page->timers[i];
    if (tm.state.load() != vt::kTimerArmed || tm.next_ns.load() > t) continue;
    const std::uint32_t how = tm.notify.load();
    if (tm.pid.load() != me || (how != vt::kNotifyEventFd && how != vt::kNotifyNone)) return false;
  }
  const int threads = g_page->threads_used.load();
  for (int i = 0; i < threads; ++i) {
    const vt::ThreadSlot& s = g_page->threads[i];
    if (s.state.load() != vt::kWaiting || s.deadline_ns.load() > t) continue;
    const std::uint32_t kind = s.kind.load();
    if (kind == vt::kSleep) continue;
    if (kind != vt::kFdWait || s.wake_fd < 0 || s.pid.load() != me) return false;
  }
  return true;
}

/// Runahead: takes the clock (kLocalAdvance) while it is granted, waiting out another thread
/// that moves it; false when the clock is the host's or this thread holds it already.
bool HoldClock() {
  if (t_holds_clock) return false;
  for (;;) {
    std::uint32_t word = g_page->runahead.load();
    const std::uint32_t state = vt::RunaheadStateOf(word);
    if (state == vt::kHostClock) return false;
    if (state == vt::kGranted && g_page->runahead.compare_exchange_strong(
                                     word, vt::NextRunaheadWord(word, vt::kLocalAdvance))) {
      t_holds_clock = true;
      return true;
    }
    ::sched_yield();  // on the firmware's one CPU, the holder runs
  }
}

/// Lets the clock go without moving it (a wait that found its fds ready).
void ReleaseClock() {
  t_holds_clock = false;
  g_page->runahead.store(vt::NextRunaheadWord(g_page->runahead.load(), vt::kGranted));
}

/// With kLocalAdvance held: when every thread of the firmware is in a wait only the clock can
/// end, moves the clock to the next instant something is due (if the grant allows) and ends
/// what is due then, as the host's VirtualClock::WakeDue would, or gives the clock back (false).
bool AdvanceOnce();

/// With the clock held and this thread's wait published (or its slot freed): moves the clock
/// on and lets it go, or gives it back to the host.
void AdvanceHeldClock() {
  if (AdvanceOnce()) {
    ReleaseClock();
  } else {
    t_holds_clock = false;
  }
}

/// libwheelhil_ucan.so's frames put ahead (runahead): the next one's instant, and publishing
/// those due (bus/ucan_interpose.cc). nullptr without that library.
internal::PeerSymbol<std::int64_t (*)()> g_ucan_next_prepared("wheelhil_ucan_next_prepared_ns");
internal::PeerSymbol<std::uint32_t (*)(std::int64_t, std::int64_t)> g_ucan_publish_prepared(
    "wheelhil_ucan_publish_prepared");

bool AdvanceOnce() {
  const pid_t me = g_page->processes[g_proc].pid.load();
  // One process only: another's fds and threads are not this one's to end.
  for (int p = 0; p < vt::kMaxProcesses; ++p) {
    const std::uint32_t st = g_page->processes[p].state.load();
    if (st != vt::kProcFree && (p != g_proc || st != vt::kProcAlive)) {
      YieldClock();
      return false;
    }
  }
  std::int64_t next = vt::kNoDeadline;
  const int threads = g_page->threads_used.load();
  for (int i = 0; i < threads; ++i) {
    const vt::ThreadSlot& s = g_page->threads[i];
    const std::uint32_t st = s.state.load();
    if (st == vt::kFree) continue;
    // Still running (it calls this when it waits), or asleep where the library does not see
    // it (the host finds that and takes the clock back).
    if (st != vt::kWaiting) return true;
    if (s.kind.load() == vt::kFdWait) {
      // On anything but bus sockets and virtual timers, it may end at any time.
      if (s.vouched.load() == 0) {
        YieldClock();
        return false;
      }
      // Written to since it began (a timer just fired): it is on its way out.
      if (!vt::VouchHolds(*g_page, s)) return true;
    }
    next = std::min(next, s.deadline_ns.load());
  }
  const int timers = g_page->timers_used.load();
  for (int i = 0; i < timers; ++i) {
    const vt::TimerSlot& t = g_page->timers[i];
    if (t.state.load() == vt::kTimerArmed) next = std::min(next, t.next_ns.load());
  }
  const auto next_frame = g_ucan_next_prepared.get();
  const auto publish = g_ucan_publish_prepared.get();
  if (next_frame != nullptr && publish != nullptr) next = std::min(next, next_frame());
  const std::int64_t now = Now();
  const std::int64_t step = g_page->runahead_step_ns.load();
  const bool on_grid = step <= 0 || (next - g_page->runahead_phase_ns.load()) % step == 0;
  // A foreseen send not made by then: what the host forecast after it does not hold.
  const vt::SendRules& rules = g_page->sends;
  const std::uint32_t taken = rules.foreseen_taken.load();
  const bool foreseen_missed = rules.enabled.load() != 0 && taken < rules.foreseen_count &&
                               rules.foreseen[taken].instant_ns < next;
  if (next == vt::kNoDeadline || next <= now || next > g_page->runahead_until_ns.load() ||
      !on_grid || g_page->bus_sends.load() != g_page->runahead_sends.load() || foreseen_missed ||
      !LocallyEndable(next, me)) {
    YieldClock();
    return false;
  }
  g_page->now_ns.store(next, std::memory_order_release);
  g_page->local_advances.fetch_add(1, std::memory_order_relaxed);
  // As the host's WakeDue: timers first (a thread woken at this instant finds them fired).
  std::uint32_t channels = 0;
  for (int i = 0; i < timers; ++i) {
    vt::TimerSlot& t = g_page->timers[i];
    if (t.state.load() != vt::kTimerArmed || t.next_ns.load() > next) continue;
    const std::uint64_t expirations = vt::ExpireTimer(t, next);
    if (t.notify.load() == vt::kNotifyEventFd) {
      eventfd_write(t.fd, expirations);
      channels |= vt::TimerChannel(i);
    }
  }
  // The frames of this instant, as the broker's pass after the host's WakeDue delivers them.
  if (publish != nullptr) channels |= publish(next, next + RealtimeOffset());
  if (channels != 0) vt::NoteWake(*g_page, channels);
  for (int i = 0; i < threads; ++i) {
    vt::ThreadSlot& s = g_page->threads[i];
    if (s.state.load() != vt::kWaiting || s.deadline_ns.load() > next) continue;
    std::uint32_t waiting = vt::kWaiting;
    vt::MarkLocallyWoken(*g_page, i, true);
    if (!s.state.compare_exchange_strong(waiting, vt::kRunning)) {
      vt::MarkLocallyWoken(*g_page, i, false);
      continue;
    }
    if (s.kind.load() == vt::kFdWait) {
      eventfd_write(s.wake_fd, 1);
    } else {
      s.wake.fetch_add(1);
      Futex(&s.wake, FUTEX_WAKE, 1);
    }
  }
  return true;
}

// ---- the agent: ends eventfd and condition-variable waits, fires timers ----

/// Empties an eventfd without blocking, whether it was opened O_NONBLOCK or not (a virtual
/// timerfd has the program's flags).
void DrainEventFd(int fd) {
  static const timespec kZero{0, 0};
  pollfd p{fd, POLLIN, 0};
  eventfd_t v = 0;
  while (real_ppoll()(&p, 1, &kZero, nullptr) == 1 && (p.revents & POLLIN) && eventfd_read(fd, &v) == 0) {
  }
}

struct TimerThreadCall {
  std::uint64_t function;
  std::uint64_t sigval;
};

void* TimerThreadMain(void* raw) {
  const TimerThreadCall call = *static_cast<TimerThreadCall*>(raw);
  ::free(raw);
  sigval v{};
  v.sival_ptr = reinterpret_cast<void*>(call.sigval);
  reinterpret_cast<void (*)(sigval)>(call.function)(v);
  return nullptr;
}

/// After a write that may end an fd wait the host cannot see (ThreadSlot::vouched).
void NoteFdWake() { vt::NoteWake(*g_page, vt::kAnyChannel); }

void FireTimers() {
  const int used = g_page->timers_used.load();
  bool wrote = false;
  for (int i = 0; i < used; ++i) {
    vt::TimerSlot& t = g_page->timers[i];
    if (t.pid.load() != getpid() || t.fired.load() == 0) continue;
    const std::uint64_t expirations = vt::ExpireTimer(t, Now());
    t.fired.store(0);
    if (t.notify.load() == vt::kNotifyEventFd) {
      eventfd_write(t.fd, expirations);
      wrote = true;
    } else if (t.notify.load() == vt::kNotifyThread) {
      // SIGEV_THREAD: like glibc, a new thread per expiration (through our pthread_create, so
      // the host sees it).
      auto* call = static_cast<TimerThreadCall*>(::malloc(sizeof(TimerThreadCall)));
      if (call == nullptr) continue;
      *call = TimerThreadCall{t.function, t.sigval};
      pthread_t th;
      pthread_attr_t attr;
      pthread_attr_init(&attr);
      pthread_attr_setdetachstate(&attr, PTHREAD_CREATE_DETACHED);
      if (pthread_create(&th, &attr, TimerThreadMain, call) != 0) ::free(call);
      pthread_attr_destroy(&attr);
    }
  }
  if (wrote) NoteFdWake();
}

void FireWaits() {
  const int used = g_page->threads_used.load();
  for (int i = 0; i < used; ++i) {
    vt::ThreadSlot& s = g_page->threads[i];
    if (s.pid.load() != getpid() || s.fired.load() == 0) continue;
    if (s.fired.exchange(0) == 0) continue;
    if (s.kind.load() == vt::kFdWait && s.wake_fd >= 0) {
      eventfd_write(s.wake_fd, 1);
      NoteFdWake();
    } else if (s.kind.load() == vt::kFutexWait) {
      real_syscall()(SYS_futex, reinterpret_cast<std::uint32_t*>(s.cond),
                     static_cast<int>(FUTEX_WAKE_BITSET | s.mutex), INT32_MAX, nullptr, nullptr,
                     FUTEX_BITSET_MATCH_ANY);
    } else if (s.kind.load() == vt::kCondWait) {
      // Under the waiter's mutex: the waiter is inside pthread_cond_wait (it registered with the
      // mutex held and the wait released it), so the broadcast cannot be missed.
      auto* m = reinterpret_cast<pthread_mutex_t*>(s.mutex);
      auto* c = reinterpret_cast<pthread_cond_t*>(s.cond);
      if (m != nullptr && c != nullptr) {
        pthread_mutex_lock(m);
        pthread_cond_broadcast(c);
        pthread_mutex_unlock(m);
      }
    }
  }
}

void* AgentMain(void* arg) {
  sigset_t all;
  sigfillset(&all);
  pthread_sigmask(SIG_BLOCK, &all, nullptr);
  t_slot = static_cast<int>(reinterpret_cast<std::intptr_t>(arg));
  vt::ThreadSlot& s = g_page->threads[t_slot];
  s.tid.store(Tid());
  for (;;) {
    const std::uint32_t w = s.wake.load();
    FireWaits();
    FireTimers();
    BeginWait(s, vt::kAgent, vt::kNoDeadline);
    while (s.wake.load() == w) Futex(&s.wake, FUTEX_WAIT, w);
    EndWait(s);
  }
  return nullptr;
}

void EnsureAgent() {
  if (__atomic_load_n(&g_agent_started, __ATOMIC_ACQUIRE)) return;
  pthread_mutex_lock(&g_agent_lock);
  if (!g_agent_started) {
    // The slot is claimed (running, tid 0) before the thread exists: the host does not take
    // the process for blocked while its agent is starting.
    const int slot = ClaimThreadSlot(0);
    g_page->processes[g_proc].agent.store(slot);
    pthread_t t;
    pthread_attr_t attr;
    pthread_attr_init(&attr);
    pthread_attr_setdetachstate(&attr, PTHREAD_CREATE_DETACHED);
    pthread_attr_setstacksize(&attr, 64 * 1024);
    if (real_pthread_create()(&t, &attr, AgentMain,
                              reinterpret_cast<void*>(static_cast<std::intptr_t>(slot))) != 0) {
      ::fprintf(stderr, "wheelhil vtime: cannot start the agent thread\n");
      ::abort();
    }
    pthread_attr_destroy(&attr);
    __atomic_store_n(&g_agent_started, true, __ATOMIC_RELEASE);
  }
  pthread_mutex_unlock(&g_agent_lock);
}

/// The wake signal's handler: nothing; it only makes the wait it interrupts return EINTR.
void OnWakeSignal(int) {}

void EnsureWakeSignal() {
  static bool installed = false;  // under g_agent_lock
  pthread_mutex_lock(&g_agent_lock);
  if (!installed) {
    struct sigaction old {};
    sigaction(vt::kWakeSignal, nullptr, &old);
    // A program with its own handler for it keeps it (that handler then sees the wake-ups).
    if (old.sa_handler == SIG_DFL) {
      struct sigaction sa {};
      sa.sa_handler = OnWakeSignal;
      sigemptyset(&sa.sa_mask);
      sa.sa_flags = 0;  // no SA_RESTART: the wait returns EINTR
      sigaction(vt::kWakeSignal, &sa, nullptr);
    }
    installed = true;
  }
  pthread_mutex_unlock(&g_agent_lock);
}

bool IsLibraryFd(int fd) {
  if (fd < 0 || g_page == nullptr) return false;
  const int used = g_page->threads_used.load();
  for (int i = 0; i < used; ++i) {
    if (g_wake_fd_plus1[i].load(std::memory_order_relaxed) == fd + 1) return true;
  }
  return false;
}

// A vfork child (a shell's or posix_spawn's way to run a command) shares its parent's memory,
// the library's records included, but not its descriptor table: it must leave them alone.
bool InVforkChild() {
  return g_proc >= 0 && g_page->processes[g_proc].pid.load() != getpid();
}

/// This thread's wake eventfd (made at its first timed fd wait), -1 when none can be made (the
/// fd table is full): its timed fd waits are then ended by the wake signal (PollUntil).
int WakeFd() {
  const int fd = g_wake_fd_plus1[t_slot].load() - 1;
  if (fd >= 0) return fd;
  const int made = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (made < 0) {
    static bool told = false;  // once per process is enough for firmware.log
    if (!__atomic_exchange_n(&told, true, __ATOMIC_RELAXED)) {
      ::fprintf(stderr,
                "wheelhil vtime: no file descriptor for a thread's wake-up (eventfd: %s): its "
                "timed waits on file descriptors are ended by signal %d instead\n",
                strerror(errno), vt::kWakeSignal);
    }
    return -1;
  }
  g_wake_fd_plus1[t_slot].store(made + 1);
  return made;
}

/// Closes the wake eventfd of thread slot i (its thread has gone).
void CloseWakeFd(int i) {
  const int fd = g_wake_fd_plus1[i].exchange(0) - 1;
  if (fd >= 0) real_close()(fd);
}

// ---- waits ----

/// Sleeps until virtual `deadline`; 0 or EINTR.
int SleepUntil(std::int64_t deadline) {
  vt::ThreadSlot& s = Self();
  if (DeadlinePassed(deadline)) return 0;
  BeginWait(s, vt::kSleep, deadline);
  int rc = 0;
  for (;;) {
    const std::uint32_t w = s.wake.load();
    if (s.state.load() != vt::kWaiting || Now() >= deadline) break;
    if (Futex(&s.wake, FUTEX_WAIT, w) < 0 && errno == EINTR) {
      rc = EINTR;
      break;
    }
  }
  EndWait(s);
  return rc;
}

/// poll() until a descriptor is ready or virtual `deadline` passed, for a thread without a
/// wake eventfd: the host ends the wait with the wake signal, which is blocked outside it and
/// let through only by ppoll's own mask (no wake-up is lost between the two).
int PollUntilSignalled(pollfd* fds, nfds_t n, std::int64_t deadline, const sigset_t* mask) {
  vt::ThreadSlot& s = Self();
  EnsureWakeSignal();
  sigset_t wake, old, during;
  sigemptyset(&wake);
  sigaddset(&wake, vt::kWakeSignal);
  pthread_sigmask(SIG_BLOCK, &wake, &old);
  during = mask != nullptr ? *mask : old;
  sigdelset(&during, vt::kWakeSignal);
  BeginWait(s, vt::kSignalWait, deadline);
  int rc = real_ppoll()(fds, n, nullptr, &during);
  int err = errno;
  EndWait(s);
  // EINTR before the deadline is a signal of the program's own: poll reports it, as the
  // kernel's does.
  if (rc < 0 && err == EINTR && Now() >= deadline) {
    rc = 0;
    err = 0;
    for (nfds_t i = 0; i < n; ++i) fds[i].revents = 0;
  }
  pthread_sigmask(SIG_SETMASK, &old, nullptr);
  errno = err;
  return rc;
}

/// libwheelhil_ucan.so's `wheelhil_ucan_bus_socket_state` (nullptr: that library is not
/// loaded): 0 not a bus socket of the broker, 1 one with nothing to read, 2 one that may have;
/// its client id on the broker.
using BusSocketFn = int (*)(int, std::uint32_t*);
internal::PeerSymbol<BusSocketFn> g_ucan_bus_socket_state("wheelhil_ucan_bus_socket_state");
BusSocketFn UcanBusSocketState() { return g_ucan_bus_socket_state.get(); }

/// The timer slot of fd when it is a virtual timerfd of this process, else -1 (no system call:
/// the pid is the process slot's).
int VirtualTimerFdSlot(int fd) {
  const pid_t me = g_page->processes[g_proc].pid.load(std::memory_order_relaxed);
  const int used = g_page->timers_used.load();
  for (int i = 0; i < used; ++i) {
    const vt::TimerSlot& t = g_page->timers[i];
    if (t.fd == fd && t.state.load() != vt::kTimerFree && t.pid.load() == me) return i;
  }
  return -1;
}

/// Whether only the host or an agent can make a wait ready (ThreadSlot::vouched): input from
/// bus sockets of the broker, virtual timerfds and epoll sets of those; output is the kernel's
/// to tell. kYes: none ready, known from memory; kLook: vouchable once a look in the kernel
/// found none ready (a timerfd's count, an epoll set, a bus socket without rings); kReady: one
/// may be ready already (a bus socket's ring). A wait of several fds takes the highest.
enum class Vouch { kNo, kYes, kLook, kReady };

std::uint32_t EpollVouchable(int epfd);

/// One fd waited on for `events` (`epoll_sets`: an epoll set of this process counts too); its
/// wake channels into `*channels`.
Vouch VouchForFd(int fd, std::uint32_t events, bool epoll_sets, std::uint32_t* channels) {
  if (events & (POLLOUT | POLLWRNORM | POLLWRBAND)) return Vouch::kNo;
  if (g_proc < 0) return Vouch::kNo;
  if (const BusSocketFn bus = UcanBusSocketState(); bus != nullptr) {
    std::uint32_t client = 0;
    const int state = bus(fd, &client);
    if (state == 3) return Vouch::kNo;  // signal-driven bus input: SIGIO may end any wait
    if (state != 0) {
      *channels |= vt::BusSocketChannel(client);
      return state == 2 ? Vouch::kReady : Vouch::kYes;
    }
  }
  const int timer = VirtualTimerFdSlot(fd);
  const std::uint32_t of = timer >= 0   ? vt::TimerChannel(timer)
                           : epoll_sets ? EpollVouchable(fd)
                                        : 0;
  if (of == 0) return Vouch::kNo;
  *channels |= of;
  return Vouch::kLook;
}

/// An epoll member: its wake channels, 0 when it is not vouchable (nor is an epoll set in it).
std::uint32_t VouchableInput(int fd, std::uint32_t events) {
  std::uint32_t channels = 0;
  return VouchForFd(fd, events, false, &channels) == Vouch::kNo ? 0 : channels;
}

// The epoll sets this process made through the library, by fd number: the members it added
// that are not vouchable (a few by number; more, and the set stays unvouched until closed).
// A set whose members are all vouchable is itself (its zero-timeout look in the kernel tells
// whether any member is ready). Members the kernel drops on their last close stay counted,
// which only costs a look in /proc. Written under g_epoll_lock, read without it.
constexpr int kMaxEpollFds = 1024;
constexpr int kMaxUnvouchedMembers = 6;
struct EpollSet {
  std::atomic<std::uint32_t> channels{0};  // of the vouchable members ever added
  std::atomic<std::uint8_t> tracked{0};
  std::atomic<std::uint8_t> overflow{0};
  std::atomic<std::uint8_t> unvouched{0};  // entries used in `members`
  std::int32_t members[kMaxUnvouchedMembers];
};
EpollSet g_epoll[kMaxEpollFds];
pthread_mutex_t g_epoll_lock = PTHREAD_MUTEX_INITIALIZER;

/// The wake channels of a tracked epoll set whose members are all vouchable, else 0.
std::uint32_t EpollVouchable(int epfd) {
  if (epfd < 0 || epfd >= kMaxEpollFds) return 0;
  const EpollSet& e = g_epoll[epfd];
  if (e.tracked.load() == 0 || e.overflow.load() != 0 || e.unvouched.load() != 0) return 0;
  return e.channels.load() | vt::kAnyChannel;
}

void ForgetEpoll(int fd) {
  if (fd < 0 || fd >= kMaxEpollFds || g_epoll[fd].tracked.load() == 0) return;
  pthread_mutex_lock(&g_epoll_lock);
  g_epoll[fd].tracked.store(0);
  pthread_mutex_unlock(&g_epoll_lock);
}

void ForgetEveryEpoll() {
  pthread_mutex_lock(&g_epoll_lock);
  for (EpollSet& e : g_epoll) e.tracked.store(0);
  pthread_mutex_unlock(&g_epoll_lock);
}

void TrackNewEpoll(int fd) {
  if (fd < 0 || fd >= kMaxEpollFds) return;
  pthread_mutex_lock(&g_epoll_lock);
  EpollSet& e = g_epoll[fd];
  e.overflow.store(0);
  e.unvouched.store(0);
  e.channels.store(0);
  e.tracked.store(1);
  pthread_mutex_unlock(&g_epoll_lock);
}

/// After a successful epoll_ctl on a tracked set.
void TrackEpollCtl(int epfd, int op, int fd, const epoll_event* ev) {
  if (epfd < 0 || epfd >= kMaxEpollFds) return;
  const std::uint32_t channels =
      op != EPOLL_CTL_DEL && ev != nullptr ? VouchableInput(fd, ev->events) : 0;
  const bool vouchable = channels != 0;
  pthread_mutex_lock(&g_epoll_lock);
  EpollSet& e = g_epoll[epfd];
  if (e.tracked.load() != 0) {
    e.channels.fetch_or(channels);
    int n = e.unvouched.load();
    int at = -1;
    for (int i = 0; i < n; ++i) {
      if (e.members[i] == fd) at = i;
    }
    if (at >= 0 && (op == EPOLL_CTL_DEL || vouchable)) {
      e.members[at] = e.members[n - 1];
      e.unvouched.store(static_cast<std::uint8_t>(n - 1));
    } else if (at < 0 && op != EPOLL_CTL_DEL && !vouchable) {
      if (n == kMaxUnvouchedMembers) {
        e.overflow.store(1);
      } else {
        e.members[n] = fd;
        e.unvouched.store(static_cast<std::uint8_t>(n + 1));
      }
    }
  }
  pthread_mutex_unlock(&g_epoll_lock);
}

/// The program's `fds` (see Vouch); `*channels`: their wake channels.
Vouch VouchFor(const pollfd* fds, nfds_t n, std::uint32_t* channels) {
  *channels = 0;
  if (g_proc < 0) return Vouch::kNo;
  Vouch v = Vouch::kYes;
  for (nfds_t i = 0; i < n; ++i) {
    if (fds[i].fd < 0) continue;  // poll ignores it
    const Vouch fd = VouchForFd(fds[i].fd, static_cast<std::uint16_t>(fds[i].events), true,
                                channels);
    if (fd == Vouch::kNo) return Vouch::kNo;
    v = std::max(v, fd);
  }
  return v;
}

// This thread's wake eventfd may hold a wake-up the host wrote for a wait that ended before it
// read it: the next vouched wait looks in the kernel first.
thread_local bool t_wake_may_be_left = false;

/// ppoll() on `all` (the program's `n` fds, then this thread's wake eventfd when `wake_fd` is
/// not -1) without timeout, as the thread's kFdWait. A vouched wait reads Page::fd_wakes
/// before it makes sure none of the fds is ready (in memory or by a look in the kernel): every
/// write counted before that read is seen, so the wait can be ended only by a later write,
/// which bumps the count again. -1 with errno, or the ready count.
int WaitOnFds(vt::ThreadSlot& s, pollfd* all, nfds_t n, int wake_fd, const sigset_t* mask,
              std::int64_t deadline, WaitTarget target) {
  static const timespec kZero{0, 0};
  const nfds_t n_all = n + (wake_fd >= 0 ? 1 : 0);
  // Runahead: the look and the wait's publishing hold the clock, so no other thread moves it
  // (firing timers, counting their writes) in between: a write counted after the look would
  // leave the wait unvouched though it may have been for another fd, and a thread moving the
  // clock would then take it for on its way out.
  const bool held = HoldClock();
  const std::uint32_t wakes = g_page->fd_wakes.load();
  std::uint32_t channels = 0;
  Vouch v = VouchFor(all, n, &channels);
  if (v == Vouch::kYes && t_wake_may_be_left) v = Vouch::kLook;
  if (v == Vouch::kLook || v == Vouch::kReady) {
    t_wake_may_be_left = false;
    const int rc = real_ppoll()(all, n_all, &kZero, mask);
    if (rc != 0) {
      const int err = errno;
      if (held) ReleaseClock();
      errno = err;
      return rc;
    }
  }
  BeginWait(s, vt::kFdWait, deadline, target, v != Vouch::kNo, wakes, channels);
  if (held) AdvanceHeldClock();
  int rc = -1;
  int err = EINTR;
  // Marked before the number is looked at again: a dup2 onto it either finds the mark (and
  // signals this thread out of the ppoll) or is seen here (its wait goes round again).
  if (wake_fd >= 0 && t_slot >= 0) g_polling_wake_plus1[t_slot].store(wake_fd + 1);
  if (wake_fd < 0 || t_slot < 0 || g_wake_fd_plus1[t_slot].load() == wake_fd + 1) {
    rc = real_ppoll()(all, n_all, nullptr, mask);
    err = errno;
  }
  if (wake_fd >= 0 && t_slot >= 0) g_polling_wake_plus1[t_slot].store(0);
  // Ended by the host (its deadline) before its eventfd write was seen: that write may follow.
  if (wake_fd >= 0 && s.state.load() == vt::kRunning && all[n].revents == 0) {
    t_wake_may_be_left = true;
  }
  EndWait(s);
  errno = err;
  return rc;
}

/// poll() on `fds` until one is ready or virtual `deadline` (kNoDeadline: none) passed.
int PollUntil(pollfd* fds, nfds_t n, std::int64_t deadline, const sigset_t* mask) {
  vt::ThreadSlot& s = Self();
  if (deadline == vt::kNoDeadline) return WaitOnFds(s, fds, n, -1, mask, deadline, {});
  EnsureAgent();
  int wake = WakeFd();
  if (wake < 0) return PollUntilSignalled(fds, n, deadline, mask);
  pollfd stack[33];
  pollfd* all = n + 1 <= 33 ? stack : static_cast<pollfd*>(::malloc((n + 1) * sizeof(pollfd)));
  if (all == nullptr) {
    errno = ENOMEM;
    return -1;
  }
  bool moved = false;
  for (;;) {
    std::memcpy(all, fds, n * sizeof(pollfd));
    all[n] = pollfd{wake, POLLIN, 0};
    WaitTarget target;
    target.wake_fd = wake;
    const int rc = WaitOnFds(s, all, n, wake, mask, deadline, target);
    const int err = errno;
    // Moved away by a dup2 (MoveLibraryFd), which signals this thread until it has seen the
    // move: an EINTR after that, in this call, is one of those signals, not the program's.
    if (rc < 0 && err == EINTR && (moved || g_wake_fd_plus1[t_slot].load() != wake + 1)) {
      moved = true;
      wake = g_wake_fd_plus1[t_slot].load() - 1;
      if (wake < 0) wake = WakeFd();
      if (wake >= 0) continue;
    }
    if (rc < 0) {
      if (all != stack) ::free(all);
      errno = err;
      return rc;
    }
    if (all[n].revents & POLLNVAL) {
      // The wake eventfd was closed behind the library's back (a raw close system call): a new
      // one, and the wait again.
      g_wake_fd_plus1[t_slot].store(0);
      wake = WakeFd();
      if (wake < 0) {
        if (all != stack) ::free(all);
        return PollUntilSignalled(fds, n, deadline, mask);
      }
      continue;
    }
    if (all[n].revents != 0) {
      eventfd_t v = 0;
      eventfd_read(wake, &v);  // EFD_NONBLOCK
    }
    int ready = 0;
    for (nfds_t i = 0; i < n; ++i) {
      fds[i].revents = all[i].revents;
      if (all[i].revents != 0) ++ready;
    }
    // A wake-up left from an earlier wait (its deadline fired as it ended) is spurious.
    if (ready > 0 || Now() >= deadline) {
      if (all != stack) ::free(all);
      return ready;
    }
  }
}

/// Waits on condition variable c until virtual `deadline`: 0 (woken; possibly spuriously,
/// as POSIX allows) or ETIMEDOUT.
int CondWaitUntil(pthread_cond_t* c, pthread_mutex_t* m, std::int64_t deadline) {
  vt::ThreadSlot& s = Self();
  if (deadline != vt::kNoDeadline) {
    if (DeadlinePassed(deadline)) return ETIMEDOUT;
    EnsureAgent();
  }
  WaitTarget target;
  target.cond = reinterpret_cast<std::uintptr_t>(c);
  target.mutex = reinterpret_cast<std::uintptr_t>(m);
  BeginWait(s, vt::kCondWait, deadline, target);
  const int rc = real_pthread_cond_wait()(c, m);
  EndWait(s);
  if (rc == 0 && deadline != vt::kNoDeadline && Now() >= deadline) return ETIMEDOUT;
  return rc;
}

/// sem_wait until virtual `deadline`: 0, or -1 with errno ETIMEDOUT (or EINTR for a signal of
/// the program's own). The host ends the wait at the deadline with kWakeSignal to this thread.
int SemWaitUntil(sem_t* sem, std::int64_t deadline) {
  if (sem_trywait(sem) == 0) return 0;
  if (DeadlinePassed(deadline)) {
    errno = ETIMEDOUT;
    return -1;
  }
  EnsureWakeSignal();
  vt::ThreadSlot& s = Self();
  sigset_t wake, old;
  sigemptyset(&wake);
  sigaddset(&wake, vt::kWakeSignal);
  pthread_sigmask(SIG_UNBLOCK, &wake, &old);
  BeginWait(s, vt::kSignalWait, deadline);
  int rc = real_sem_wait()(sem);
  int err = errno;
  EndWait(s);
  pthread_sigmask(SIG_SETMASK, &old, nullptr);
  if (rc != 0 && err == EINTR && Now() >= deadline) err = ETIMEDOUT;
  errno = err;
  return rc;
}

/// A mutex has no wait the host can end: tried every millisecond of virtual time until the
/// deadline (deterministic; the lock is taken up to 1 ms after its release).
int MutexLockUntil(pthread_mutex_t* m, std::int64_t deadline) {
  for (;;) {
    const int rc = pthread_mutex_trylock(m);
    if (rc != EBUSY) return rc;
    const std::int64_t now = Now();
    if (now >= deadline) return ETIMEDOUT;
    if (SleepUntil(std::min(deadline, now + 1000000)) != 0) continue;
  }
}

// ---- virtual timers ----

/// A disarmed timer slot of this process telling its expiry by `notify`; -1 when all are taken.
int ClaimTimer(clockid_t c, vt::TimerNotify notify, int fd) {
  for (int i = 0; i < vt::kMaxTimers; ++i) {
    vt::TimerSlot& t = g_page->timers[i];
    std::uint32_t expect = vt::kTimerFree;
    if (!t.state.compare_exchange_strong(expect, vt::kTimerDisarmed)) continue;
    t.fired.store(0);
    t.fd = fd;
    t.notify.store(notify);
    t.signo = 0;
    t.target_tid = 0;
    t.sigval = 0;
    t.function = 0;
    t.overrun.store(0);
    t.generation.fetch_add(1);
    t.next_ns.store(vt::kNoDeadline);
    t.interval_ns.store(0);
    t.pid.store(getpid());
    g_timer_clock[i] = c;
    RaiseUsed(g_page->timers_used, i);
    return i;
  }
  return -1;
}

/// Arms (value > 0) or disarms a timer slot; `abs`: value is an absolute time on its clock.
void ArmTimer(int i, const itimerspec& v, bool abs) {
  vt::TimerSlot& t = g_page->timers[i];
  t.state.store(vt::kTimerDisarmed);
  t.next_ns.store(vt::kNoDeadline);
  t.fired.store(0);
  const std::int64_t value = vt::ToNs(v.it_value.tv_sec, v.it_value.tv_nsec);
  if (value == 0) return;
  const std::int64_t next = abs ? DeadlineFromAbs(g_timer_clock[i], v.it_value) : DeadlineIn(value);
  t.interval_ns.store(vt::ToNs(v.it_interval.tv_sec, v.it_interval.tv_nsec));
  t.next_ns.store(next);
  t.state.store(vt::kTimerArmed);
}

bool ValidItimerspec(const itimerspec& v) {
  return v.it_value.tv_nsec >= 0 && v.it_value.tv_nsec < 1000000000 &&
         v.it_interval.tv_nsec >= 0 && v.it_interval.tv_nsec < 1000000000 &&
         v.it_value.tv_sec >= 0 && v.it_interval.tv_sec >= 0;
}

// timer_t handles of virtual timers: above every user-space address and kernel timer id.
constexpr std::uintptr_t kTimerHandleTag = 0x7674000000000000ull;

timer_t TimerHandle(int slot) {
  return reinterpret_cast<timer_t>(kTimerHandleTag | static_cast<std::uintptr_t>(slot));
}
int TimerSlotOf(timer_t h) {
  const auto v = reinterpret_cast<std::uintptr_t>(h);
  if ((v & ~std::uintptr_t{0xffff}) != kTimerHandleTag) return -1;
  const int i = static_cast<int>(v & 0xffff);
  if (i >= vt::kMaxTimers || g_page->timers[i].state.load() == vt::kTimerFree ||
      g_page->timers[i].pid.load() != getpid()) {
    return -1;
  }
  return i;
}

/// The process's alarm / ITIMER_REAL timer (created on first use), -1 when none is free.
int AlarmTimer() {
  const int used = g_page->timers_used.load();
  for (int i = 0; i < used; ++i) {
    const vt::TimerSlot& t = g_page->timers[i];
    if (t.state.load() != vt::kTimerFree && t.pid.load() == getpid() &&
        t.notify.load() == vt::kNotifyAlarm) {
      return i;
    }
  }
  return ClaimTimer(CLOCK_MONOTONIC, vt::kNotifyAlarm, -1);
}

// ---- virtual timerfds ----

int TimerOf(int fd) {
  if (fd < 0) return -1;
  const int used = g_page->timers_used.load();
  const pid_t me = getpid();
  for (int i = 0; i < used; ++i) {
    const vt::TimerSlot& t = g_page->timers[i];
    if (t.state.load() != vt::kTimerFree && t.fd == fd && t.pid.load() == me) return i;
  }
  return -1;
}

itimerspec TimerValue(const vt::TimerSlot& t) {
  itimerspec v{};
  const std::int64_t next = t.next_ns.load();
  if (t.state.load() == vt::kTimerArmed) {
    // (Armed for longer than ns can count: the most there is, as the kernel's KTIME_MAX.)
    v.it_value = ToTimespec(next - Now());
    if (v.it_value.tv_sec == 0 && v.it_value.tv_nsec == 0) v.it_value.tv_nsec = 1;
  }
  v.it_interval = ToTimespec(t.interval_ns.load());
  return v;
}

// ---- set-up ----

void FreeStaleSlots(pid_t pid, int keep) {
  // After an exec the process keeps its pid but not its threads, timers or agent.
  for (int i = 0; i < vt::kMaxThreads; ++i) {
    vt::ThreadSlot& s = g_page->threads[i];
    if (i != keep && s.state.load() != vt::kFree && s.pid.load() == pid) FreeThreadSlot(i);
  }
  for (int i = 0; i < vt::kMaxTimers; ++i) {
    vt::TimerSlot& t = g_page->timers[i];
    if (t.state.load() != vt::kTimerFree && t.pid.load() == pid) t.state.store(vt::kTimerFree);
  }
}

int ClaimProcessSlot(vt::ProcessState state, pid_t pid) {
  for (int i = 0; i < vt::kMaxProcesses; ++i) {
    vt::ProcessSlot& p = g_page->processes[i];
    std::uint32_t expect = vt::kProcFree;
    if (p.state.compare_exchange_strong(expect, vt::kProcStarting)) {
      p.pid.store(pid);
      p.agent.store(-1);
      p.exec_pending.store(0);
      p.state.store(state);
      return i;
    }
  }
  ::fprintf(stderr, "wheelhil vtime: more than %d firmware processes\n", vt::kMaxProcesses);
  ::abort();
}

void RegisterProcess() {
  const pid_t me = getpid();
  g_proc = -1;
  for (int i = 0; i < vt::kMaxProcesses; ++i) {
    vt::ProcessSlot& p = g_page->processes[i];
    if (p.state.load() != vt::kProcFree && p.pid.load() == me) {
      g_proc = i;
      break;
    }
  }
  // The host registers the firmware's first process before it knows its pid (-1), and sets
  // the pid once its fork returned: here, or between the look above and this one (a host
  // slower than the new program's start: then the swap finds `me` there already, and the slot
  // is this process's all the same; a second slot would leave this one starting for ever).
  for (int i = 0; g_proc < 0 && i < vt::kMaxProcesses; ++i) {
    std::int32_t expect = vt::kFirstProcessPid;
    if (g_page->processes[i].state.load() == vt::kProcStarting &&
        (g_page->processes[i].pid.compare_exchange_strong(expect, me) || expect == me)) {
      g_proc = i;
    }
  }
  // The new main thread's slot first: the process is never without a running thread.
  t_slot = ClaimThreadSlot(Tid());
  FreeStaleSlots(me, t_slot);
  if (g_proc >= 0) {
    g_page->processes[g_proc].agent.store(-1);
    g_page->processes[g_proc].exec_pending.store(0);
    g_page->processes[g_proc].state.store(vt::kProcAlive);
  } else {
    g_proc = ClaimProcessSlot(vt::kProcAlive, me);
  }
  // An exec closed the old program's close-on-exec sockets: counted once they are closed.
  g_page->bus_calls.fetch_add(1);
  Transition();
}

void OnThreadExit(void* value) {
  const int slot = static_cast<int>(reinterpret_cast<std::intptr_t>(value)) - 1;
  if (slot < 0 || g_page == nullptr) return;
  CloseWakeFd(slot);
  FreeThreadSlot(slot);
}

__attribute__((constructor)) void Init() {
  const char* path = ::getenv(vt::kPageEnv);
  if (path == nullptr || *path == '\0') return;
  const int fd = ::open(path, O_RDWR | O_CLOEXEC);
  struct stat st {};
  if (fd < 0 || ::fstat(fd, &st) != 0 || st.st_size < static_cast<off_t>(sizeof(vt::Page))) {
    ::fprintf(stderr, "wheelhil vtime: cannot open the clock page %s (%s)\n", path,
              fd < 0 ? strerror(errno) : "too small");
    ::_exit(127);
  }
  void* p = ::mmap(nullptr, sizeof(vt::Page), PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  ::close(fd);
  if (p == MAP_FAILED) {
    ::fprintf(stderr, "wheelhil vtime: cannot map the clock page %s (%s)\n", path,
              strerror(errno));
    ::_exit(127);
  }
  auto* page = static_cast<vt::Page*>(p);
  if (page->magic != vt::kMagic || page->size != sizeof(vt::Page)) {
    ::fprintf(stderr, "wheelhil vtime: %s is not a clock page of this version\n", path);
    ::_exit(127);
  }
  pthread_key_create(&g_thread_key, OnThreadExit);
  g_page = page;
  RegisterProcess();
}

struct ThreadStart {
  void* (*fn)(void*);
  void* arg;
  int slot;
};

void* ThreadTrampoline(void* raw) {
  ThreadStart start = *static_cast<ThreadStart*>(raw);
  ::free(raw);
  t_slot = start.slot;
  g_page->threads[t_slot].tid.store(Tid());
  pthread_setspecific(g_thread_key, reinterpret_cast<void*>(static_cast<std::intptr_t>(t_slot) + 1));
  Transition();
  return start.fn(start.arg);
}

}  // namespace

// ---- clocks ----

VTIME_EXPORT int clock_gettime(clockid_t c, timespec* ts) {
  if (g_page == nullptr || !IsVirtualClock(c)) return real_clock_gettime()(c, ts);
  *ts = ToTimespec(NowOn(c));
  NoteCall(vt::kCallClock);
  return 0;
}

VTIME_EXPORT int gettimeofday(timeval* tv, void* tz) {
  if (g_page == nullptr) return real_gettimeofday()(tv, tz);
  const std::int64_t ns = NowOn(CLOCK_REALTIME);
  tv->tv_sec = static_cast<time_t>(ns / 1000000000);
  tv->tv_usec = static_cast<suseconds_t>(ns % 1000000000 / 1000);
  if (tz != nullptr) std::memset(tz, 0, sizeof(struct timezone));
  NoteCall(vt::kCallClock);
  return 0;
}

VTIME_EXPORT time_t time(time_t* out) {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  if (out != nullptr) *out = ts.tv_sec;
  return ts.tv_sec;
}

VTIME_EXPORT int timespec_get(timespec* ts, int base) {
  if (base != TIME_UTC) return 0;
  return clock_gettime(CLOCK_REALTIME, ts) == 0 ? base : 0;
}

// ---- setting the clock: the firmware's own CLOCK_REALTIME, never the host's ----
//
// A firmware may set its clock (from GPS, NTP, its RTC): every call that would set or adjust
// the host's clock moves the virtual CLOCK_REALTIME of all the firmware's processes instead,
// whatever the firmware's privileges. A virtual clock has no rate to discipline: adjustments
// (adjtime, adjtimex offsets) are applied at once; frequency and status are kept and read back.

namespace {

void StepRealtime(std::int64_t delta_ns) { g_page->realtime_offset_ns.fetch_add(delta_ns); }

void SetRealtime(std::int64_t realtime_ns) {
  g_page->realtime_offset_ns.store(realtime_ns - Now());
}

int Fail(int err) {
  errno = err;
  return -1;
}

// What adjtimex keeps besides the time (process-wide, as the kernel's is system-wide; under
// g_ntp_lock).
long g_ntp_freq = 0, g_ntp_maxerror = 0, g_ntp_esterror = 0, g_ntp_constant = 0;
long g_ntp_tick = 10000;
int g_ntp_status = 0;

int AdjustVirtualClockLocked(timex* tx);

pthread_mutex_t g_ntp_lock = PTHREAD_MUTEX_INITIALIZER;

int AdjustVirtualClock(timex* tx) {
  pthread_mutex_lock(&g_ntp_lock);
  const int rc = AdjustVirtualClockLocked(tx);
  pthread_mutex_unlock(&g_ntp_lock);
  return rc;
}

int AdjustVirtualClockLocked(timex* tx) {
  if (tx == nullptr) return Fail(EFAULT);
  const unsigned modes = tx->modes;
  if (modes == ADJ_OFFSET_SINGLESHOT) {
    StepRealtime(std::int64_t{tx->offset} * 1000);  // adjtime(): microseconds
  } else if (modes != ADJ_OFFSET_SS_READ) {
    const bool nano = (modes & ADJ_NANO) || ((g_ntp_status & STA_NANO) && !(modes & ADJ_MICRO));
    if (modes & ADJ_SETOFFSET) {
      const long sub = tx->time.tv_usec;
      if (sub < 0 || sub >= (nano ? 1000000000L : 1000000L)) return Fail(EINVAL);
      StepRealtime(vt::ToNs(tx->time.tv_sec, nano ? sub : sub * 1000));
    }
    if (modes & ADJ_OFFSET) StepRealtime(nano ? tx->offset : std::int64_t{tx->offset} * 1000);
    if (modes & ADJ_FREQUENCY) g_ntp_freq = tx->freq;
    if (modes & ADJ_MAXERROR) g_ntp_maxerror = tx->maxerror;
    if (modes & ADJ_ESTERROR) g_ntp_esterror = tx->esterror;
    if (modes & ADJ_TIMECONST) g_ntp_constant = tx->constant;
    if (modes & ADJ_TICK) g_ntp_tick = tx->tick;
    if (modes & ADJ_STATUS) g_ntp_status = tx->status;
    if (modes & ADJ_NANO) g_ntp_status |= STA_NANO;
    if (modes & ADJ_MICRO) g_ntp_status &= ~STA_NANO;
  }
  const std::int64_t now = NowOn(CLOCK_REALTIME);
  const bool nano = (g_ntp_status & STA_NANO) != 0;
  tx->offset = 0;  // nothing left to slew
  tx->freq = g_ntp_freq;
  tx->maxerror = g_ntp_maxerror;
  tx->esterror = g_ntp_esterror;
  tx->status = g_ntp_status;
  tx->constant = g_ntp_constant;
  tx->precision = 1;
  tx->tolerance = 500L << 16;  // 500 ppm, as the kernel's MAXFREQ
  tx->tick = g_ntp_tick;
  tx->time.tv_sec = static_cast<time_t>(now / 1000000000);
  tx->time.tv_usec = static_cast<suseconds_t>(nano ? now % 1000000000 : now % 1000000000 / 1000);
  return TIME_OK;
}

}  // namespace

VTIME_EXPORT int clock_settime(clockid_t c, const timespec* ts) {
  if (g_page == nullptr) return real_clock_settime()(c, ts);
  // Only CLOCK_REALTIME can be set (the kernel's EINVAL for the others); CPU-time and dynamic
  // clocks (a /dev/ptp device: host hardware) are refused.
  if (c != CLOCK_REALTIME) return Fail(IsVirtualClock(c) ? EINVAL : EPERM);
  if (!ValidTimespec(*ts)) return Fail(EINVAL);
  SetRealtime(vt::ToNs(ts->tv_sec, ts->tv_nsec));
  return 0;
}

VTIME_EXPORT int settimeofday(const timeval* tv, const struct timezone* tz) {
  if (g_page == nullptr) return real_settimeofday()(tv, tz);
  // The time zone (tz) is the host's: ignored.
  if (tv == nullptr) return 0;
  if (tv->tv_sec < 0 || tv->tv_usec < 0 || tv->tv_usec >= 1000000) return Fail(EINVAL);
  SetRealtime(vt::ToNs(tv->tv_sec, std::int64_t{tv->tv_usec} * 1000));
  return 0;
}

VTIME_EXPORT int adjtimex(timex* tx) {
  if (g_page == nullptr) return real_adjtimex()(tx);
  return AdjustVirtualClock(tx);
}

VTIME_EXPORT int ntp_adjtime(timex* tx) {
  if (g_page == nullptr) return real_ntp_adjtime()(tx);
  return AdjustVirtualClock(tx);
}

VTIME_EXPORT int clock_adjtime(clockid_t c, timex* tx) {
  if (g_page == nullptr) return real_clock_adjtime()(c, tx);
  if (c != CLOCK_REALTIME) return Fail(IsVirtualClock(c) ? EOPNOTSUPP : EPERM);
  return AdjustVirtualClock(tx);
}

VTIME_EXPORT int adjtime(const timeval* delta, timeval* olddelta) {
  if (g_page == nullptr) return real_adjtime()(delta, olddelta);
  if (delta != nullptr) StepRealtime(vt::ToNs(delta->tv_sec, std::int64_t{delta->tv_usec} * 1000));
  if (olddelta != nullptr) *olddelta = timeval{0, 0};
  return 0;
}

// Gone from glibc's headers, still in its ABI (stime@GLIBC_2.2.5) for old binaries.
VTIME_EXPORT int stime(const time_t* t) {
  if (g_page == nullptr) {
    if (auto real = real_stime()) return real(t);
    return Fail(ENOSYS);
  }
  if (t == nullptr) return Fail(EFAULT);
  SetRealtime(vt::ToNs(*t, 0));
  return 0;
}

// ---- sleeps ----

VTIME_EXPORT int clock_nanosleep(clockid_t c, int flags, const timespec* req, timespec* rem) {
  if (g_page == nullptr || !IsVirtualClock(c)) return real_clock_nanosleep()(c, flags, req, rem);
  if (req == nullptr) return EFAULT;
  if (!ValidTimespec(*req)) return EINVAL;
  const std::int64_t deadline = (flags & TIMER_ABSTIME) ? DeadlineFromAbs(c, *req)
                                                        : DeadlineIn(vt::ToNs(req->tv_sec, req->tv_nsec));
  const int rc = SleepUntil(deadline);
  if (rc == EINTR && rem != nullptr && !(flags & TIMER_ABSTIME)) *rem = ToTimespec(deadline - Now());
  return rc;
}

VTIME_EXPORT int nanosleep(const timespec* req, timespec* rem) {
  if (g_page == nullptr) return real_nanosleep()(req, rem);
  const int rc = clock_nanosleep(CLOCK_MONOTONIC, 0, req, rem);
  if (rc == 0) return 0;
  errno = rc;
  return -1;
}

VTIME_EXPORT int usleep(useconds_t us) {
  const timespec req{static_cast<time_t>(us / 1000000), static_cast<long>(us % 1000000) * 1000};
  return nanosleep(&req, nullptr);
}

VTIME_EXPORT unsigned sleep(unsigned s) {
  timespec req{static_cast<time_t>(s), 0}, rem{};
  if (nanosleep(&req, &rem) == 0) return 0;
  return static_cast<unsigned>(rem.tv_sec + (rem.tv_nsec > 0 ? 1 : 0));
}

// ---- poll, select, epoll ----

VTIME_EXPORT int ppoll(pollfd* fds, nfds_t n, const timespec* tmo, const sigset_t* mask) {
  if (g_page == nullptr) return real_ppoll()(fds, n, tmo, mask);
  static const timespec kZero{0, 0};
  if (tmo != nullptr && !ValidTimespec(*tmo)) {
    errno = EINVAL;
    return -1;
  }
  if (tmo != nullptr && tmo->tv_sec == 0 && tmo->tv_nsec == 0) {
    const int rc = real_ppoll()(fds, n, &kZero, mask);
    if (rc == 0) NoteCall(vt::kCallPollZero);
    return rc;
  }
  // No zero-timeout look first: a wait on fds that are ready ends at once (one system call).
  const std::int64_t deadline =
      tmo == nullptr ? vt::kNoDeadline : DeadlineIn(vt::ToNs(tmo->tv_sec, tmo->tv_nsec));
  return PollUntil(fds, n, deadline, mask);
}

VTIME_EXPORT int poll(pollfd* fds, nfds_t n, int timeout_ms) {
  if (g_page == nullptr) return real_poll()(fds, n, timeout_ms);
  if (timeout_ms < 0) return ppoll(fds, n, nullptr, nullptr);
  const timespec tmo = ToTimespec(std::int64_t{timeout_ms} * 1000000);
  return ppoll(fds, n, &tmo, nullptr);
}

namespace {

int SelectVirtual(int nfds, fd_set* rd, fd_set* wr, fd_set* ex, std::int64_t timeout_ns,
                  const sigset_t* mask) {
  const fd_set none{};
  const fd_set r0 = rd ? *rd : none, w0 = wr ? *wr : none, e0 = ex ? *ex : none;
  timespec zero{0, 0};
  int rc = real_pselect()(nfds, rd, wr, ex, &zero, mask);
  if (rc != 0) return rc;
  if (timeout_ns == 0) {
    NoteCall(vt::kCallPollZero);
    return 0;
  }
  const std::int64_t deadline = timeout_ns < 0 ? vt::kNoDeadline : DeadlineIn(timeout_ns);
  pollfd fds[FD_SETSIZE];
  for (;;) {
    nfds_t n = 0;
    for (int fd = 0; fd < nfds && fd < FD_SETSIZE; ++fd) {
      short ev = 0;
      if (FD_ISSET(fd, &r0)) ev |= POLLIN;
      if (FD_ISSET(fd, &w0)) ev |= POLLOUT;
      if (FD_ISSET(fd, &e0)) ev |= POLLPRI;
      if (ev != 0) fds[n++] = pollfd{fd, ev, 0};
    }
    rc = PollUntil(fds, n, deadline, mask);
    if (rc <= 0) {
      if (rc == 0) {
        if (rd) FD_ZERO(rd);
        if (wr) FD_ZERO(wr);
        if (ex) FD_ZERO(ex);
      }
      return rc;
    }
    // The kernel says which sets are ready (select's own semantics).
    if (rd) *rd = r0;
    if (wr) *wr = w0;
    if (ex) *ex = e0;
    rc = real_pselect()(nfds, rd, wr, ex, &zero, mask);
    if (rc != 0) return rc;
  }
}

}  // namespace

VTIME_EXPORT int select(int nfds, fd_set* rd, fd_set* wr, fd_set* ex, timeval* tv) {
  if (g_page == nullptr) return real_select()(nfds, rd, wr, ex, tv);
  const std::int64_t ns = tv == nullptr ? -1 : vt::ToNs(tv->tv_sec, std::int64_t{tv->tv_usec} * 1000);
  const int rc = SelectVirtual(nfds, rd, wr, ex, ns, nullptr);
  if (rc == 0 && tv != nullptr) *tv = timeval{0, 0};  // as Linux: the time not slept
  return rc;
}

VTIME_EXPORT int pselect(int nfds, fd_set* rd, fd_set* wr, fd_set* ex, const timespec* ts,
                         const sigset_t* mask) {
  if (g_page == nullptr) return real_pselect()(nfds, rd, wr, ex, ts, mask);
  return SelectVirtual(nfds, rd, wr, ex, ts == nullptr ? -1 : vt::ToNs(ts->tv_sec, ts->tv_nsec),
                       mask);
}

VTIME_EXPORT int epoll_pwait(int epfd, epoll_event* ev, int max, int timeout_ms,
                             const sigset_t* mask) {
  if (g_page == nullptr) return real_epoll_pwait()(epfd, ev, max, timeout_ms, mask);
  int rc = 0;
  if (timeout_ms == 0) {
    rc = real_epoll_pwait()(epfd, ev, max, 0, mask);
    if (rc == 0) NoteCall(vt::kCallPollZero);
    return rc;
  }
  const std::int64_t deadline =
      timeout_ms < 0 ? vt::kNoDeadline : DeadlineIn(std::int64_t{timeout_ms} * 1000000);
  for (;;) {
    // An epoll fd is readable while its ready list is not empty.
    pollfd p{epfd, POLLIN, 0};
    rc = PollUntil(&p, 1, deadline, mask);
    if (rc <= 0) return rc;
    rc = real_epoll_pwait()(epfd, ev, max, 0, mask);
    if (rc != 0) return rc;
  }
}

VTIME_EXPORT int epoll_create(int size) {
  const int fd = real_epoll_create()(size);
  if (g_page != nullptr) TrackNewEpoll(fd);
  return fd;
}

VTIME_EXPORT int epoll_create1(int flags) {
  const int fd = real_epoll_create1()(flags);
  if (g_page != nullptr) TrackNewEpoll(fd);
  return fd;
}

VTIME_EXPORT int epoll_ctl(int epfd, int op, int fd, epoll_event* ev) {
  const int rc = real_epoll_ctl()(epfd, op, fd, ev);
  if (g_page != nullptr && rc == 0) TrackEpollCtl(epfd, op, fd, ev);
  return rc;
}

VTIME_EXPORT int epoll_wait(int epfd, epoll_event* ev, int max, int timeout_ms) {
  if (g_page == nullptr) return real_epoll_wait()(epfd, ev, max, timeout_ms);
  return epoll_pwait(epfd, ev, max, timeout_ms, nullptr);
}

// ---- timerfd ----

VTIME_EXPORT int timerfd_create(int c, int flags) {
  if (g_page == nullptr || !IsVirtualClock(c)) return real_timerfd_create()(c, flags);
  if (flags & ~(TFD_NONBLOCK | TFD_CLOEXEC)) {
    errno = EINVAL;
    return -1;
  }
  const int fd = eventfd(0, ((flags & TFD_NONBLOCK) ? EFD_NONBLOCK : 0) |
                                ((flags & TFD_CLOEXEC) ? EFD_CLOEXEC : 0));
  if (fd < 0) return -1;
  if (ClaimTimer(c, vt::kNotifyEventFd, fd) < 0) {
    real_close()(fd);
    errno = EMFILE;
    return -1;
  }
  return fd;
}

VTIME_EXPORT int timerfd_gettime(int fd, itimerspec* cur) {
  const int i = g_page == nullptr ? -1 : TimerOf(fd);
  if (i < 0) return real_timerfd_gettime()(fd, cur);
  if (cur == nullptr) {
    errno = EFAULT;
    return -1;
  }
  *cur = TimerValue(g_page->timers[i]);
  return 0;
}

VTIME_EXPORT int timerfd_settime(int fd, int flags, const itimerspec* nv, itimerspec* old) {
  const int i = g_page == nullptr ? -1 : TimerOf(fd);
  if (i < 0) return real_timerfd_settime()(fd, flags, nv, old);
  if (nv == nullptr || nv->it_value.tv_nsec < 0 || nv->it_value.tv_nsec >= 1000000000 ||
      nv->it_interval.tv_nsec < 0 || nv->it_interval.tv_nsec >= 1000000000) {
    errno = nv == nullptr ? EFAULT : EINVAL;
    return -1;
  }
  vt::TimerSlot& t = g_page->timers[i];
  if (old != nullptr) *old = TimerValue(t);
  EnsureAgent();
  // Disarm first (the host no longer fires it), then the new setting; expirations not yet
  // read are discarded, as timerfd_settime(2) does.
  t.state.store(vt::kTimerDisarmed);
  DrainEventFd(fd);
  ArmTimer(i, *nv, (flags & TFD_TIMER_ABSTIME) != 0);
  return 0;
}

// ---- descriptors: the library keeps its own ----

namespace {

void FreeTimerSlot(int i) {
  g_page->timers[i].state.store(vt::kTimerFree);
  g_page->timers[i].pid.store(0);
}

/// The virtual timerfds of this process numbered first..last are closed.
void FreeTimersIn(unsigned first, unsigned last) {
  const int used = g_page->timers_used.load();
  const pid_t me = getpid();
  for (int i = 0; i < used; ++i) {
    const vt::TimerSlot& t = g_page->timers[i];
    if (t.state.load() != vt::kTimerFree && t.pid.load() == me && t.fd >= 0 &&
        static_cast<unsigned>(t.fd) >= first && static_cast<unsigned>(t.fd) <= last) {
      FreeTimerSlot(i);
    }
  }
}

/// The program is about to put another file on number `fd`: when that is a wake eventfd of the
/// library's, it moves to a free number first. -1 (errno) when there is none.
int MoveLibraryFd(int fd) {
  const int used = g_page->threads_used.load();
  for (int i = 0; i < used; ++i) {
    if (g_wake_fd_plus1[i].load() != fd + 1) continue;
    const int moved = ::fcntl(fd, F_DUPFD_CLOEXEC, 0);
    if (moved < 0) return -1;
    // The slot's copy first: a waiting thread's ppoll holds the file, not the number, and the
    // host or agent writes whichever number it reads.
    vt::ThreadSlot& s = g_page->threads[i];
    if (s.wake_fd == fd) s.wake_fd = moved;
    g_wake_fd_plus1[i].store(moved + 1);
    // A thread polling the old number would look at the program's new file there from its
    // next wake-up on (poll resolves numbers each time): the wake signal sends it round again.
    // Signalled on its way into that ppoll, it would enter it after the handler ran: it is
    // signalled until it is out, for at most 50 ms of the host's time (a thread that blocks the
    // signal stays in its ppoll on the eventfd, which the host still reaches by its new number).
    // This thread yields rather than sleeps: asleep, the host would take it for blocked.
    if (i != t_slot) {
      EnsureWakeSignal();
      timespec t0{}, now{};
      real_clock_gettime()(CLOCK_MONOTONIC, &t0);
      while (g_polling_wake_plus1[i].load() == fd + 1) {
        real_syscall()(SYS_tgkill, s.pid.load(), s.tid.load(), vt::kWakeSignal);
        ::sched_yield();
        real_clock_gettime()(CLOCK_MONOTONIC, &now);
        if ((now.tv_sec - t0.tv_sec) * 1'000'000'000L + (now.tv_nsec - t0.tv_nsec) > 50'000'000L) {
          break;
        }
      }
    }
    return 0;
  }
  return 0;
}

}  // namespace

VTIME_EXPORT int close(int fd) {
  if (g_page != nullptr) {
    // Not the program's descriptor: the kernel's answer for a number it never opened.
    if (IsLibraryFd(fd) && !InVforkChild()) {
      errno = EBADF;
      return -1;
    }
    const int i = TimerOf(fd);
    if (i >= 0) FreeTimerSlot(i);
    ForgetEpoll(fd);
  }
  MarkKernelCan(fd, false);
  return real_close()(fd);
}

VTIME_EXPORT int close_range(unsigned first, unsigned last, int flags) {
  if (g_page == nullptr || first > last || (flags & CLOSE_RANGE_CLOEXEC)) {
    // (The library's descriptors are close-on-exec already.)
    return real_close_range()(first, last, flags);
  }
  // The range in pieces around the library's descriptors.
  int keep[vt::kMaxThreads];
  int n = 0;
  const int used = g_page->threads_used.load();
  for (int i = 0; i < used; ++i) {
    const int fd = g_wake_fd_plus1[i].load() - 1;
    if (fd >= 0 && static_cast<unsigned>(fd) >= first && static_cast<unsigned>(fd) <= last) {
      keep[n++] = fd;
    }
  }
  std::sort(keep, keep + n);
  unsigned from = first;
  for (int k = 0; k < n; ++k) {
    const auto fd = static_cast<unsigned>(keep[k]);
    if (fd > from && real_close_range()(from, fd - 1, flags) != 0) return -1;
    from = fd + 1;
  }
  if (from <= last && real_close_range()(from, last, flags) != 0) return -1;
  FreeTimersIn(first, last);
  for (unsigned fd = first; fd <= last && fd < static_cast<unsigned>(kMaxEpollFds); ++fd) {
    ForgetEpoll(static_cast<int>(fd));
  }
  for (unsigned fd = first; fd <= last && fd < static_cast<unsigned>(kMaxCanFds); ++fd) {
    MarkKernelCan(static_cast<int>(fd), false);
  }
  return 0;
}

VTIME_EXPORT void closefrom(int low) {
  if (g_page == nullptr) {
    real_closefrom()(low);
    return;
  }
  const unsigned first = low < 0 ? 0u : static_cast<unsigned>(low);
  if (close_range(first, ~0u, 0) == 0) return;
  // No close_range in this kernel: one by one, up to the descriptor limit.
  const long max = ::sysconf(_SC_OPEN_MAX);
  for (long fd = first; fd < (max > 0 ? max : 1024); ++fd) close(static_cast<int>(fd));
}

namespace {

/// Before `fd2` takes another file: 0, or -1 (errno) when the library's descriptor there
/// could not be moved away.
int KeepLibraryFd(int fd, int fd2) {
  if (g_page == nullptr || fd == fd2 || InVforkChild()) return 0;
  ForgetEpoll(fd2);
  return MoveLibraryFd(fd2);
}

}  // namespace

VTIME_EXPORT int dup2(int fd, int fd2) {
  if (KeepLibraryFd(fd, fd2) != 0) return -1;
  const int r = real_dup2()(fd, fd2);
  if (r >= 0 && fd != fd2) MarkKernelCan(fd2, MarkedKernelCan(fd));
  return r;
}

VTIME_EXPORT int dup3(int fd, int fd2, int flags) {
  if (KeepLibraryFd(fd, fd2) != 0) return -1;
  const int r = real_dup3()(fd, fd2, flags);
  if (r >= 0) MarkKernelCan(fd2, MarkedKernelCan(fd));
  return r;
}

// ---- threads, condition variables, processes ----

VTIME_EXPORT int pthread_create(pthread_t* t, const pthread_attr_t* attr, void* (*fn)(void*),
                                void* arg) {
  if (g_page == nullptr) return real_pthread_create()(t, attr, fn, arg);
  auto* start = static_cast<ThreadStart*>(::malloc(sizeof(ThreadStart)));
  if (start == nullptr) return EAGAIN;
  // Claimed before the thread exists (tid 0): the host waits for it to start.
  *start = ThreadStart{fn, arg, ClaimThreadSlot(0)};
  const int slot = start->slot;
  const int rc = real_pthread_create()(t, attr, ThreadTrampoline, start);
  if (rc != 0) {
    ::free(start);
    FreeThreadSlot(slot);
  }
  return rc;
}

VTIME_EXPORT int pthread_cond_wait(pthread_cond_t* c, pthread_mutex_t* m) {
  if (g_page == nullptr) return real_pthread_cond_wait()(c, m);
  return CondWaitUntil(c, m, vt::kNoDeadline);
}

VTIME_EXPORT int pthread_cond_clockwait(pthread_cond_t* c, pthread_mutex_t* m, clockid_t clk,
                                        const timespec* abstime) {
  if (g_page == nullptr || !IsVirtualClock(clk)) return real_pthread_cond_clockwait()(c, m, clk, abstime);
  if (abstime->tv_nsec < 0 || abstime->tv_nsec >= 1000000000) return EINVAL;
  return CondWaitUntil(c, m, DeadlineFromAbs(clk, *abstime));
}

VTIME_EXPORT int pthread_cond_timedwait(pthread_cond_t* c, pthread_mutex_t* m,
                                        const timespec* abstime) {
  if (g_page == nullptr) return real_pthread_cond_timedwait()(c, m, abstime);
  if (abstime->tv_nsec < 0 || abstime->tv_nsec >= 1000000000) return EINVAL;
  // glibc keeps the clock of pthread_condattr_setclock in __wrefs: bit 1 set is monotonic
  // (__PTHREAD_COND_CLOCK_MONOTONIC_MASK; bit 0 is process-shared).
  const clockid_t clk = (c->__data.__wrefs & 2) ? CLOCK_MONOTONIC : CLOCK_REALTIME;
  return CondWaitUntil(c, m, DeadlineFromAbs(clk, *abstime));
}

VTIME_EXPORT pid_t fork() {
  if (g_page == nullptr) return real_fork()();
  // The child's process slot exists before the child does (pid 0 = fork in progress), so the
  // host never takes the firmware for blocked while a child it has not seen yet runs.
  const int slot = ClaimProcessSlot(vt::kProcStarting, 0);
  const pid_t pid = real_fork()();
  // An epoll set made before shares its members with the other process from here on, which
  // this one's record would not see: such sets are no longer vouched for on either side. (The
  // child's lock may have been held by a thread it does not have.)
  if (pid == 0) g_epoll_lock = PTHREAD_MUTEX_INITIALIZER;
  if (pid >= 0) ForgetEveryEpoll();
  if (pid == 0) {
    // The parent's wake eventfds are copies here, of threads this process does not have.
    for (int i = 0; i < vt::kMaxThreads; ++i) CloseWakeFd(i);
    t_wait_depth = 0;
    t_slot = ClaimThreadSlot(Tid());
    g_agent_started = false;
    g_agent_lock = PTHREAD_MUTEX_INITIALIZER;
    g_proc = slot;
    g_page->processes[slot].pid.store(getpid());
    g_page->processes[slot].state.store(vt::kProcAlive);
    Transition();
  } else if (pid > 0) {
    g_page->processes[slot].pid.store(pid);
  } else {
    g_page->processes[slot].state.store(vt::kProcFree);
  }
  return pid;
}

// An exec replaces the program: until the new one's library registers it, the process is
// starting again, so a program without the library (LD_PRELOAD cleared, a static binary) is
// never taken for blocked and is named when the run gives up on it.
namespace {

// The exec of a vfork child is not its parent's: the new program registers itself.
bool ExecIsThisProcess() { return g_page != nullptr && g_proc >= 0 && !InVforkChild(); }

void BeforeExec() {
  if (ExecIsThisProcess()) {
    g_page->processes[g_proc].exec_pending.store(1);
    g_page->processes[g_proc].state.store(vt::kProcStarting);
    g_page->bus_calls.fetch_add(1);  // its close-on-exec sockets close with the exec
    Transition();
  }
}

int AfterFailedExec(int rc) {
  const int err = errno;
  if (ExecIsThisProcess()) {
    g_page->processes[g_proc].state.store(vt::kProcAlive);
    g_page->processes[g_proc].exec_pending.store(0);
  }
  errno = err;
  return rc;
}

/// The arguments of an execl-style call after `arg`, up to the NULL (and, for execle, the
/// environment after it). Returns a malloc'ed argv (nullptr: ENOMEM).
char** CollectArgs(const char* arg, va_list ap, char* const** envp) {
  va_list count;
  va_copy(count, ap);
  std::size_t n = 1;
  if (arg != nullptr) {
    while (va_arg(count, const char*) != nullptr) ++n;
  }
  va_end(count);
  auto** argv = static_cast<char**>(::malloc((n + 1) * sizeof(char*)));
  if (argv == nullptr) return nullptr;
  argv[0] = const_cast<char*>(arg);
  for (std::size_t i = 1; i < n; ++i) argv[i] = va_arg(ap, char*);
  argv[n] = nullptr;
  if (arg != nullptr) (void)va_arg(ap, char*);  // the terminating NULL
  if (envp != nullptr) *envp = va_arg(ap, char* const*);
  return argv;
}

}  // namespace

VTIME_EXPORT int execve(const char* path, char* const argv[], char* const envp[]) {
  BeforeExec();
  return AfterFailedExec(real_execve()(path, argv, envp));
}

VTIME_EXPORT int execv(const char* path, char* const argv[]) {
  BeforeExec();
  return AfterFailedExec(real_execv()(path, argv));
}

VTIME_EXPORT int execvp(const char* file, char* const argv[]) {
  BeforeExec();
  return AfterFailedExec(real_execvp()(file, argv));
}

VTIME_EXPORT int execvpe(const char* file, char* const argv[], char* const envp[]) {
  BeforeExec();
  return AfterFailedExec(real_execvpe()(file, argv, envp));
}

VTIME_EXPORT int fexecve(int fd, char* const argv[], char* const envp[]) {
  BeforeExec();
  return AfterFailedExec(real_fexecve()(fd, argv, envp));
}

namespace {

/// Runs `exec(argv)` for an argv CollectArgs made (nullptr: ENOMEM), then frees it (an exec
/// that returns failed).
template <typename Exec>
int ExecCollected(char** argv, Exec exec) {
  if (argv == nullptr) return Fail(ENOMEM);
  const int rc = exec(argv);
  ::free(argv);
  return rc;
}

}  // namespace

VTIME_EXPORT int execl(const char* path, const char* arg, ...) {
  va_list ap;
  va_start(ap, arg);
  char** argv = CollectArgs(arg, ap, nullptr);
  va_end(ap);
  return ExecCollected(argv, [path](char** a) { return execv(path, a); });
}

VTIME_EXPORT int execlp(const char* file, const char* arg, ...) {
  va_list ap;
  va_start(ap, arg);
  char** argv = CollectArgs(arg, ap, nullptr);
  va_end(ap);
  return ExecCollected(argv, [file](char** a) { return execvp(file, a); });
}

VTIME_EXPORT int execle(const char* path, const char* arg, ...) {
  va_list ap;
  va_start(ap, arg);
  char* const* envp = nullptr;
  char** argv = CollectArgs(arg, ap, &envp);
  va_end(ap);
  return ExecCollected(argv, [path, envp](char** a) { return execve(path, a, envp); });
}

// ---- semaphores, timed mutexes ----

VTIME_EXPORT int sem_timedwait(sem_t* sem, const timespec* abstime) {
  if (g_page == nullptr) return real_sem_timedwait()(sem, abstime);
  if (abstime->tv_nsec < 0 || abstime->tv_nsec >= 1000000000) {
    errno = EINVAL;
    return -1;
  }
  return SemWaitUntil(sem, DeadlineFromAbs(CLOCK_REALTIME, *abstime));
}

VTIME_EXPORT int sem_clockwait(sem_t* sem, clockid_t clk, const timespec* abstime) {
  if (g_page == nullptr || !IsVirtualClock(clk)) return real_sem_clockwait()(sem, clk, abstime);
  if (abstime->tv_nsec < 0 || abstime->tv_nsec >= 1000000000) {
    errno = EINVAL;
    return -1;
  }
  return SemWaitUntil(sem, DeadlineFromAbs(clk, *abstime));
}

VTIME_EXPORT int pthread_mutex_timedlock(pthread_mutex_t* m, const timespec* abstime) {
  if (g_page == nullptr) return real_pthread_mutex_timedlock()(m, abstime);
  if (abstime->tv_nsec < 0 || abstime->tv_nsec >= 1000000000) return EINVAL;
  return MutexLockUntil(m, DeadlineFromAbs(CLOCK_REALTIME, *abstime));
}

VTIME_EXPORT int pthread_mutex_clocklock(pthread_mutex_t* m, clockid_t clk,
                                         const timespec* abstime) {
  if (g_page == nullptr || !IsVirtualClock(clk)) {
    return real_pthread_mutex_clocklock()(m, clk, abstime);
  }
  if (abstime->tv_nsec < 0 || abstime->tv_nsec >= 1000000000) return EINVAL;
  return MutexLockUntil(m, DeadlineFromAbs(clk, *abstime));
}

// ---- raw system calls through libc's syscall() (Rust's std parks threads this way) ----

namespace {

long FutexWaitUntil(std::uint32_t* addr, int op, std::uint32_t val, std::int64_t deadline,
                    std::uint32_t bitset) {
  if (__atomic_load_n(addr, __ATOMIC_SEQ_CST) != val) {
    errno = EAGAIN;
    return -1;
  }
  if (DeadlinePassed(deadline)) {
    errno = ETIMEDOUT;
    return -1;
  }
  EnsureAgent();
  vt::ThreadSlot& s = Self();
  WaitTarget target;
  target.cond = reinterpret_cast<std::uintptr_t>(addr);
  target.mutex = static_cast<std::uint64_t>(op & FUTEX_PRIVATE_FLAG);
  BeginWait(s, vt::kFutexWait, deadline, target);
  const long rc = real_syscall()(SYS_futex, addr, FUTEX_WAIT_BITSET | (op & FUTEX_PRIVATE_FLAG),
                                 val, nullptr, nullptr, bitset);
  const int err = errno;
  EndWait(s);
  if (rc == 0 && Now() >= deadline) {
    errno = ETIMEDOUT;
    return -1;
  }
  errno = err;
  return rc;
}

}  // namespace

VTIME_EXPORT long syscall(long number, ...) {
  va_list ap;
  va_start(ap, number);
  const long a1 = va_arg(ap, long), a2 = va_arg(ap, long), a3 = va_arg(ap, long);
  const long a4 = va_arg(ap, long), a5 = va_arg(ap, long), a6 = va_arg(ap, long);
  va_end(ap);
  if (g_page != nullptr) {
    switch (number) {
      case SYS_clock_gettime:
        return clock_gettime(static_cast<clockid_t>(a1), reinterpret_cast<timespec*>(a2));
      case SYS_gettimeofday:
        return gettimeofday(reinterpret_cast<timeval*>(a1), reinterpret_cast<void*>(a2));
      case SYS_time:
        return time(reinterpret_cast<time_t*>(a1));
      case SYS_nanosleep:
        return nanosleep(reinterpret_cast<const timespec*>(a1), reinterpret_cast<timespec*>(a2));
      case SYS_clock_nanosleep: {
        const int rc = clock_nanosleep(static_cast<clockid_t>(a1), static_cast<int>(a2),
                                       reinterpret_cast<const timespec*>(a3),
                                       reinterpret_cast<timespec*>(a4));
        if (rc == 0) return 0;
        errno = rc;
        return -1;
      }
      case SYS_clock_settime:
        if (a2 == 0) return Fail(EFAULT);
        return clock_settime(static_cast<clockid_t>(a1), reinterpret_cast<const timespec*>(a2));
      case SYS_settimeofday:
        return settimeofday(reinterpret_cast<const timeval*>(a1),
                            reinterpret_cast<const struct timezone*>(a2));
      case SYS_adjtimex:
        return adjtimex(reinterpret_cast<timex*>(a1));
      case SYS_clock_adjtime:
        return clock_adjtime(static_cast<clockid_t>(a1), reinterpret_cast<timex*>(a2));
      case SYS_close:
        return close(static_cast<int>(a1));
      case SYS_close_range:
        return close_range(static_cast<unsigned>(a1), static_cast<unsigned>(a2),
                           static_cast<int>(a3));
      case SYS_dup2:
        return dup2(static_cast<int>(a1), static_cast<int>(a2));
      case SYS_dup3:
        return dup3(static_cast<int>(a1), static_cast<int>(a2), static_cast<int>(a3));
      case SYS_execve:
        return execve(reinterpret_cast<const char*>(a1), reinterpret_cast<char* const*>(a2),
                      reinterpret_cast<char* const*>(a3));
      case SYS_futex: {
        const int op = static_cast<int>(a2);
        const int cmd = op & FUTEX_CMD_MASK;
        const auto* ts = reinterpret_cast<const timespec*>(a4);
        if ((cmd == FUTEX_WAIT || cmd == FUTEX_WAIT_BITSET) && ts != nullptr) {
          // FUTEX_WAIT: relative; FUTEX_WAIT_BITSET: absolute on MONOTONIC or REALTIME.
          const clockid_t clk = (op & FUTEX_CLOCK_REALTIME) ? CLOCK_REALTIME : CLOCK_MONOTONIC;
          const std::int64_t deadline = cmd == FUTEX_WAIT
                                            ? DeadlineIn(vt::ToNs(ts->tv_sec, ts->tv_nsec))
                                            : DeadlineFromAbs(clk, *ts);
          return FutexWaitUntil(reinterpret_cast<std::uint32_t*>(a1), op,
                                static_cast<std::uint32_t>(a3), deadline,
                                cmd == FUTEX_WAIT ? FUTEX_BITSET_MATCH_ANY
                                                  : static_cast<std::uint32_t>(a6));
        }
        break;
      }
      case SYS_kill:
      case SYS_tkill:
      case SYS_tgkill:
      case SYS_rt_sigqueueinfo:
      case SYS_rt_tgsigqueueinfo: {
        const long rc = real_syscall()(number, a1, a2, a3, a4, a5, a6);
        if (rc == 0) NoteFdWake();
        return rc;
      }
      default:
        break;
    }
  }
  return real_syscall()(number, a1, a2, a3, a4, a5, a6);
}

// ---- the bus library's calls on its sockets (Page::bus_calls) ----

VTIME_EXPORT void wheelhil_vtime_note_bus_call() {
  if (g_page != nullptr) g_page->bus_calls.fetch_add(1);
}

/// A send that leaves the window open (Page::sends): the frame foreseen next, at its instant;
/// or, with no foreseen one due now, a standard data frame no device reads that would find
/// the forecast bus idle, losing every arbitration on the way, and leave it before anything
/// else starts, queued behind the firmware's earlier such frames (at most their stuffed length).
bool SendRunsThrough(const void* frame, std::size_t frame_len) {
  vt::SendRules& r = g_page->sends;
  if (frame == nullptr || frame_len != sizeof(can_frame) || r.enabled.load() == 0 ||
      vt::RunaheadStateOf(g_page->runahead.load()) != vt::kGranted) {
    return false;
  }
  can_frame f;
  std::memcpy(&f, frame, sizeof(f));
  const std::int64_t now = Now();
  while (r.lock.exchange(1, std::memory_order_acquire) != 0) ::sched_yield();
  bool through = false;
  const std::uint32_t taken = r.foreseen_taken.load();
  const vt::ForeseenSend* next = taken < r.foreseen_count ? &r.foreseen[taken] : nullptr;
  if (next != nullptr && next->instant_ns <= now) {
    // Only the frame foreseen here, as foreseen, and before any other.
    through = next->instant_ns == now && next->can_id == f.can_id && next->len == f.len &&
              f.len <= CAN_MAX_DLEN && std::memcmp(next->data, f.data, f.len) == 0;
    if (through) r.foreseen_taken.store(taken + 1);
  } else if ((f.can_id & (CAN_EFF_FLAG | CAN_RTR_FLAG | CAN_ERR_FLAG)) == 0 &&
             f.len <= CAN_MAX_DLEN && r.bit_ns > 0 &&
             (r.unread_ids[f.can_id / 64] >> (f.can_id % 64) & 1u) != 0) {
    const std::int64_t step = g_page->runahead_step_ns.load();
    const std::int64_t since = now - r.gap_first_ns;
    if (step > 0 && since >= 0 && since % step == 0 && since / step < r.gap_count) {
      const vt::SendGap& g = r.gaps[since / step];
      const std::int64_t start = std::max(g.idle_ns, r.free_ns.load());
      const std::int64_t end = start + vt::StandardFrameBitsAtMost(f.len) * r.bit_ns;
      through = vt::StandardDataKey(f.can_id) > g.max_key && end <= g.busy_ns;
      if (through) r.free_ns.store(end);
    }
  }
  if (through) {
    const std::uint32_t n = r.sent_count.load();
    through = n < vt::kMaxSendsThrough;
    if (through) {
      r.sent_at[n] = now;
      r.sent_count.store(n + 1);
      r.through.fetch_add(1);
    }
  }
  r.lock.store(0, std::memory_order_release);
  return through;
}

/// The bus library sent a frame (`frame`, `frame_len` bytes as written; nullptr: one it could
/// not show). Unless it runs through a window (SendRunsThrough), a clock granted to the
/// firmware goes back to the host at its next turn (Page::bus_sends), which takes the frame at
/// the instant it was sent. Called before the sending thread can wait again.
VTIME_EXPORT void wheelhil_vtime_note_frame_sent(const void* frame, std::size_t frame_len) {
  if (g_page != nullptr && !SendRunsThrough(frame, frame_len)) g_page->bus_sends.fetch_add(1);
}

// ---- kernel CAN sockets: the frames the firmware sends, and their receive timestamps ----

void CountKernelCanSends(int fd, long frames) {
  if (g_page != nullptr && frames > 0 && MarkedKernelCan(fd)) {
    g_page->kernel_can_sends.fetch_add(static_cast<std::uint64_t>(frames));
  }
}

/// The kernel stamps a received frame with the host's CLOCK_REALTIME (SO_TIMESTAMP,
/// SO_TIMESTAMPNS, SO_TIMESTAMPING's software stamp): each becomes the virtual CLOCK_REALTIME
/// now. The run hands a frame over at the instant it is due and the firmware reads it before the
/// clock moves on (a firmware that leaves it in its socket longer sees it stamped later).
void VirtualReceiveStamps(int fd, msghdr* msg) {
  if (msg == nullptr || msg->msg_control == nullptr || msg->msg_controllen == 0 ||
      !MarkedKernelCan(fd)) {
    return;
  }
  const std::int64_t now = Now() + RealtimeOffset();
  for (cmsghdr* c = CMSG_FIRSTHDR(msg); c != nullptr; c = CMSG_NXTHDR(msg, c)) {
    if (c->cmsg_level != SOL_SOCKET) continue;
    const int type = c->cmsg_type;
    const bool tv = type == SO_TIMESTAMP_OLD || type == SO_TIMESTAMP_NEW;
    const bool ts = type == SO_TIMESTAMPNS_OLD || type == SO_TIMESTAMPNS_NEW ||
                    type == SO_TIMESTAMPING_OLD || type == SO_TIMESTAMPING_NEW;
    if (!tv && !ts) continue;
    const std::size_t room = c->cmsg_len - CMSG_LEN(0);
    if (tv && room >= sizeof(timeval)) {
      const timeval v{now / 1000000000, (now % 1000000000) / 1000};
      std::memcpy(CMSG_DATA(c), &v, sizeof(v));
    } else if (ts && room >= sizeof(timespec)) {
      const timespec v{now / 1000000000, now % 1000000000};
      std::memcpy(CMSG_DATA(c), &v, sizeof(v));  // SO_TIMESTAMPING: [0] is the software stamp
    }
  }
}

VTIME_EXPORT int socket(int domain, int type, int protocol) {
  const int fd = real_socket()(domain, type, protocol);
  // The bus library's CAN sockets are unix sockets underneath: only the kernel's are marked.
  if (fd >= 0) MarkKernelCan(fd, domain == PF_CAN && KernelCanSocket(fd));
  return fd;
}

VTIME_EXPORT ssize_t write(int fd, const void* buf, size_t n) {
  const ssize_t r = real_write()(fd, buf, n);
  if (r > 0) CountKernelCanSends(fd, 1);
  return r;
}

VTIME_EXPORT ssize_t send(int fd, const void* buf, size_t n, int flags) {
  const ssize_t r = real_send()(fd, buf, n, flags);
  if (r > 0) CountKernelCanSends(fd, 1);
  return r;
}

VTIME_EXPORT ssize_t sendto(int fd, const void* buf, size_t n, int flags, const sockaddr* to,
                            socklen_t to_len) {
  const ssize_t r = real_sendto()(fd, buf, n, flags, to, to_len);
  if (r > 0) CountKernelCanSends(fd, 1);
  return r;
}

VTIME_EXPORT ssize_t sendmsg(int fd, const msghdr* msg, int flags) {
  const ssize_t r = real_sendmsg()(fd, msg, flags);
  if (r > 0) CountKernelCanSends(fd, 1);
  return r;
}

VTIME_EXPORT int sendmmsg(int fd, mmsghdr* msgs, unsigned int vlen, int flags) {
  const int r = real_sendmmsg()(fd, msgs, vlen, flags);
  CountKernelCanSends(fd, r);
  return r;
}

VTIME_EXPORT ssize_t recvmsg(int fd, msghdr* msg, int flags) {
  const ssize_t n = real_recvmsg()(fd, msg, flags);
  if (n >= 0 && g_page != nullptr) VirtualReceiveStamps(fd, msg);
  return n;
}

VTIME_EXPORT int recvmmsg(int fd, mmsghdr* msgs, unsigned int vlen, int flags, timespec* timeout) {
  const int n = real_recvmmsg()(fd, msgs, vlen, flags, timeout);
  if (g_page != nullptr) {
    for (int i = 0; i < n; ++i) VirtualReceiveStamps(fd, &msgs[i].msg_hdr);
  }
  return n;
}

// ---- signals between the firmware's threads: they may end a wait the host takes for vouched ----

VTIME_EXPORT int kill(pid_t pid, int sig) {
  const int rc = real_kill()(pid, sig);
  if (g_page != nullptr && rc == 0 && sig != 0) NoteFdWake();
  return rc;
}

VTIME_EXPORT int pthread_kill(pthread_t thread, int sig) {
  const int rc = real_pthread_kill()(thread, sig);
  if (g_page != nullptr && rc == 0 && sig != 0) NoteFdWake();
  return rc;
}

VTIME_EXPORT int sigqueue(pid_t pid, int sig, const union sigval value) {
  const int rc = real_sigqueue()(pid, sig, value);
  if (g_page != nullptr && rc == 0 && sig != 0) NoteFdWake();
  return rc;
}

// ---- alarm, setitimer(ITIMER_REAL), POSIX timers ----

VTIME_EXPORT int getitimer(int which, itimerval* cur) {
  if (g_page == nullptr || which != ITIMER_REAL) return real_getitimer()(which, cur);
  const int i = AlarmTimer();
  if (i < 0) return real_getitimer()(which, cur);
  const itimerspec v = TimerValue(g_page->timers[i]);
  cur->it_value = timeval{v.it_value.tv_sec, v.it_value.tv_nsec / 1000};
  cur->it_interval = timeval{v.it_interval.tv_sec, v.it_interval.tv_nsec / 1000};
  return 0;
}

VTIME_EXPORT int setitimer(int which, const itimerval* nv, itimerval* old) {
  if (g_page == nullptr || which != ITIMER_REAL) return real_setitimer()(which, nv, old);
  const int i = AlarmTimer();
  if (i < 0) {
    errno = EAGAIN;
    return -1;
  }
  if (nv->it_value.tv_usec < 0 || nv->it_value.tv_usec >= 1000000 || nv->it_interval.tv_usec < 0 ||
      nv->it_interval.tv_usec >= 1000000) {
    errno = EINVAL;
    return -1;
  }
  if (old != nullptr) getitimer(which, old);
  itimerspec v{};
  v.it_value = timespec{nv->it_value.tv_sec, nv->it_value.tv_usec * 1000};
  v.it_interval = timespec{nv->it_interval.tv_sec, nv->it_interval.tv_usec * 1000};
  ArmTimer(i, v, false);
  return 0;
}

VTIME_EXPORT unsigned alarm(unsigned seconds) {
  if (g_page == nullptr) return real_alarm()(seconds);
  itimerval nv{}, old{};
  nv.it_value.tv_sec = static_cast<time_t>(seconds);
  if (setitimer(ITIMER_REAL, &nv, &old) != 0) return 0;
  // As glibc's alarm: the seconds left, rounded to the nearest, at least 1 when some are left.
  unsigned left = static_cast<unsigned>(old.it_value.tv_sec);
  if (old.it_value.tv_usec >= 500000 || (left == 0 && old.it_value.tv_usec > 0)) ++left;
  return left;
}

VTIME_EXPORT int timer_create(clockid_t c, sigevent* sev, timer_t* id) {
  if (g_page == nullptr || !IsVirtualClock(c)) return real_timer_create()(c, sev, id);
  const int notify = sev == nullptr ? SIGEV_SIGNAL : sev->sigev_notify;
  vt::TimerNotify kind = vt::kNotifySignal;
  if (notify == SIGEV_NONE) {
    kind = vt::kNotifyNone;
  } else if (notify == SIGEV_THREAD) {
    kind = vt::kNotifyThread;
  } else if (notify != SIGEV_SIGNAL && notify != SIGEV_THREAD_ID) {
    errno = EINVAL;
    return -1;
  }
  const int i = ClaimTimer(c, kind, -1);
  if (i < 0) {
    errno = EAGAIN;
    return -1;
  }
  vt::TimerSlot& t = g_page->timers[i];
  if (sev == nullptr) {
    t.signo = SIGALRM;
    t.sigval = static_cast<std::uint64_t>(i);  // as the kernel: sival_int = the timer id
  } else {
    t.signo = sev->sigev_signo;
    t.sigval = reinterpret_cast<std::uintptr_t>(sev->sigev_value.sival_ptr);
    if (notify == SIGEV_THREAD) {
      t.function = reinterpret_cast<std::uintptr_t>(sev->sigev_notify_function);
    }
    if (notify == SIGEV_THREAD_ID) t.target_tid = sev->_sigev_un._tid;
  }
  if (kind == vt::kNotifyThread) EnsureAgent();
  *id = TimerHandle(i);
  return 0;
}

VTIME_EXPORT int timer_settime(timer_t id, int flags, const itimerspec* nv, itimerspec* old) {
  const int i = g_page == nullptr ? -1 : TimerSlotOf(id);
  if (i < 0) return real_timer_settime()(id, flags, nv, old);
  if (!ValidItimerspec(*nv)) {
    errno = EINVAL;
    return -1;
  }
  if (old != nullptr) *old = TimerValue(g_page->timers[i]);
  ArmTimer(i, *nv, (flags & TIMER_ABSTIME) != 0);
  return 0;
}

VTIME_EXPORT int timer_gettime(timer_t id, itimerspec* cur) {
  const int i = g_page == nullptr ? -1 : TimerSlotOf(id);
  if (i < 0) return real_timer_gettime()(id, cur);
  *cur = TimerValue(g_page->timers[i]);
  return 0;
}

VTIME_EXPORT int timer_getoverrun(timer_t id) {
  const int i = g_page == nullptr ? -1 : TimerSlotOf(id);
  if (i < 0) return real_timer_getoverrun()(id);
  return static_cast<int>(g_page->timers[i].overrun.load());
}

VTIME_EXPORT int timer_delete(timer_t id) {
  const int i = g_page == nullptr ? -1 : TimerSlotOf(id);
  if (i < 0) return real_timer_delete()(id);
  g_page->timers[i].state.store(vt::kTimerFree);
  g_page->timers[i].pid.store(0);
  return 0;
}
