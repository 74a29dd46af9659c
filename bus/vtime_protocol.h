#pragma once
/// The shared clock page of virtual time: how the emulator (the clock's host,
/// emulator/firmware/virtual_clock.h) and the firmware's processes (the interposition library
/// bus/vtime_interpose.cc, libwheelhil_vtime.so) share one clock. See docs/virtual-time.md.
///
/// The host creates the page as a file in the run's private runtime directory and names it in
/// the firmware's environment (kPageEnv). Every process of the firmware maps it shared. The
/// host alone moves `now_ns`; the library reads it for every clock call and turns every timed
/// wait into a wait without timeout plus a deadline published in the thread's slot, so the
/// host knows the earliest instant the firmware needs and when all of it is blocked.
///
/// Wake-ups: a thread in a plain sleep (kSleep) or the process's agent (kAgent) waits on its
/// slot's `wake` futex word, which only the host bumps. A wait on file descriptors (kFdWait)
/// waits on the thread's eventfd too, and a virtual timerfd is an eventfd: the host writes
/// them itself when it could take a copy of the fd (pidfd_getfd), else it marks the wait or
/// timer `fired` and wakes the process's agent thread, which writes them. A condition variable
/// (kCondWait) is always broadcast by the agent.
///
/// Slot states: whoever ends a wait sets the slot kRunning before the waiter can run: the
/// waiter itself (its wait returned) or the host (a deadline it reached), by compare-and-swap
/// from kWaiting; every wait entry and exit bumps `transitions` (a futex word the host may wait
/// on). Plain C layout, no C++ runtime: the library includes it.

#include <atomic>
#include <cstdint>

