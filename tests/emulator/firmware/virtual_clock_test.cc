// The virtual clock end to end, without a run: the test is the clock's host
// (emulator/firmware/virtual_clock.h) and tests/emulator/firmware/vtime_probe.c, preloaded with
// libwheelhil_vtime.so, waits in each way the library intercepts. Time moves only when the probe
// is blocked, straight to its next deadline, so each wait must end exactly at its virtual
// deadline, and 30 s of sleep must take far less than 30 s of wall time.
#include <fcntl.h>
#include <linux/capability.h>
#include <sched.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "bus/ucan_runtime_dir.h"
#include "bus/vtime_protocol.h"
#include "emulator/firmware/virtual_clock.h"

namespace wheelhil::emulator::firmware {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

const std::string kLib = std::string(WHEELHIL_BINARY_DIR) + "/lib/libwheelhil_vtime.so";
const std::string kProbe = std::string(WHEELHIL_BINARY_DIR) + "/bin/vtime_probe";

struct ProbeRun {
  int exit_status = -1;
  bool finished = false;       // exited within the wall-clock limit
  double wall_s = 0;
  std::int64_t virtual_ns = 0;  // the clock when it exited
  std::vector<std::string> running;  // RunningThreads() when it did not block
  pid_t unregistered = 0;
  pid_t pid = 0;  // a process UnregisteredProcess() named while it ran
  std::map<std::string, std::pair<std::int64_t, long>> waits;  // label -> (elapsed ns, result)
  std::string out;
  std::uint64_t host_moves = 0;      // instants the host moved the clock to
  std::uint64_t local_advances = 0;  // ... and the probe itself (runahead)
  std::uint64_t sends_through = 0;   // its sends that did not give the clock back
  double give_back_wait_s = -1;      // Grant::host_sleeps: how long the host slept
  bool granted_after_wait = false;
};

// Runahead for RunProbe: granted once the probe first blocked, up to run time until_ns on the
// grid of step_ns.
struct Grant {
  std::int64_t until_ns = 0;
  std::int64_t step_ns = 0;
  // After the grant the host sleeps until the firmware gives the clock back
  // (WaitWhileGranted), rather than looking at its threads.
  bool host_sleeps = false;
};

// Runs the probe on a fresh clock: whenever it is blocked, the clock moves to its next deadline.
// `sends`: what of its sends may run through the window (GrantRunahead's plan).
ProbeRun RunProbe(const std::string& what, double wall_limit_s = 20,
                  std::optional<Grant> grant = std::nullopt,
                  const RunaheadSendPlan* sends = nullptr) {
  const std::string dir = bus::CreateTempUcanRuntimeDir("wheelhil-vtime-test-");
  ProbeRun r;
  {
    VirtualClock clock(dir);
    clock.ExpectFirstProcess();
    const std::string out_path = dir + "/out.txt";
    const pid_t pid = ::fork();
    if (pid == 0) {
      // The probe sets the clock: without CAP_SYS_TIME a call that reached the kernel fails
      // (EPERM) instead of setting the host's clock (the tests run as root).
      (void)::prctl(PR_CAPBSET_DROP, CAP_SYS_TIME, 0, 0, 0);
      const int fd = ::open(out_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
      ::dup2(fd, 1);
      for (const auto& [k, v] : clock.ChildEnvironment(kLib)) ::setenv(k.c_str(), v.c_str(), 1);
      ::setenv("LD_PRELOAD", kLib.c_str(), 1);
      // Under ASan the probe is instrumented and the library is not (as the bus library).
      ::setenv("ASAN_OPTIONS", "verify_asan_link_order=0", 1);
      if (grant) {
        // As a run places the firmware: one CPU, at SCHED_BATCH (a thread the one moving the
        // clock wakes does not preempt it before it has said so).
        cpu_set_t one;
        CPU_ZERO(&one);
        CPU_SET(sched_getcpu(), &one);
        (void)::sched_setaffinity(0, sizeof(one), &one);
        sched_param batch{};
        (void)::sched_setscheduler(0, SCHED_BATCH, &batch);
      }
      ::execl(kProbe.c_str(), kProbe.c_str(), what.c_str(), nullptr);
      ::_exit(127);
    }
    clock.SetFirstProcessPid(pid);
    r.pid = pid;
    bool registered = false;
    const auto t0 = Clock::now();
    int status = 0;
    for (;;) {
      if (::waitpid(pid, &status, WNOHANG) == pid) {
        r.finished = true;
        r.exit_status = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
        break;
      }
      r.wall_s = std::chrono::duration<double>(Clock::now() - t0).count();
      if (r.wall_s > wall_limit_s) {
        r.running = clock.RunningThreads();
        ::kill(pid, SIGKILL);
        ::waitpid(pid, &status, 0);
        break;
      }
      clock.WakeDue();
      // (Unregistered again once it had registered: not its start.)
      if (const pid_t u = clock.UnregisteredProcess(); u > 0 && registered) {
        r.unregistered = u;
      } else if (u == 0) {
        registered = true;
      }
      if (!clock.Blocked()) {
        clock.WaitForChange(200);
        continue;
      }
      const std::int64_t next = clock.NextDeadlineNs();
      if (next != INT64_MAX && next > clock.now_ns()) {
        clock.SetNow(next);
        ++r.host_moves;
      }
      if (grant && registered) {
        // What is due now is the host's to end; from there the firmware moves the clock.
        clock.WakeDue();
        clock.GrantRunahead(grant->until_ns, grant->step_ns, 0, sends);
        // As a run does: the waits published before the grant (all of them, perhaps, if the
        // firmware ran before the grant) are not looked at again unless something wakes.
        EXPECT_TRUE(clock.KickRunahead());
        if (grant->host_sleeps) {
          // Each sleep up to 30 s: only the firmware's wake-up ends one sooner (or a change of
          // the word before it began, which makes it return at once and go round again).
          const auto slept_from = Clock::now();
          while (clock.RunaheadGranted() && Clock::now() - slept_from < std::chrono::seconds(60)) {
            clock.WaitWhileGranted(30'000'000);
          }
          r.give_back_wait_s = std::chrono::duration<double>(Clock::now() - slept_from).count();
          r.granted_after_wait = clock.RunaheadGranted();
        }
        grant.reset();
      }
    }
    r.local_advances = clock.local_advances();
    r.sends_through = clock.sends_through();
    r.wall_s = std::chrono::duration<double>(Clock::now() - t0).count();
    r.virtual_ns = clock.now_ns();
    std::ifstream in(out_path);
    std::stringstream ss;
    ss << in.rdbuf();
    r.out = ss.str();
  }
  std::istringstream lines(r.out);
  std::string label;
  std::int64_t ns = 0;
  long result = 0;
  std::string line;
  while (std::getline(lines, line)) {
    std::istringstream words(line);
    if (words >> label >> ns >> result) r.waits[label] = {ns, result};
  }
  fs::remove_all(dir);
  return r;
}

constexpr std::int64_t kMs = 1'000'000;

// What a run that gives up on a process says of it: its name, where it sleeps, whether the
// library is in it.
TEST(VirtualClock, DescribeProcessSaysWhereAProcessIsAndWhetherTheLibraryIsIn) {
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    ::close(fds[1]);
    char c;
    (void)!::read(fds[0], &c, 1);  // until the parent closes its end
    ::_exit(0);
  }
  ::close(fds[0]);
  std::string said;
  for (int i = 0; i < 2000 && said.find("asleep") == std::string::npos; ++i) {
    said = VirtualClock::DescribeProcess(child);
    ::usleep(1000);
  }
  EXPECT_THAT(said, ::testing::HasSubstr("asleep (S)"));
  EXPECT_THAT(said, ::testing::HasSubstr("system call 0"));  // read
  EXPECT_THAT(said, ::testing::HasSubstr("libwheelhil_vtime.so not loaded"));
  ::close(fds[1]);
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  EXPECT_EQ(VirtualClock::DescribeProcess(child), "gone");
}

TEST(VirtualClock, SleepsEndAtTheirVirtualDeadlinesWithoutTheWallClock) {
  const ProbeRun r = RunProbe("sleeps");
  ASSERT_TRUE(r.finished) << r.out;
  EXPECT_EQ(r.exit_status, 0) << r.out;
  EXPECT_EQ(r.waits.at("start").first, 0);
  EXPECT_EQ(r.waits.at("sleep30").first, 30'000 * kMs);
  EXPECT_EQ(r.waits.at("nanosleep").first, 30'250 * kMs);
  EXPECT_EQ(r.waits.at("nanosleep").second, 0);
  EXPECT_EQ(r.waits.at("usleep").first, 30'250 * kMs + 1'500'000);
  EXPECT_EQ(r.waits.at("clock_nanosleep_abs").first, 32'250 * kMs + 1'500'000);
  // 32 s of virtual sleeps; a host that waited for them would need that long.
  EXPECT_LT(r.wall_s, 4.0);
  // CLOCK_REALTIME is the fixed start epoch plus the run's time, not the host's date.
  EXPECT_THAT(r.out, ::testing::HasSubstr(
                         "realtime_s " + std::to_string(VirtualClock::kRealtimeAtStartNs /
                                                            1'000'000'000 + 32)));
}

TEST(VirtualClock, PollSelectAndEpollTimeoutsAreVirtual) {
  const ProbeRun r = RunProbe("polls");
  ASSERT_TRUE(r.finished) << r.out;
  EXPECT_EQ(r.exit_status, 0) << r.out;
  EXPECT_EQ(r.waits.at("poll"), std::make_pair(5 * kMs, 0L));
  EXPECT_EQ(r.waits.at("select"), std::make_pair(20 * kMs, 0L));
  EXPECT_EQ(r.waits.at("epoll_wait"), std::make_pair(23 * kMs, 0L));
  EXPECT_EQ(r.waits.at("ppoll"), std::make_pair(30 * kMs, 0L));
  EXPECT_EQ(r.waits.at("poll_ready"), std::make_pair(30 * kMs, 1L));
}

TEST(VirtualClock, TimerfdTicksOnTheVirtualClockAndCountsOverruns) {
  const ProbeRun r = RunProbe("timerfd");
  ASSERT_TRUE(r.finished) << r.out;
  EXPECT_EQ(r.exit_status, 0) << r.out;
  // A blocking read() waits in the kernel, outside the library: the clock still sees it blocked.
  EXPECT_EQ(r.waits.at("tick"), std::make_pair(47 * kMs, 1L));  // the last of 7, 27, 47 ms
  EXPECT_THAT(r.out, ::testing::HasSubstr("remaining_ns 20000000"));
  // 45 ms of sleep from 47 ms: expirations at 67 and 87 ms, read at 92 ms.
  EXPECT_EQ(r.waits.at("overrun"), std::make_pair(92 * kMs, 2L));
}

TEST(VirtualClock, ConditionVariableTimeoutsAreVirtualAndSignalsStillWake) {
  const ProbeRun r = RunProbe("cond");
  ASSERT_TRUE(r.finished) << r.out;
  EXPECT_EQ(r.exit_status, 0) << r.out;
  EXPECT_EQ(r.waits.at("clockwait"), std::make_pair(50 * kMs, 1L));
  EXPECT_EQ(r.waits.at("timedwait"), std::make_pair(70 * kMs, 1L));
  EXPECT_EQ(r.waits.at("timedwait_monotonic"), std::make_pair(75 * kMs, 1L));
  EXPECT_EQ(r.waits.at("signalled"), std::make_pair(85 * kMs, 1L));
}

TEST(VirtualClock, SemaphoreTimeoutsAreVirtualAndPostsStillWake) {
  const ProbeRun r = RunProbe("sem");
  ASSERT_TRUE(r.finished) << r.out;
  EXPECT_EQ(r.exit_status, 0) << r.out;
  EXPECT_EQ(r.waits.at("sem_timedwait"), std::make_pair(30 * kMs, 1L));
  EXPECT_EQ(r.waits.at("sem_clockwait_posted"), std::make_pair(35 * kMs, 1L));
}

TEST(VirtualClock, TimedMutexLocksAreTriedEveryVirtualMillisecond) {
  const ProbeRun r = RunProbe("mutex");
  ASSERT_TRUE(r.finished) << r.out;
  EXPECT_EQ(r.exit_status, 0) << r.out;
  // Released at 12.6 ms (100 us + 12.5 ms), taken at the next whole millisecond of trying.
  EXPECT_EQ(r.waits.at("timedlock"), std::make_pair(13 * kMs + 100'000, 1L));
  EXPECT_EQ(r.waits.at("clocklock_timeout"), std::make_pair(18 * kMs + 200'000, 1L));
}

TEST(VirtualClock, RawSystemCallsThroughLibcAreVirtual) {
  const ProbeRun r = RunProbe("syscall");
  ASSERT_TRUE(r.finished) << r.out;
  EXPECT_EQ(r.exit_status, 0) << r.out;
  EXPECT_EQ(r.waits.at("raw_clock"), std::make_pair(0L, 0L));
  EXPECT_EQ(r.waits.at("raw_nanosleep"), std::make_pair(3 * kMs, 0L));
  // Rust's std parks threads this way: FUTEX_WAIT (relative), FUTEX_WAIT_BITSET (absolute).
  EXPECT_EQ(r.waits.at("futex_timeout"), std::make_pair(7 * kMs, 1L));
  EXPECT_EQ(r.waits.at("futex_woken"), std::make_pair(9 * kMs, 1L));
}

TEST(VirtualClock, AlarmSetitimerAndPosixTimersSignalAtVirtualInstants) {
  const ProbeRun r = RunProbe("timers");
  ASSERT_TRUE(r.finished) << r.out;
  EXPECT_EQ(r.exit_status, 0) << r.out;
  EXPECT_EQ(r.waits.at("alarm_left"), std::make_pair(0L, 2L));
  EXPECT_EQ(r.waits.at("alarm"), std::make_pair(1000 * kMs, 1L));
  EXPECT_EQ(r.waits.at("posix_timer"), std::make_pair(1015 * kMs, 1L));  // the third: 5, 10, 15
  EXPECT_EQ(r.waits.at("thread_timer"), std::make_pair(1023 * kMs, 1L));
  EXPECT_EQ(r.waits.at("setitimer"), std::make_pair(1026 * kMs, 1L));
}

// The probe's "ahead" waits, at their virtual instants: the main thread's sleeps at 3, 6, 9,
// 12 ms, a timerfd thread's ticks at 2 .. 10 ms, then a sleep to 32 ms.
void ExpectAheadWaits(const ProbeRun& r) {
  ASSERT_TRUE(r.finished) << r.out;
  EXPECT_EQ(r.exit_status, 0) << r.out;
  for (int i = 1; i <= 4; ++i) {
    EXPECT_EQ(r.waits.at("sleep" + std::to_string(i)).first, 3 * i * kMs) << r.out;
  }
  for (int i = 1; i <= 5; ++i) {
    EXPECT_EQ(r.waits.at("tick" + std::to_string(i)), std::make_pair(2 * i * kMs, 1L)) << r.out;
  }
  EXPECT_EQ(r.waits.at("late"), std::make_pair(32 * kMs, 0L)) << r.out;
}

// Runahead: granted the clock, the firmware's library moves it itself through the firmware's
// own sleeps and timer ticks, each ended at its own instant as the host would have, and gives
// it back at the end of the grant, or at a deadline off the grid it was given.
TEST(VirtualClock, RunaheadMovesTheClockThroughTheFirmwaresOwnWaitsInOrder) {
  const ProbeRun host = RunProbe("ahead");
  ExpectAheadWaits(host);
  EXPECT_EQ(host.local_advances, 0u);
  EXPECT_EQ(host.host_moves, 9u);  // 2, 3, 4, 6, 8, 9, 10, 12, 32 ms

  // Who moved which instant can depend on scheduling: once in a full suite run under load the
  // probe was granted the clock only after its last instant (the host moved all nine; every
  // wait still ended at its own instant). So each grant gets up to three runs to show its count;
  // every run's waits are checked.
  auto granted = [](Grant g, std::uint64_t local, std::uint64_t host_moves) {
    for (int attempt = 0; attempt < 3; ++attempt) {
      const ProbeRun r = RunProbe("ahead", 20, g);
      ExpectAheadWaits(r);
      EXPECT_EQ(r.local_advances + r.host_moves, 9u);
      if (r.local_advances == local && r.host_moves == host_moves) return;
    }
    ADD_FAILURE() << "three runs without " << local << " instants moved by the probe";
  };
  // Granted after the host's first move (2 ms): the other eight are the probe's own.
  granted(Grant{1000 * kMs, kMs}, 8u, 1u);
  // Up to 5 ms: 3 and 4 ms, then the clock is the host's again.
  granted(Grant{5 * kMs, kMs}, 2u, 7u);

  // On a 2 ms grid: 3 ms is off it, so the host takes that instant and everything after.
  const ProbeRun grid = RunProbe("ahead", 20, Grant{1000 * kMs, 2 * kMs});
  ExpectAheadWaits(grid);
  EXPECT_EQ(grid.local_advances, 0u);
}

// The host need not look at the firmware while it holds the clock: the library wakes the host
// when it gives the clock back (here at the end of a grant to 5 ms).
TEST(VirtualClock, RunaheadWakesTheSleepingHostWhenItGivesTheClockBack) {
  const ProbeRun r = RunProbe("ahead", 120, Grant{5 * kMs, kMs, /*host_sleeps=*/true});
  ExpectAheadWaits(r);
  EXPECT_FALSE(r.granted_after_wait);
  EXPECT_LT(r.give_back_wait_s, 20.0) << "the host slept out its 30 s: no wake-up came";
  EXPECT_EQ(r.local_advances, 2u);
}

// Runahead through the firmware's sends (the probe tells the library of a send as the bus
// library does): at 3 and 5 ms it sends 080#, at 4 ms 680# (8 bytes), at 7 ms 181#; it wakes
// at 2, 3, 4, 5, 7 and 8 ms. Granted at 2 ms; a send that runs through leaves the clock with
// the probe, any other gives it back at that instant.
TEST(VirtualClock, RunaheadGoesOnThroughForeseenSendsAndThoseThatChangeNothing) {
  auto frame = [](std::uint32_t id) {
    bus::CanFrame f;
    f.id = id;
    return f;
  };
  // Every instant of the window has the bus idle for 1 ms; 0x080 and 0x680 are read by no
  // device, 0x181 is.
  RunaheadSendPlan open;
  open.bit_ns = 1000;  // 1 Mbit/s
  for (int ms = 0; ms <= 10; ++ms) open.gaps.push_back({ms * kMs, (ms + 1) * kMs, 0});
  open.unread_ids.set(0x680);
  auto run = [](const RunaheadSendPlan& plan) {
    const ProbeRun r = RunProbe("ahead_sends", 20, Grant{1000 * kMs, kMs}, &plan);
    for (int ms : {2, 3, 4, 5, 7, 8}) {
      EXPECT_EQ(r.waits.at("at" + std::to_string(ms)), std::make_pair(ms * kMs, 1L)) << r.out;
    }
    return r;
  };

  // No plan: the send at 3 ms ends the window there.
  const ProbeRun none = run(RunaheadSendPlan{});
  EXPECT_EQ(none.local_advances, 1u);
  EXPECT_EQ(none.sends_through, 0u);

  // 080# foreseen at 3 and 5 ms, 680# unforeseen but unread, in a gap: on to 7 ms, where 181#
  // (read by a device) ends the window.
  RunaheadSendPlan all = open;
  all.foreseen = {{3 * kMs, frame(0x080)}, {5 * kMs, frame(0x080)}};
  const ProbeRun through = run(all);
  EXPECT_EQ(through.local_advances, 4u);  // 3, 4, 5, 7 ms
  EXPECT_EQ(through.sends_through, 3u);

  // Foreseen at 6 ms too, where the probe sends nothing: the forecast after it does not hold,
  // so the clock goes back at 5 ms, before it would pass 6.
  RunaheadSendPlan missed = all;
  missed.foreseen.push_back({6 * kMs, frame(0x080)});
  const ProbeRun m = run(missed);
  EXPECT_EQ(m.local_advances, 3u);  // 3, 4, 5 ms
  EXPECT_EQ(m.sends_through, 3u);

  // 080# foreseen at 4 ms only: the one at 3 ms is unforeseen (unread: it runs through); at
  // 4 ms 680# comes before the foreseen frame and ends the window.
  RunaheadSendPlan other = open;
  other.unread_ids.set(0x080);
  other.foreseen = {{4 * kMs, frame(0x080)}};
  const ProbeRun o = run(other);
  EXPECT_EQ(o.local_advances, 2u);
  EXPECT_EQ(o.sends_through, 1u);

  // The bus idle for only 50 us after 4 ms: 680# with 8 bytes (up to 135 bits) does not fit.
  RunaheadSendPlan narrow = all;
  narrow.gaps[4].busy_ns = 4 * kMs + 50'000;
  const ProbeRun n = run(narrow);
  EXPECT_EQ(n.local_advances, 2u);
  EXPECT_EQ(n.sends_through, 1u);

  // 680# would win an arbitration at 4 ms (against 0x700): it must lose every one.
  RunaheadSendPlan wins = all;
  wins.gaps[4].max_key = bus::vtime::StandardDataKey(0x700);
  const ProbeRun w = run(wins);
  EXPECT_EQ(w.local_advances, 2u);
  EXPECT_EQ(w.sends_through, 1u);
}

// On a kernel CAN interface the kernel stamps a received frame with the host's realtime clock
// (SO_TIMESTAMPNS); the firmware sees the virtual one, as on the private bus. Needs a kernel
// vcan (WHEELHIL_VCAN): ctest runs it in the user-mode-linux guest (Vcan.VirtualClock).
TEST(VirtualClock, KernelCanReceiveStampsAreTheVirtualClocks) {
  if (std::getenv("WHEELHIL_VCAN") == nullptr) {
    GTEST_SKIP() << "no kernel vcan (WHEELHIL_VCAN unset): ctest -L vcan runs this in a guest";
  }
  const ProbeRun r = RunProbe("can_stamps");
  ASSERT_TRUE(r.finished);
  ASSERT_EQ(r.exit_status, 0) << r.out;
  // The virtual realtime clock starts at 2026-01-01T00:00:00Z and nothing moved it.
  const std::int64_t start = VirtualClock::kRealtimeAtStartNs;
  EXPECT_EQ(r.waits.at("stamp").first, start) << r.out;
  EXPECT_EQ(r.waits.at("realtime").first, start) << r.out;
}

// A thread asleep in the kernel where the library does not see it (a read on a pipe) may be
// woken by anything: the firmware never moves the clock, the host finds every thread blocked,
// takes the clock back and moves it as ever.
TEST(VirtualClock, RunaheadWithAThreadAsleepOutsideTheLibraryStaysWithTheHost) {
  const ProbeRun r = RunProbe("ahead_outside", 20, Grant{1000 * kMs, kMs});
  ExpectAheadWaits(r);
  EXPECT_EQ(r.local_advances, 0u);
  EXPECT_EQ(r.host_moves, 9u);
}

TEST(VirtualClock, AThreadThatNeverBlocksIsNamedWithItsLastCall) {
  const ProbeRun r = RunProbe("spin", 1.0);
  EXPECT_FALSE(r.finished);
  EXPECT_EQ(r.virtual_ns, 0);  // time never moved
  ASSERT_EQ(r.running.size(), 1u) << r.out;
  EXPECT_THAT(r.running[0], ::testing::HasSubstr("thread 'vtime_probe'"));
  EXPECT_THAT(r.running[0], ::testing::HasSubstr("last called a clock read"));
}

// Setting the clock (a firmware that takes its time from GPS or NTP) moves the firmware's own
// CLOCK_REALTIME, never the host's: the probe runs without CAP_SYS_TIME, so a call that
// reached the kernel would fail.
TEST(VirtualClock, SettingTheClockMovesOnlyTheVirtualRealtimeClock) {
  timespec host_before{};
  ::clock_gettime(CLOCK_REALTIME, &host_before);
  const ProbeRun r = RunProbe("settime");
  ASSERT_TRUE(r.finished) << r.out;
  EXPECT_EQ(r.exit_status, 0) << r.out;
  EXPECT_EQ(r.waits.at("clock_settime").second, 1900000000L);
  EXPECT_EQ(r.waits.at("settimeofday").second, 2000000000L);
  EXPECT_EQ(r.waits.at("adjtimex_setoffset").second, 2000000005L);
  EXPECT_EQ(r.waits.at("adjtime").second, 2000000015L);
  EXPECT_EQ(r.waits.at("adjtimex_read_freq").second, 1234L);
  EXPECT_EQ(r.waits.at("adjtimex_read_time").second, 2000000015L);
  EXPECT_EQ(r.waits.at("stime").second, 2100000000L);
  EXPECT_EQ(r.waits.at("syscall_settime").second, 2200000000L);
  EXPECT_EQ(r.waits.at("settime_monotonic").second, 1L);
  // The set clock runs on with virtual time; the monotonic clock never jumped.
  EXPECT_EQ(r.waits.at("after_sleep"), std::make_pair(2000 * kMs, 2200000002L));
  timespec host_after{};
  ::clock_gettime(CLOCK_REALTIME, &host_after);
  EXPECT_LT(host_after.tv_sec - host_before.tv_sec, 60);  // the host's clock untouched
  EXPECT_LT(host_before.tv_sec, 1900000000L);
}

// tv_sec = LONG_MAX means "forever" to the kernel: such waits never end (they ended at once
// when the conversion to ns overflowed into the past).
TEST(VirtualClock, WaitsWithTheLargestTimeoutsSleepForever) {
  const ProbeRun r = RunProbe("forever");
  ASSERT_TRUE(r.finished) << r.out;
  EXPECT_EQ(r.exit_status, 0) << r.out;
  EXPECT_EQ(r.waits.at("forever_ended"), std::make_pair(50 * kMs, 0L));
  EXPECT_EQ(r.waits.at("timerfd_far").second, 1L);
}

// A wait in a signal handler nests inside the wait the signal interrupted, as the kernel's do:
// the interrupted condition wait still ends at its deadline.
TEST(VirtualClock, AWaitInASignalHandlerNestsInTheInterruptedWait) {
  const ProbeRun r = RunProbe("nested");
  ASSERT_TRUE(r.finished) << r.out;
  ASSERT_EQ(r.exit_status, 0) << r.out;
  ASSERT_EQ(r.waits.count("handler_slept"), 1u) << r.out;
  EXPECT_EQ(r.waits.at("handler_slept"), std::make_pair(15 * kMs, 0L));
  EXPECT_EQ(r.waits.at("interrupted_cond"), std::make_pair(50 * kMs, 1L));
}

// close_range, closefrom, a close-everything loop and dup2 onto its descriptors do not take
// the library's wake-ups from it (its own or another thread's); timers still work after.
TEST(VirtualClock, ClosingEveryDescriptorLeavesTheLibraryItsOwn) {
  const ProbeRun r = RunProbe("closefds");
  ASSERT_TRUE(r.finished) << r.out << (r.running.empty() ? "" : r.running[0]);
  EXPECT_EQ(r.exit_status, 0) << r.out;
  EXPECT_EQ(r.waits.at("close_range"), std::make_pair(6 * kMs, 0L));
  EXPECT_EQ(r.waits.at("after_close_range"), std::make_pair(11 * kMs, 0L));
  EXPECT_EQ(r.waits.at("after_closefrom"), std::make_pair(16 * kMs, 0L));
  EXPECT_EQ(r.waits.at("after_close_loop"), std::make_pair(21 * kMs, 0L));
  EXPECT_EQ(r.waits.at("dup2_onto").second, 1L);
  EXPECT_EQ(r.waits.at("after_dup2"), std::make_pair(26 * kMs, 0L));
  EXPECT_EQ(r.waits.at("timerfd_after"), std::make_pair(29 * kMs, 1L));
  EXPECT_EQ(r.waits.at("thread_poll3"), std::make_pair(35 * kMs, 0L));
}

// A thread whose first timed wait finds the descriptor table full still waits on the virtual
// clock (the library's wake-up by signal), and the library says so in the firmware's log.
TEST(VirtualClock, ATimedWaitWithTheDescriptorTableFullStillEndsOnTime) {
  const ProbeRun r = RunProbe("fdfull");
  ASSERT_TRUE(r.finished) << r.out;
  EXPECT_EQ(r.exit_status, 0) << r.out;
  EXPECT_EQ(r.waits.at("fd_table_full").second, 1L);
  EXPECT_EQ(r.waits.at("nofd_poll"), std::make_pair(7 * kMs, 0L));
  EXPECT_EQ(r.waits.at("nofd_select"), std::make_pair(12 * kMs, 0L));
}

// A process that re-execs itself without the library is starting again from its exec on: it
// is never taken for blocked, and the run can name it.
TEST(VirtualClock, AProcessThatExecsWithoutTheLibraryIsNamed) {
  const ProbeRun r = RunProbe("reexec");
  ASSERT_TRUE(r.finished) << r.out;
  EXPECT_EQ(r.exit_status, 0) << r.out;
  EXPECT_EQ(r.unregistered, r.pid);
  EXPECT_EQ(r.virtual_ns, kMs);  // its host-clock sleep did not move virtual time
}

TEST(VirtualClock, AStaticBinaryIsRefusedWithTheReason) {
  EXPECT_EQ(WhyNotVirtualClock(kProbe + " sleeps"), "");
  EXPECT_EQ(WhyNotVirtualClock("exec env A=1 /bin/sh -c true"), "");
  EXPECT_EQ(WhyNotVirtualClock("no-such-program-here --x"), "");
  const std::string static_probe = std::string(WHEELHIL_BINARY_DIR) + "/bin/vtime_probe_static";
  EXPECT_THAT(WhyNotVirtualClock(static_probe + " sleeps"),
              ::testing::HasSubstr("is a statically linked executable"));
}

}  // namespace
}  // namespace wheelhil::emulator::firmware
