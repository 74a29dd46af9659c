#include "emulator/firmware/firmware_link.h"

#include <poll.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>
#include <utility>

#include <fmt/format.h>

#include "bus/ucan_runtime_dir.h"
#include "bus/vtime_protocol.h"
#include "emulator/firmware/stale_run_dirs.h"
#include "emulator/sim/wall_account.h"

namespace wheelhil::emulator::firmware {

namespace {

// A run's private bus directory; a killed run's is removed by the next run (stale_run_dirs.h).
constexpr char kRunDirPrefix[] = "wheelhil-run-";

using Clock = std::chrono::steady_clock;

double WallSeconds(Clock::time_point since) {
  return std::chrono::duration<double>(Clock::now() - since).count();
}

}  // namespace

int CountKernelCanReceivers(const std::string& iface) {
  int count = -1;
  for (const char* list : {"all", "fil", "inv", "sff", "eff", "err"}) {
    std::ifstream in(std::string("/proc/net/can/rcvlist_") + list);
    if (!in) continue;
    count = std::max(count, 0);
    std::string line, first;
    while (std::getline(in, line)) {
      std::istringstream words(line);
      if (words >> first && first == iface) ++count;
    }
  }
  return count;
}

FirmwareLink::FirmwareLink(const std::string& can_iface, Pacing pacing, sim::RunContext& run)
    : run_(run) {
  const bool lockstep = pacing != Pacing::kRealTime;
  bus::CanTransportOptions opt;
  // On the virtual clock over a kernel bus the run takes its own frames back: each one back
  // says the firmware's sockets have it (ReceivedFrame::own).
  opt.receive_own = !can_iface.empty() && pacing == Pacing::kVirtualClock;
  kernel_confirms_ = opt.receive_own;
  if (can_iface.empty()) {
    RemoveStaleRunDirs(kRunDirPrefix);
    runtime_dir_ = bus::CreateTempUcanRuntimeDir(kRunDirPrefix);
    bus::UcanBrokerOptions bo;
    bo.runtime_dir = runtime_dir_;
    bo.remove_runtime_dir = true;
    bo.control_requests = false;  // the run owns its bus: the firmware cannot remove it
    bo.tx_rings_drained_every_pass = pacing == Pacing::kVirtualClock;
    broker_ = std::make_unique<bus::UcanBroker>(bo);
    iface_ = "ucan0";
    broker_->AddBus(iface_);
    ::setenv("WHEELHIL_UCAN_DIR", runtime_dir_.c_str(), 1);
  } else {
    iface_ = can_iface;
    if (pacing == Pacing::kVirtualClock) {
      // No bus of its own, but a private directory for the clock's page.
      RemoveStaleRunDirs(kRunDirPrefix);
      runtime_dir_ = bus::CreateTempUcanRuntimeDir(kRunDirPrefix);
    }
  }
  if (broker_ && lockstep) {
    broker_->UseCallerThread();
    local_port_ = broker_->OpenLocalPort(iface_);
    pumped_ = true;
  } else {
    can_.emplace(bus::SocketCanTransport::Open(iface_, opt));
  }
}

FirmwareLink::~FirmwareLink() { Close(); }

void FirmwareLink::FailExited(const FirmwareProcess& process) {
  FirmwareConnected();  // brings opened_once_ up to date
  run_.Fail(fmt::format("the firmware {} {} (see firmware.log){}", process.ExitDescription(),
                        opened_once_ ? std::string("during the run")
                                     : fmt::format("before opening {}", iface_),
                        process.CrashSummary()));
}

void FirmwareLink::Close() {
  if (broker_) {
    can_.reset();
    broker_.reset();
  }
  // The broker removes only what it made; the directory is the run's, with whatever else is
  // in it (the clock page, files a firmware wrote there).
  if (!runtime_dir_.empty()) {
    std::error_code ec;
    std::filesystem::remove_all(runtime_dir_, ec);
    runtime_dir_.clear();
  }
}

void FirmwareLink::BeforeFirmwareStarts() {
  if (!broker_) kernel_receivers_before_ = CountKernelCanReceivers(iface_);
}

bool FirmwareLink::WaitForConnection(FirmwareProcess& process, double timeout_s,
                                     std::string& why) {
  if (!broker_) {
    // A kernel bus has no broker to see the other side, but the kernel's receive lists show a
    // socket bound to the interface: wait (up to the timeout) for one more receiver than before
    // the firmware started, else (lists unreadable) give it 300 ms. Frames sent before it binds
    // are lost to it (a boot-up in the user-mode-linux guest was). A firmware command that never
    // binds here (a real board's flasher, exit status 0) only costs the wait.
    if (kernel_receivers_before_ < 0) {
      std::this_thread::sleep_for(std::chrono::milliseconds(300));
      return true;
    }
    const auto t0 = Clock::now();
    while (WallSeconds(t0) < timeout_s &&
           CountKernelCanReceivers(iface_) <= kernel_receivers_before_) {
      if (auto code = process.Exited(); code && *code != 0) {
        why = fmt::format("the firmware {} before opening {} (see firmware.log){}",
                          process.ExitDescription(), iface_, process.CrashSummary());
        return false;
      } else if (code) {
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return true;
  }
  const auto t0 = Clock::now();
  while (WallSeconds(t0) < timeout_s) {
    if (FirmwareConnected()) return true;
    if (auto code = process.Exited()) {
      // (FirmwareConnected remembers a socket bound and gone since its last look.)
      why = fmt::format("the firmware {} {} {} (see firmware.log){}", process.ExitDescription(),
                        opened_once_ ? "right after opening" : "before opening", iface_,
                        process.CrashSummary());
      return false;
    }
    if (pumped_) {
      PumpBroker(2);  // its connection and its requests need a broker pass
    } else {
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
  }
  why = fmt::format("the firmware did not open {} within {} s", iface_, timeout_s);
  return false;
}

bool FirmwareLink::Send(const bus::CanFrame& frame) {
  firmware_blocked_ = false;
  if (pumped_) {
    const bool ok = broker_->SendLocal(local_port_, frame);
    // A pumped broker moves nothing on its own: hand the firmware what piled up between two
    // waits for it before its socket fills.
    if (++unpumped_frames_ >= kMaxUnpumpedFrames) Pump(0);
    return ok;
  }
  if (kernel_confirms_) {
    // The kernel would hand it over at once: before the clock is at its instant, the firmware
    // could read it at the instant before. It goes out with the settle of its instant.
    to_kernel_.push_back(frame);
    return true;
  }
  return !can_->Send(frame);
}

void FirmwareLink::SendToKernel() {
  for (const bus::CanFrame& f : to_kernel_) {
    if (const std::error_code ec = can_->Send(f)) {
      run_.Fail(fmt::format("cannot send {:03X}#... to the firmware on {}: {}", f.id, iface_,
                            ec.message()));
      break;
    }
    ++unconfirmed_;
  }
  to_kernel_.clear();
}

void FirmwareLink::Pump(int timeout_ms, bool quiet) {
  unpumped_frames_ = 0;
  if (!PumpBroker(timeout_ms, quiet)) run_.Fail("the userspace bus stopped");
  CheckBrokerLimits();
}

void FirmwareLink::CheckBrokerLimits() {
  const bus::UcanBrokerHealth health = broker_->Health();
  if (health.refused_connections == 0) return;
  run_.Fail(fmt::format("the firmware opened too many connections to the bus: {} ({} refused "
                        "with EMFILE; a CAN socket is one connection, see docs/ucan.md)",
                        health.last_refusal, health.refused_connections));
}

void FirmwareLink::Drain(int timeout_ms, const FrameFn& on_frame) {
  if (broker_) CheckBrokerLimits();
  bus::ReceivedFrame rx;
  int wait = timeout_ms;
  while (!can_->Receive(rx, wait)) {
    on_frame(rx.frame);
    wait = 0;
  }
}

bool FirmwareLink::FirmwareConnected() {
  if (!broker_) {
    // A kernel bus: a receiver more than before the firmware started (else: no way to tell).
    return kernel_receivers_before_ < 0 ||
           CountKernelCanReceivers(iface_) > kernel_receivers_before_;
  }
  bool connected = false;
  for (const auto& st : broker_->Stats()) {
    if (st.name != iface_) continue;
    connected = st.clients >= 2;
    // The run's own port is one bind, any other the firmware's: a socket bound and gone
    // between two looks (a firmware that opened the bus and died at once) still opened it.
    if (st.binds >= 2) opened_once_ = true;
  }
  return connected;
}

void FirmwareLink::KeepAlive(VirtualClock& clock) {
  clock.WakeDue();
  if (broker_ == nullptr) {
    bus::ReceivedFrame rx;
    while (!can_->Receive(rx, 0)) {
    }
  } else {
    if (!PumpBroker(0)) return;
    bus::CanFrame f;
    while (broker_->ReceiveLocal(local_port_, &f)) {
    }
  }
  clock.Blocked();  // the reference point of the wait below
  clock.WaitForChange(1000);
}

bool FirmwareLink::PumpBroker(int timeout_ms, bool quiet, std::size_t first_sent) {
  const std::uint64_t before = broker_->client_progress();
  const bool ok = first_sent != SIZE_MAX ? broker_->PumpFirstSent(first_sent)
                  : quiet                ? broker_->PumpQuiet()
                                         : broker_->Pump(timeout_ms);
  if (broker_->client_progress() != before) {
    broker_->TakeWokenClients(&woken_);
    if (clock_ != nullptr) {
      std::uint32_t channels = woken_.other ? bus::vtime::kAnyChannel : 0u;
      for (const std::uint32_t id : woken_.ids) channels |= bus::vtime::BusSocketChannel(id);
      clock_->NoteFdWakes(channels);
    }
  }
  return ok;
}

void FirmwareLink::UseVirtualClock(VirtualClock& clock) {
  clock_ = &clock;
  if (broker_) broker_->SetReceiveClock([&clock] { return clock.RealtimeNs(); });
}

bool FirmwareLink::Settle(VirtualClock& clock, double timeout_s, FirmwareProcess& process,
                          const FrameFn& on_frame) {
  // Blocked at the end of the last settle, nothing sent to it since and no deadline reached:
  // nothing can have woken it.
  const bool ended_waits = clock.WakeDue() > 0;
  if (!ended_waits && firmware_blocked_) return true;
  firmware_blocked_ = false;
  // After runahead: a pass takes what the firmware sent at its own instant; that is a turn of
  // its only if something wakes it.
  bool counted = !std::exchange(after_runahead_, false);
  if (counted) ++handovers_;
  auto turn = [&] {
    if (!counted) ++handovers_;
    counted = true;
  };
  double unaccounted = 0;
  sim::WallTimer timer(handover_s_ != nullptr ? *handover_s_ : unaccounted);
  // The limit is on running without blocking: a firmware that blocks and is woken again by
  // what it asked the bus for (a burst of socket opens, requests) makes progress, and starts
  // the count again; only a far longer stay at one instant ends the run as well.
  const auto settle_start = Clock::now();
  auto t0 = settle_start;
  bool checked_exit = false;
  auto exited = [&] {
    FailExited(process);
    return false;
  };
  // One broker pass; true when it wrote to a client (which may wake a firmware thread).
  // A pass looks at the broker's sockets only when the firmware did something there since the
  // last look (its frames travel in the rings), when a process of it is not on the clock, and
  // at least every kSocketLookEveryNs of virtual time (programs off the clock on the bus: a
  // candump the user attached).
  auto pass = [&] {
    if (broker_ == nullptr) {
      TakeKernelFrames(on_frame);
      return false;
    }
    const std::uint64_t before = broker_->client_progress();
    const std::uint64_t activity = clock.socket_activity();
    const bool quiet = activity == activity_at_look_ &&
                       clock.now_ns() - last_look_ns_ < kSocketLookEveryNs &&
                       clock.UnregisteredProcess() == 0;
    if (!quiet) {
      activity_at_look_ = activity;
      last_look_ns_ = clock.now_ns();
    }
    Pump(0, quiet);
    bus::CanFrame f;
    while (broker_->ReceiveLocal(local_port_, &f)) on_frame(f);
    return broker_->client_progress() != before;
  };
  // What the run sent since the last settle; if that reached the firmware, it runs now (and
  // cannot be blocked yet).
  // Waits it just ended run now as well: no look at the firmware can find it blocked yet.
  const bool sent = !to_kernel_.empty();
  if (sent) SendToKernel();
  bool woke = pass() || ended_waits || sent;
  for (;;) {
    if (run_.failed()) return false;
    if (!woke && clock.Blocked()) {
      // Every thread was blocked: frames written before that are in the broker's queues. If
      // routing them wakes nobody, the firmware stays blocked.
      if (pass()) {
        woke = true;
        turn();
        t0 = Clock::now();
        const double cap_s = std::max(kMinSecondsAtOneInstant, kTimeoutsAtOneInstant * timeout_s);
        if (WallSeconds(settle_start) > cap_s) {
          run_.Fail(fmt::format("the firmware kept the bus busy at one instant of virtual time "
                                "for {} s of wall time (each time it blocked, the bus woke it "
                                "again)",
                                cap_s));
          return false;
        }
        continue;
      }
      if (run_.failed()) return false;
      // A process that exits leaves threads the check finds gone: only then is it asked, and
      // given the time to finish exiting, so the exit is seen at this instant on every host.
      if (clock.TakeThreadsGone() && process.running()) {
        const auto gone_at = Clock::now();
        do {
          if (process.Exited()) return exited();
          std::this_thread::sleep_for(std::chrono::microseconds(200));
        } while (WallSeconds(gone_at) < 2.0);
      }
      firmware_blocked_ = true;
      return true;
    }
    turn();
    if (clock.FirmwareStopped()) {
      // A debugger has it (or it was stopped for one): no limit, and no hurry to look again.
      t0 = Clock::now();
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
      woke = false;  // the next round looks again
      continue;
    }
    if (!StillWaiting(clock, WallSeconds(t0), timeout_s, process, checked_exit)) return false;
    clock.WaitForChange(200);
    woke = false;
  }
}

void FirmwareLink::TakeKernelFrames(const FrameFn& on_frame) {
  // The run's frames went out in Send; the kernel may hand them over after its send returned
  // (its softirq, or ksoftirqd under load). The firmware has them once the run has its own
  // back, and may not be taken for blocked before. The firmware's frames, counted by its clock
  // library as it sends them, are waited for the same way.
  const auto t0 = Clock::now();
  bus::ReceivedFrame rx;
  for (;;) {
    while (!can_->Receive(rx, 0)) {
      if (rx.own) {
        if (unconfirmed_ > 0) --unconfirmed_;
      } else {
        ++kernel_frames_in_;
        on_frame(rx.frame);
      }
    }
    const std::uint64_t sent = clock_ != nullptr ? clock_->KernelCanSends() : 0;
    const std::uint64_t theirs_missing = sent > kernel_frames_in_ ? sent - kernel_frames_in_ : 0;
    if (unconfirmed_ == 0 && theirs_missing == 0) return;
    if (WallSeconds(t0) > kKernelDeliverySeconds) {
      run_.Fail(
          fmt::format("the kernel did not deliver {} frame(s) on {} within {} s ({} of the "
                      "run's own not back, {} of the firmware's sends not received)",
                      unconfirmed_ + theirs_missing, iface_, kKernelDeliverySeconds, unconfirmed_,
                      theirs_missing));
      unconfirmed_ = 0;
      return;
    }
    pollfd p{can_->fd(), POLLIN, 0};
    (void)::poll(&p, 1, 1);
  }
}

bool FirmwareLink::StillWaiting(VirtualClock& clock, double wall_s, double timeout_s,
                                FirmwareProcess& process, bool& checked_exit) {
  auto running_threads = [&] {
    std::string who;
    for (const auto& t : clock.RunningThreads()) who += (who.empty() ? "" : "; ") + t;
    return who;
  };
  if (wall_s > std::min(1.0, timeout_s / 2) && !checked_exit) {
    checked_exit = true;
    if (process.running() && process.Exited()) {
      FailExited(process);
      return false;
    }
    // Long before the limit: say who keeps virtual time from moving.
    run_.events.push_back(nlohmann::json{{"t_s", run_.MotionSeconds(run_.now_ns)},
                                         {"event", "firmware_busy"},
                                         {"wall_s", std::min(1.0, timeout_s / 2)},
                                         {"threads", running_threads()}});
  }
  if (wall_s <= timeout_s) return true;
  std::string who = running_threads();
  if (const pid_t p = clock.UnregisteredProcess(); p != 0) {
    who += fmt::format(
        "{}process {} ({}) is not on the virtual clock: it never loaded "
        "libwheelhil_vtime.so, or exec'd a program without it (a static "
        "binary, or LD_PRELOAD cleared: see docs/virtual-time.md)",
        who.empty() ? "" : "; ", p, VirtualClock::DescribeProcess(p));
  }
  run_.events.push_back(nlohmann::json{{"t_s", run_.MotionSeconds(run_.now_ns)},
                                       {"event", "firmware_not_blocking"},
                                       {"threads", who}});
  run_.Fail(
      fmt::format("the firmware did not block within {} s of wall time, so virtual "
                  "time could not go on: {} (a firmware that polls in a loop can run "
                  "with timing.spin_cost_s: docs/virtual-time.md)",
                  timeout_s, who.empty() ? "no thread seen running" : who));
  return false;
}

void FirmwareLink::TakeSent(std::size_t frames, const FrameFn& on_frame) {
  if (broker_ == nullptr || !pumped_ || frames == 0) return;
  (void)PumpBroker(0, true, frames);
  bus::CanFrame f;
  while (broker_->ReceiveLocal(local_port_, &f)) on_frame(f);
}

bool FirmwareLink::SendsReachOnlyTheRun() const {
  return broker_ != nullptr && pumped_ && broker_->FramesReachOnlyPorts();
}

bool FirmwareLink::Prepare(const bus::CanFrame& frame, std::int64_t instant_ns) {
  return broker_ != nullptr &&
         broker_->PrepareLocal(local_port_, frame, VirtualClock::kMonotonicAtStartNs + instant_ns);
}

bool FirmwareLink::RunAhead(VirtualClock& clock, double timeout_s, FirmwareProcess& process) {
  ++handovers_;
  double unaccounted = 0;
  sim::WallTimer timer(handover_s_ != nullptr ? *handover_s_ : unaccounted);
  const auto t0 = Clock::now();
  bool ok = true;
  bool checked_exit = false;
  // No broker pass meanwhile: what the firmware sends is taken at the instant it sent it,
  // once the run's bus is there. While the firmware holds the clock the host sleeps, and looks
  // at its threads (in the kernel) only every millisecond: the firmware wakes it when it gives
  // the clock back.
  auto last_look = t0;
  for (;;) {
    if (run_.failed()) {
      ok = false;
      break;
    }
    if (!clock.RunaheadGranted() || WallSeconds(last_look) > 1e-3) {
      last_look = Clock::now();
      if (clock.Blocked()) break;
    }
    if (!StillWaiting(clock, WallSeconds(t0), timeout_s, process, checked_exit)) {
      ok = false;
      break;
    }
    if (clock.RunaheadGranted()) {
      clock.WaitWhileGranted(1000);
    } else {
      clock.WaitForChange(200);
    }
  }
  (void)broker_->SettlePrepared();
  // What it sent is in its ring: the next settle, at its instant, takes it.
  firmware_blocked_ = false;
  after_runahead_ = true;
  return ok;
}

}  // namespace wheelhil::emulator::firmware