namespace wheelhil::bus::vtime {

inline constexpr std::uint32_t kMagic = 0x31545657u;  // "WVT1"
inline constexpr char kPageEnv[] = "WHEELHIL_VTIME";
inline constexpr char kPageName[] = "vtime.page";
inline constexpr int kMaxProcesses = 64;
inline constexpr int kMaxThreads = 256;
inline constexpr int kMaxTimers = 128;
inline constexpr std::int64_t kNoDeadline = INT64_MAX;
/// The pid of a process slot the host claimed for the firmware before it was started.
inline constexpr std::int32_t kFirstProcessPid = -1;

enum SlotState : std::uint32_t {
  kFree = 0,
  kRunning = 1,  ///< Running, or blocked where the library does not see it.
  kWaiting = 2,  ///< In a wait of the library (kind, deadline below).
};

enum WaitKind : std::uint32_t {
  kNone = 0,
  kSleep = 1,     ///< Futex on `wake`: only the host ends it.
  kFdWait = 2,    ///< poll/select/epoll on the thread's fds + its eventfd.
  kCondWait = 3,  ///< A condition variable (the agent broadcasts it at the deadline).
  kAgent = 4,     ///< The process's agent, idle: only the host ends it.
  kSignalWait = 5,  ///< sem_wait, or an fd wait without a wake eventfd (none could be made):
                    ///< the host ends it with kWakeSignal to the thread (EINTR).
  kFutexWait = 6, ///< A raw futex wait (syscall()): the agent wakes the futex word.
};

/// Calls without blocking a thread makes for free before the spin cost applies.
inline constexpr std::uint32_t kSpinCallsFree = 64;

/// The signal that ends a semaphore wait at its deadline (SIGRTMAX; its handler does nothing).
inline constexpr int kWakeSignal = 64;

/// What a thread last called that did not block (for the report of a thread that never does).
enum LastCall : std::uint32_t {
  kCallNone = 0,
  kCallClock = 1,     ///< clock_gettime / gettimeofday / time
  kCallPollZero = 2,  ///< poll/select/epoll with a zero timeout
  kCallPastDeadline = 3,
};

/// Runahead (Page::runahead): who moves the clock.
enum RunaheadState : std::uint32_t {
  kHostClock = 0,     ///< The host (the default).
  kGranted = 1,       ///< The firmware's library may move it, up to Page::runahead_until_ns.
  kLocalAdvance = 2,  ///< A thread of the firmware is moving it (held by that thread).
};

/// Page::runahead is a RunaheadState in its low two bits and, above them, a count of its
/// changes: the host takes the clock back only from the very word it read before it looked
/// at the threads, so a thread that held the clock and let it go meanwhile (a move the look
/// may have half seen) makes the take-back fail.
inline constexpr std::uint32_t RunaheadStateOf(std::uint32_t word) { return word & 3u; }
inline constexpr std::uint32_t NextRunaheadWord(std::uint32_t word, RunaheadState next) {
  return (((word >> 2) + 1) << 2) | next;
}

enum ProcessState : std::uint32_t {
  kProcFree = 0,
  kProcStarting = 1,  ///< Forked or spawned; its library has not registered it yet.
  kProcAlive = 2,
  /// Host-only: it exec'd a program without the library (LD_PRELOAD cleared, a static binary):
  /// on the host's clock; its threads count as blocked while asleep in the kernel. A later
  /// exec of a program with the library registers it again.
  kProcOutside = 3,
};

struct ProcessSlot {
  std::atomic<std::uint32_t> state{kProcFree};
  std::atomic<std::int32_t> pid{0};  ///< 0 while a fork is in progress.
  std::atomic<std::int32_t> agent{-1};  ///< Thread slot of its agent (-1: none yet).
  /// 1 from an exec* call of a registered process until the new program's library registers
  /// it (kProcStarting meanwhile): the host may then find it is a program without the library.
  std::atomic<std::uint32_t> exec_pending{0};
};

/// Wake channels (ThreadSlot::wait_channels, Page::channel_wakes): what a write that may end a
/// vouched fd wait was for, as a bit. Channel 0 is anything (a signal, an agent's write, the
/// broker's connection events); the others are shared by timers, and by bus sockets, whose
/// numbers fall on the same bit (a write for one then also counts for the other).
inline constexpr int kWakeChannels = 32;
inline constexpr std::uint32_t kAnyChannel = 1u;
inline std::uint32_t TimerChannel(int timer_slot) { return 1u << (1 + timer_slot % 15); }
inline std::uint32_t BusSocketChannel(std::uint32_t client_id) {
  return 1u << (16 + client_id % 16);
}

struct alignas(64) ThreadSlot {
  std::atomic<std::uint32_t> state{kFree};
  std::atomic<std::uint32_t> wake{0};   ///< Futex word (kSleep, kAgent).
  std::atomic<std::uint16_t> kind{kNone};
  std::atomic<std::uint16_t> fired{0};  ///< Host -> agent: the deadline of this wait passed.
  /// kFdWait with `vouched`: the wake channels of its fds (kAnyChannel always counts).
  std::atomic<std::uint32_t> wait_channels{0};
  std::atomic<std::int64_t> deadline_ns{kNoDeadline};  ///< Virtual CLOCK_MONOTONIC.
  std::atomic<std::int32_t> pid{0};
  std::atomic<std::int32_t> tid{0};     ///< 0: created, not started yet.
  std::atomic<std::uint32_t> calls{0};  ///< Non-blocking calls since its last wait.
  /// kFdWait with `vouched`: Page::fd_wakes when the thread last found none of its fds ready,
  /// right before it published the wait.
  std::atomic<std::uint32_t> entry_wakes{0};
  std::atomic<std::uint16_t> last_call{kCallNone};
  /// 1 while the slot holds a wait that a signal handler's own wait interrupted and handed back:
  /// the thread may be running on its way out of it, so the host asks the kernel (as for fd
  /// waits) even for a kSleep.
  std::atomic<std::uint8_t> resumed{0};
  /// kFdWait: 1 when every fd of the wait is one only the host or an agent makes ready (a bus
  /// socket of the broker, a virtual timerfd, an epoll set of those, the thread's wake
  /// eventfd), each waited on for input, and none was ready at `entry_wakes`. While no channel
  /// of `wait_channels` was written after that (Page::channel_wakes), nothing can have woken
  /// the thread: the host needs no look at the kernel.
  std::atomic<std::uint8_t> vouched{0};
  // Process-local, written by the thread before it waits, read by its process's agent.
  std::int32_t wake_fd = -1;  ///< kFdWait: the thread's eventfd.
  std::uint64_t cond = 0;     ///< kCondWait: pthread_cond_t*
  std::uint64_t mutex = 0;    ///< kCondWait: pthread_mutex_t*
};

enum TimerState : std::uint32_t { kTimerFree = 0, kTimerDisarmed = 1, kTimerArmed = 2 };

/// How a timer tells its expiry.
enum TimerNotify : std::uint32_t {
  kNotifyEventFd = 0,  ///< A virtual timerfd: the expirations are written to `fd`.
  kNotifySignal = 1,   ///< A signal (`signo`, SI_TIMER with `sigval`) to the process, or to
                       ///< `target_tid` when it is not 0 (SIGEV_THREAD_ID).
  kNotifyAlarm = 2,    ///< alarm / setitimer(ITIMER_REAL): SIGALRM to the process.
  kNotifyThread = 3,   ///< SIGEV_THREAD: the agent runs `function(sigval)` in a new thread.
  kNotifyNone = 4,     ///< SIGEV_NONE: only timer_gettime sees it.
};

struct alignas(64) TimerSlot {
  std::atomic<std::uint32_t> state{kTimerFree};
  std::atomic<std::uint32_t> fired{0};  ///< Host -> agent: next_ns passed.
  std::atomic<std::int32_t> pid{0};
  std::int32_t fd = -1;  ///< The eventfd the program sees as its timerfd (process-local).
  /// Bumped by every timerfd_create on this slot: a host that holds a copy of `fd` (pidfd_getfd)
  /// knows when it is another timer's.
  std::atomic<std::uint32_t> generation{0};
  std::atomic<std::uint32_t> notify{kNotifyEventFd};
  std::int32_t signo = 0;
  std::int32_t target_tid = 0;
  std::uint64_t sigval = 0;    ///< union sigval as its pointer member
  std::uint64_t function = 0;  ///< kNotifyThread: void (*)(union sigval)
  std::atomic<std::uint32_t> overrun{0};  ///< timer_getoverrun: expirations - 1 of the last
  std::atomic<std::int64_t> next_ns{kNoDeadline};
  std::atomic<std::int64_t> interval_ns{0};
};

/// Runahead through the firmware's own sends (Page::sends, docs/virtual-time.md "Sends in a
/// window"): a send the host foresaw, or one that cannot change what the firmware is handed
/// next, does not end the window.
inline constexpr int kMaxForeseenSends = 256;
inline constexpr int kMaxSendGaps = 1024;
inline constexpr int kStandardIds = 2048;
inline constexpr int kMaxSendsThrough = 4096;  ///< In one window.

/// A frame the host expects the firmware to send at an instant (it sent it so before): the
/// forecast holds it, so the firmware must send exactly it, there, before any other frame.
struct ForeseenSend {
  std::int64_t instant_ns = 0;  ///< Virtual CLOCK_MONOTONIC.
  std::uint32_t can_id = 0;     ///< struct can_frame's, flags included.
  std::uint8_t len = 0;
  std::uint8_t pad[3] = {};
  std::uint8_t data[8] = {};
};

/// The forecast bus seen from one instant of the window, for a frame the firmware sends there
/// that nobody foresaw: it first contends with frames whose highest arbitration key is
/// `max_key` (0: none), which it must lose to, then finds the bus idle from `idle_ns` with
/// nothing starting before `busy_ns`. It changes nothing if it lies wholly in there.
struct SendGap {
  std::int64_t idle_ns = 0;
  std::int64_t busy_ns = 0;
  std::uint32_t max_key = 0;
  std::uint32_t pad = 0;
};

/// The arbitration key of a classic standard data frame (emulator::ArbitrationKey's layout:
/// base id, RTR, IDE, extension, lower wins).
inline constexpr std::uint32_t StandardDataKey(std::uint32_t id) { return (id & 0x7FFu) << 21; }
/// Its length on the wire at most, SOF to the end of the interframe space, stuff bits included
/// (can-utils' CFL_WORSTCASE: 55 + 10 n bits for n data bytes).
inline constexpr std::int64_t StandardFrameBitsAtMost(std::uint32_t len) { return 55 + 10 * len; }

/// Written by the host while the clock is its own, before a grant; read by the firmware's
/// library during it. The library's own fields (taken, free_ns, through) change under `lock`.
struct SendRules {
  /// 0: every send of the firmware's ends the window (the host wrote no rules).
  std::atomic<std::uint32_t> enabled{0};
  std::atomic<std::uint32_t> lock{0};  ///< A spin lock of the firmware's sending threads.
  std::uint32_t foreseen_count = 0;
  std::atomic<std::uint32_t> foreseen_taken{0};  ///< Library: foreseen sends made so far.
  /// Unforeseen sends: the grid instant of gaps[0] (gaps follow every runahead_step_ns), the
  /// bus's bit time (0: none runs through).
  std::uint32_t gap_count = 0;
  std::int64_t gap_first_ns = 0;
  std::int64_t bit_ns = 0;
  /// Library: when its unforeseen sends leave the bus at the latest (their own queue).
  std::atomic<std::int64_t> free_ns{0};
  std::atomic<std::uint64_t> through{0};  ///< Library: sends that did not end a window.
  /// Library: the instants of this window's sends that did not end it, in the order they
  /// entered the socket's ring (the host takes them so, each at its instant).
  std::atomic<std::uint32_t> sent_count{0};
  std::int64_t sent_at[kMaxSendsThrough] = {};
  /// Bit `id`: no device reads standard data frames with this id (they change nothing).
  std::uint64_t unread_ids[kStandardIds / 64] = {};
  ForeseenSend foreseen[kMaxForeseenSends];
  SendGap gaps[kMaxSendGaps];
};

struct Page {
  std::uint32_t magic = kMagic;
  std::uint32_t size = 0;  ///< sizeof(Page), checked by the library.
  /// Virtual CLOCK_MONOTONIC (and BOOTTIME), ns. Only the host writes it.
  alignas(64) std::atomic<std::int64_t> now_ns{0};
  /// CLOCK_REALTIME = now_ns + realtime_offset_ns. The host sets it at the start; the firmware
  /// moves it when it sets its clock (clock_settime, settimeofday, adjtimex, ...).
  std::atomic<std::int64_t> realtime_offset_ns{0};
  /// Spin cost (0: off): from its kSpinCallsFree-th call that did not block since its last
  /// wait (a clock read, a zero-timeout poll), each such call of a thread first sleeps this
  /// many ns of virtual time, so a firmware that polls in a loop moves time on. Host-written.
  std::atomic<std::int64_t> spin_cost_ns{0};
  /// Bumped on every wait entry and exit (futex word).
  alignas(64) std::atomic<std::uint32_t> transitions{0};
  /// Bumped after every write that can end an fd wait without the slot saying so: the host's
  /// (its broker's writes to the firmware's sockets, the eventfds and signals of WakeDue), an
  /// agent's (eventfds), a firmware thread's signal to another. See ThreadSlot::vouched.
  std::atomic<std::uint32_t> fd_wakes{0};
  /// Per wake channel: the fd_wakes value of the last write on it (NoteWake).
  std::atomic<std::uint32_t> channel_wakes[kWakeChannels] = {};
  /// Bumped by the firmware's bus library before and after every call the broker sees on a
  /// socket rather than in a ring (a connection, a frame sent or received as a message, a
  /// doorbell, a close), and by an exec (before it, and by the new program as it registers):
  /// while it stays what it was when the host began a look at the broker's sockets, that look
  /// saw everything of the firmware's there (a look begun between the bump before a call and
  /// the call's effect sees the bump after it change).
  std::atomic<std::uint32_t> bus_calls{0};
  /// Set by the host before it sleeps on `transitions`; the first transition after takes it
  /// (exchange to 0) and wakes the host.
  std::atomic<std::uint32_t> host_waiting{0};
  /// Runahead (docs/virtual-time.md): while `runahead` is kGranted, the last thread of the
  /// firmware to enter a wait moves the clock itself to the next instant something of it is
  /// due (a sleep's or an fd wait's deadline, a timer), ends those waits and fires those timers
  /// as the host would (WakeDue), as long as that instant is at most `runahead_until_ns`, lies
  /// on the step grid (`runahead_step_ns` > 0: phase + k * step), every thread is in a wait
  /// only the clock can end, the firmware is one process, it sent no frame since the grant
  /// but those `sends` lets through (`bus_sends` still `runahead_sends`) and it made every
  /// foreseen send before that instant (SendRules). Otherwise that thread gives the clock back
  /// (kHostClock) and wakes the host. The host takes it back itself (compare-and-swap from
  /// kGranted) when it finds every thread blocked while granted (a thread asleep outside the
  /// library's waits never calls it; RunaheadStateOf). kLocalAdvance excludes the two; a thread
  /// holds it from before it publishes its wait until it moved the clock or gave it back, so every
  /// thread waiting while the clock is kGranted means nobody will move it.
  alignas(64) std::atomic<std::uint32_t> runahead{kHostClock};
  std::atomic<std::int64_t> runahead_until_ns{0};
  std::atomic<std::int64_t> runahead_step_ns{0};
  std::atomic<std::int64_t> runahead_phase_ns{0};
  std::atomic<std::uint32_t> runahead_sends{0};
  /// Per thread slot, a bit: the slot's wait was ended by a thread of the firmware (runahead),
  /// not by the host; cleared when that thread is out of its wait. The host takes such a thread
  /// for running even while the kernel still has it asleep (it was not scheduled yet).
  std::atomic<std::uint64_t> locally_woken[kMaxThreads / 64] = {};
  /// Bumped by the firmware's bus library on every frame it sends, but those `sends` lets
  /// run through a window.
  std::atomic<std::uint32_t> bus_sends{0};
  /// Frames the firmware wrote to kernel CAN sockets it opened (a kernel interface such as
  /// vcan0): the host waits until it received as many before it takes the firmware for blocked.
  std::atomic<std::uint64_t> kernel_can_sends{0};
  /// Instants the firmware's library moved the clock to itself (for the run's report).
  std::atomic<std::uint64_t> local_advances{0};
  /// One past the highest thread / timer slot ever claimed (bounds the host's scans).
  std::atomic<std::int32_t> threads_used{0};
  std::atomic<std::int32_t> timers_used{0};
  ProcessSlot processes[kMaxProcesses];
  ThreadSlot threads[kMaxThreads];
  TimerSlot timers[kMaxTimers];
  SendRules sends;
};

inline void MarkLocallyWoken(Page& page, int slot, bool woken) {
  const std::uint64_t bit = std::uint64_t{1} << (slot % 64);
  if (woken) {
    page.locally_woken[slot / 64].fetch_or(bit);
  } else if (page.locally_woken[slot / 64].load(std::memory_order_relaxed) & bit) {
    page.locally_woken[slot / 64].fetch_and(~bit);
  }
}
inline bool LocallyWoken(const Page& page, int slot) {
  return (page.locally_woken[slot / 64].load() >> (slot % 64) & 1u) != 0;
}

/// Counts a write that may end a vouched fd wait, on the channels of `channels`: after it, a
/// wait that read fd_wakes before it and waits on one of them is no longer vouched for.
inline void NoteWake(Page& page, std::uint32_t channels) {
  const std::uint32_t v = page.fd_wakes.fetch_add(1) + 1;
  for (int b = 0; b < kWakeChannels; ++b) {
    if ((channels >> b & 1u) == 0) continue;
    std::uint32_t cur = page.channel_wakes[b].load();
    while (static_cast<std::int32_t>(v - cur) > 0 &&
           !page.channel_wakes[b].compare_exchange_weak(cur, v)) {
    }
  }
}

/// Nothing was written on the channels of a vouched wait of `slot` since it was entered.
inline bool VouchHolds(const Page& page, const ThreadSlot& slot) {
  const std::uint32_t entry = slot.entry_wakes.load();
  const std::uint32_t channels = slot.wait_channels.load() | kAnyChannel;
  for (int b = 0; b < kWakeChannels; ++b) {
    if ((channels >> b & 1u) != 0 &&
        static_cast<std::int32_t>(page.channel_wakes[b].load() - entry) > 0) {
      return false;
    }
  }
  return true;
}

/// sec + nsec as ns, saturated: a time beyond the int64 range of ns ("sleep forever" as
/// tv_sec = LONG_MAX) is kNoDeadline, one before it -kNoDeadline. nsec in [0, 1e9).
inline std::int64_t ToNs(std::int64_t sec, std::int64_t nsec) {
  constexpr std::int64_t kMaxSec = kNoDeadline / 1000000000 - 1;
  if (sec > kMaxSec) return kNoDeadline;
  if (sec < -kMaxSec) return -kNoDeadline;
  return sec * 1000000000 + nsec;
}

/// a + b, saturated to [-kNoDeadline, kNoDeadline]; kNoDeadline stays kNoDeadline.
inline std::int64_t AddNs(std::int64_t a, std::int64_t b) {
  if (a == kNoDeadline || b == kNoDeadline) return kNoDeadline;
  std::int64_t sum = 0;
  if (__builtin_add_overflow(a, b, &sum)) return b > 0 ? kNoDeadline : -kNoDeadline;
  if (sum > kNoDeadline - 1) return kNoDeadline;
  return sum < -kNoDeadline ? -kNoDeadline : sum;
}

/// A timer whose next_ns is at or before `now` expires: returns the expirations since then
/// (what a read of the timerfd returns), keeps all but one as its overrun (timer_getoverrun)
/// and moves next_ns on, or disarms a one-shot timer. Whoever fires the timer (host or agent)
/// calls it, once per firing.
inline std::uint64_t ExpireTimer(TimerSlot& t, std::int64_t now) {
  const std::int64_t next = t.next_ns.load();
  const std::int64_t interval = t.interval_ns.load();
  std::uint64_t expirations = 1;
  if (interval > 0 && interval != kNoDeadline) {
    expirations += static_cast<std::uint64_t>((now - next) / interval);
    std::int64_t step = 0;
    const bool overflow =
        __builtin_mul_overflow(static_cast<std::int64_t>(expirations), interval, &step);
    t.next_ns.store(overflow ? kNoDeadline : AddNs(next, step));
  } else {
    t.next_ns.store(kNoDeadline);
    t.state.store(kTimerDisarmed);
  }
  t.overrun.store(static_cast<std::uint32_t>(expirations - 1));
  return expirations;
}

static_assert(std::atomic<std::int64_t>::is_always_lock_free);
static_assert(std::atomic<std::uint16_t>::is_always_lock_free);
static_assert(std::atomic<std::uint8_t>::is_always_lock_free);
static_assert(sizeof(ThreadSlot) == 64, "a thread's slot is one cache line");
static_assert(std::atomic<std::uint32_t>::is_always_lock_free);

}  // namespace wheelhil::bus::vtime
