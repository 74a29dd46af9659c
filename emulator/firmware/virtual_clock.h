#pragma once
/// The host side of the firmware's virtual clock (bus/vtime_protocol.h, docs/virtual-time.md).
/// It creates the clock page in the run's private runtime directory, moves the firmware's time
/// (SetNow), says when the firmware next needs the clock (NextDeadlineNs), ends the waits that
/// reached their deadline (WakeDue: futex wakes, writes to copies of the firmware's eventfds
/// taken with pidfd_getfd, signals, or the agent thread), and tells whether every thread of
/// every firmware process is blocked (Blocked): in a wait of the library that only the clock
/// can end (a sleep, or an fd wait the library vouches for: bus/vtime_protocol.h), or asleep in
/// the kernel (read from /proc/<pid>/task/<tid>/stat) with no transition of any thread while it
/// looked. Times are run ns (0 = run start); the firmware's CLOCK_MONOTONIC is
/// kMonotonicAtStartNs + run ns and its CLOCK_REALTIME kRealtimeAtStartNs + run ns, whatever
/// the host's clocks say, so a run is the same on every machine (until the firmware sets its
/// own CLOCK_REALTIME, which moves only its virtual one: RealtimeNs).
/// Thread-compatible: the run's thread only.

#include <sys/types.h>

#include <bitset>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "bus/can_frame.h"

namespace wheelhil::bus::vtime {
struct Page;
struct TimerSlot;
}

namespace wheelhil::emulator::firmware {

/// What of the firmware's sends may run through a runahead window (bus/vtime_protocol.h,
/// SendRules; docs/virtual-time.md "Sends in a window"). Instants in run ns.
struct RunaheadSendPlan {
  /// The frames the firmware is expected to send, in the order it is to send them; the window's
  /// forecast holds them.
  std::vector<std::pair<std::int64_t, bus::CanFrame>> foreseen;
  /// Unforeseen sends (bit_ns 0: none): the forecast bus from the grid instants
  /// gaps_first_ns + k * step (k < gaps.size()); standard ids no device reads.
  struct Gap {
    std::int64_t idle_ns = 0, busy_ns = 0;
    std::uint32_t max_key = 0;
  };
  std::int64_t gaps_first_ns = 0;
  std::vector<Gap> gaps;
  std::int64_t bit_ns = 0;
  std::bitset<2048> unread_ids;
};

class VirtualClock {
 public:
  /// 10 s of uptime at the run start: programs that take 0 for "never" see no zero.
  static constexpr std::int64_t kMonotonicAtStartNs = 10'000'000'000;
  /// 2026-01-01T00:00:00Z.
  static constexpr std::int64_t kRealtimeAtStartNs = 1'767'225'600'000'000'000;

  /// Creates `<dir>/vtime.page`. Throws std::system_error when it cannot.
  explicit VirtualClock(const std::string& dir);
  ~VirtualClock();
  VirtualClock(const VirtualClock&) = delete;
  VirtualClock& operator=(const VirtualClock&) = delete;

  /// The environment that puts a child on this clock (with the preload of the library).
  std::vector<std::pair<std::string, std::string>> ChildEnvironment(
      const std::string& vtime_library) const;
  /// Before the firmware is started: its first process counts as running until its library
  /// registered it (or it exited).
  void ExpectFirstProcess();
  /// After the start: the pid of that process.
  void SetFirstProcessPid(pid_t pid);

  /// The spin cost (bus/vtime_protocol.h, Page::spin_cost_ns): the virtual time each call that
  /// does not block costs a thread that keeps making them; 0 (the default) for none.
  void SetSpinCost(std::int64_t ns);
  /// Moves the firmware's clock to run time t_ns (never backwards).
  void SetNow(std::int64_t t_ns);
  std::int64_t now_ns() const;
  /// The firmware's CLOCK_REALTIME now, ns since the epoch (it may have set it).
  std::int64_t RealtimeNs() const;
  /// The earliest deadline of a waiting thread or an armed timer, in run ns (at least now);
  /// INT64_MAX when there is none.
  std::int64_t NextDeadlineNs() const;
  /// Ends every wait whose deadline is now or past and fires the timers due. Returns the
  /// number of waits ended and timers fired; none while the firmware holds the clock
  /// (GrantRunahead).
  int WakeDue();
  /// After the host wrote to the firmware's sockets (a broker pass that wrote to a client): an
  /// fd wait on those `channels` (bus/vtime_protocol.h: BusSocketChannel of the clients
  /// written to, kAnyChannel for anything else) may have ended (ThreadSlot::vouched). Counted
  /// with the turn's other writes (WakeDue's) at the next look at the firmware (Blocked,
  /// WaitForChange, the runahead calls): one count a turn, and a firmware thread that looks
  /// before then finds what was written in its fds.
  void NoteFdWakes(std::uint32_t channels);
  /// Runahead (bus/vtime_protocol.h, Page::runahead): the firmware's library may move the
  /// clock itself, to the instants its own waits and timers are due, up to run time until_ns,
  /// on the grid phase_ns + k * step_ns (step_ns 0: any instant), until it sends a frame or
  /// meets what only the host can do; then it gives the clock back. Call with the firmware
  /// blocked and everything due now woken (WakeDue). While it holds the clock Blocked() is
  /// false; Blocked() takes the clock back when it finds every thread blocked (a thread asleep
  /// outside the library's waits). now_ns() then says where the firmware got to.
  /// `sends` (nullptr: none) lets sends of the firmware's run through the window: those the
  /// host foresaw and forecast, and unforeseen ones that change nothing (SendPlan).
  using SendPlan = RunaheadSendPlan;
  void GrantRunahead(std::int64_t until_ns, std::int64_t step_ns, std::int64_t phase_ns,
                     const SendPlan* sends = nullptr);
  /// Runahead, right after GrantRunahead: wakes the first process's agent thread, which finds
  /// nothing of its own to do and, waiting again, moves the clock on. False when it has none
  /// (nothing would take the grant up: take it back).
  bool KickRunahead();
  /// Takes the clock back from a firmware that did not take it up (KickRunahead false).
  void RevokeRunahead();
  /// The firmware may still move the clock (granted, or moving it now).
  bool RunaheadGranted() const;
  /// Sleeps until the firmware gave the clock back (it wakes the host then), at most
  /// timeout_us: while it moves the clock itself, the host has nothing to do.
  void WaitWhileGranted(int timeout_us);
  /// Instants the firmware moved its clock to itself so far.
  std::uint64_t local_advances() const;
  /// Frames the firmware wrote to kernel CAN sockets so far (bus/vtime_protocol.h).
  std::uint64_t KernelCanSends() const;
  /// Sends of the firmware's that did not end a window, so far.
  std::uint64_t sends_through() const;
  /// After a window (the firmware gave the clock back): the run instants of its sends that did
  /// not end it, in the order they entered its socket's ring.
  void TakeSendsThroughAt(std::vector<std::int64_t>& instants_ns) const;
  /// The last Blocked() found a thread stopped or traced (a debugger has it): the firmware
  /// does not move until it is let go, however long that takes.
  bool FirmwareStopped() const { return stopped_seen_; }
  /// Threads looked up in the kernel (/proc/<pid>/task/<tid>/stat reads) so far.
  std::uint64_t kernel_looks() const { return kernel_looks_; }
  /// Times Blocked() found the firmware blocked only through such looks at a thread in a wait
  /// the library cannot vouch for (a pipe, a futex, ...) or asleep outside its waits. Not
  /// counted: a vouched wait that a write on one of its channels made the host ask about (the
  /// write may have come after the thread took what it wrote: more often on a busy machine).
  /// Unlike kernel_looks it does not grow with the host's load.
  std::uint64_t blocked_seen_in_kernel() const { return blocked_seen_in_kernel_; }
  /// Changes whenever the firmware made a call the broker sees on a socket rather than in a
  /// ring (bus/vtime_protocol.h, Page::bus_calls) or a thread of it was found gone: while it
  /// stays, a look at the broker's sockets finds nothing new from the firmware.
  std::uint64_t socket_activity() const;

  /// True when every thread of the firmware is blocked (see above). A thread asleep in the
  /// kernel outside the library's waits counts once it was seen asleep twice without running
  /// in between, so a first look at such a thread returns false.
  bool Blocked();
  /// A thread of the first process was found gone (exited or killed without the library's
  /// word) since the last call: then the firmware may be exiting.
  bool TakeThreadsGone() { return std::exchange(threads_gone_, false); }
  /// Sleeps until a thread of the firmware entered or left a wait since the last Blocked()
  /// began (so nothing between that check and this sleep is missed), at most timeout_us.
  void WaitForChange(int timeout_us);
  /// The firmware's processes run on the host thread's one CPU: WaitForChange makes way for
  /// them (sched_yield) before it sleeps on the page.
  void SetSharesCpu(bool shares) { shares_cpu_ = shares; }

  /// The threads that are not blocked: "name (tid N) last called X (K calls since its last
  /// wait)", for the report of a firmware that does not block.
  std::vector<std::string> RunningThreads();
  /// Timed waits found that bypassed the library (a raw system call, a glibc-internal wait):
  /// "thread 'NAME' (pid P, tid T) is in nanosleep, a timed wait ...", each thread and call
  /// once, since the last call. They end on the host's clock, so the run may not be
  /// deterministic. Found when a thread the library sees running is first seen asleep in the
  /// kernel (its /proc .../syscall); where that file cannot be read, nothing is found.
  std::vector<std::string> TakeHostClockWaits() { return std::exchange(host_clock_waits_, {}); }
  /// Processes found running without the library since the last call (an exec of a program
  /// without it: LD_PRELOAD cleared, a static binary): "process P (NAME) exec'd a program
  /// without libwheelhil_vtime.so: ...", each once. They run on the host's clock, so the run
  /// may not be deterministic; their threads count as blocked while asleep in the kernel.
  std::vector<std::string> TakeProcessesOffTheClock() {
    return std::exchange(off_the_clock_, {});
  }
  /// A process not on the clock: one whose library has not registered it yet (the run cannot
  /// go on while it starts), else one found running without the library; its pid, else 0.
  pid_t UnregisteredProcess() const;
  /// What the kernel says of process `pid`, for a run that gives up on it: "'sh', asleep (S)
  /// in do_wait, system call 61, libwheelhil_vtime.so loaded"; "gone" when it is.
  static std::string DescribeProcess(pid_t pid);

 private:
  enum class Kernel { kAsleep, kRunning, kGone };
  struct ProcFiles {
    pid_t tid = 0;
    int stat_fd = -1;
    int schedstat_fd = -1;
    int syscall_fd = -1;
    std::uint64_t runs_seen = UINT64_MAX;  // schedstat timeslices when last seen asleep
    std::vector<long> calls_reported;      // host-clock waits already reported
  };
  // Blocked() without the runahead grant's part. `*unvouchable`: some thread was found blocked
  // only by a look in the kernel at a wait the library could not vouch for, or at a thread
  // asleep outside its waits.
  bool AllThreadsBlocked(bool* unvouchable);
  // Counts the writes NoteFdWakes was told of (Page::fd_wakes), once for all of them: before
  // any look at the firmware's waits and before the host waits or grants the clock.
  void CountFdWakes();
  // GrantRunahead: the page's SendRules from `plan` (nullptr: every send ends the window).
  void WriteSendRules(const SendPlan* plan);
  std::uint32_t unnoted_channels_ = 0;  // NoteFdWakes since the last CountFdWakes
  Kernel KernelState(int slot, pid_t pid, pid_t tid, std::uint64_t* runs);
  // A thread the library sees running is asleep in the kernel: reports it when that sleep is a
  // timed wait the library did not see.
  void CheckKernelWait(int slot, pid_t pid, pid_t tid);
  static std::string ThreadName(pid_t pid, pid_t tid);
  // This process's copy of fd `fd` of process `pid` (pidfd_getfd), cached while `tag` (the
  // thread, or the timer's generation) is the same; -1 when copies cannot be had.
  int CopyOfFd(pid_t pid, int fd, std::uint64_t tag);
  // An alarm / POSIX timer's signal, as the kernel sends it (SI_TIMER with its value).
  void SendTimerSignal(const bus::vtime::TimerSlot& t, pid_t pid);
  void FreeDeadThread(int slot);
  bool ProcessAlive(pid_t pid) const;

  std::string path_;
  bus::vtime::Page* page_ = nullptr;
  std::vector<ProcFiles> files_;
  std::uint32_t transitions_seen_ = 0;
  std::uint64_t kernel_looks_ = 0;
  std::uint64_t blocked_seen_in_kernel_ = 0;
  std::uint64_t threads_freed_ = 0;  // FreeDeadThread
  bool stopped_seen_ = false;         // FirmwareStopped
  bool shares_cpu_ = false;
  // WaitForChange: yields in a row after which no thread had changed (then it sleeps).
  static constexpr int kYieldsBeforeSleep = 2;
  int yields_in_vain_ = 0;
  int first_process_slot_ = -1;
  struct FdCopy {
    pid_t pid = 0;
    int remote_fd = -1;
    std::uint64_t tag = 0;
    int local_fd = -1;
  };
  std::vector<FdCopy> fd_copies_;
  std::vector<std::pair<pid_t, int>> pidfds_;
  bool fd_copies_work_ = true;
  std::vector<pid_t> signalled_;  // processes a timer signal went to at the current instant
  bool threads_gone_ = false;
  std::vector<std::string> host_clock_waits_;
  std::vector<std::string> off_the_clock_;
  // A starting process (pid) that is a program without the library: its slot becomes
  // kProcOutside and it is reported.
  bool FoundOffTheClock(pid_t pid);
  // Starting processes seen asleep in the kernel, with their timeslice count then.
  std::vector<std::pair<pid_t, std::uint64_t>> starting_asleep_;
  pid_t first_pid_ = 0;
};

/// A system call a thread is blocked in, as /proc/<pid>/task/<tid>/syscall gives it ("202 0x..
/// 0x80 ..."), when it is a wait with a timeout (which then runs on the host's clock): its
/// number and name; call == nullptr for anything else (no timeout, not a wait, running).
struct HostClockWait {
  long number = -1;
  const char* call = nullptr;
};
HostClockWait ClassifyKernelWait(const std::string& proc_syscall_line);

/// `file` is an ELF executable without an interpreter (nothing can be preloaded into it).
bool IsStaticExecutable(const std::string& file);

/// Why `command` (a shell command line) cannot run on the virtual clock: its program is a
/// statically linked executable, into which no library can be preloaded. Empty when nothing
/// speaks against it (a dynamic executable, a script, a program not found on PATH).
std::string WhyNotVirtualClock(const std::string& command);

}  // namespace wheelhil::emulator::firmware
