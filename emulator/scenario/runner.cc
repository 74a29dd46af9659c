#include "emulator/scenario/runner.h"

#include <signal.h>
#include <sys/resource.h>

#include <algorithm>
#include <array>
#include <bitset>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>

#include <fmt/format.h>

#include "bus/canopen.h"
#include "bus/dbc.h"
#include "bus/ucan_protocol.h"
#include "bus/vector_logs.h"
#include "bus/vtime_protocol.h"
#include "emulator/devices/device.h"
#include "emulator/firmware/firmware_bus_watch.h"
#include "emulator/firmware/firmware_link.h"
#include "emulator/firmware/firmware_process.h"
#include "emulator/firmware/virtual_clock.h"
#include "emulator/firmware/wheelhil_fw_config.h"
#include "emulator/scenario/bus_forecast.h"
#include "emulator/scenario/device_registry.h"
#include "emulator/scenario/fault_plan.h"
#include "emulator/scenario/physics_stage.h"
#include "emulator/scenario/runahead_sends.h"
#include "emulator/scenario/timing_plan.h"
#include "emulator/scoring/artefacts.h"
#include "emulator/scoring/estimate_decoder.h"
#include "emulator/scoring/expectations.h"
#include "emulator/scoring/metric_components.h"
#include "emulator/scoring/run_artefacts.h"
#include "emulator/scoring/run_mcap.h"
#include "emulator/scoring/truth_recorder.h"
#include "emulator/sim/bus_hub.h"
#include "emulator/sim/cpu_placement.h"
#include "emulator/sim/cycle_scheduler.h"
#include "emulator/sim/event_loop.h"
#include "emulator/sim/run_context.h"
#include "emulator/sim/wall_account.h"

namespace wheelhil::emulator::scenario {

namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using Clock = std::chrono::steady_clock;

// CPU seconds (user + system) of the children this process has waited for.
double ChildrenCpuSeconds() {
  rusage ru{};
  ::getrusage(RUSAGE_CHILDREN, &ru);
  return static_cast<double>(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) +
         static_cast<double>(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec) * 1e-6;
}

double WallSeconds(Clock::time_point since) {
  return std::chrono::duration<double>(Clock::now() - since).count();
}

// libwheelhil_vtime.so: $WHEELHIL_VTIME_LIB, else next to the bus library the child preloads.
std::string VtimeLibrary(const std::vector<std::pair<std::string, std::string>>& env) {
  if (const char* lib = std::getenv("WHEELHIL_VTIME_LIB"); lib != nullptr && lib[0] != '\0') {
    return lib;
  }
  for (const auto& [key, value] : env) {
    if (key != "LD_PRELOAD") continue;
    const std::string first = value.substr(0, value.find(':'));
    return fs::path(first).parent_path().append("libwheelhil_vtime.so").string();
  }
  return "libwheelhil_vtime.so";
}

// One run: builds the stages, runs the phases of the event loop (its sources order the stages:
// emulator/sim/cycle_scheduler.h), scores and writes the result.
class Run final : public sim::RunStages, public sim::FirmwareGate {
 public:
  Run(const Scenario& s, const RunOptions& o) : s_(s), o_(o) {}
  RunResult Execute();

  // sim::RunStages
  std::int64_t step_ns() const override { return physics_->step_ns(); }
  bool StepPhysics(std::int64_t t_end_ns, bool motion) override {
    sim::WallTimer timer(wall_.physics_s);
    if (s_.firmware_motion) CommandDrives();
    const bool ok = physics_->Step(t_end_ns - physics_->step_ns(), motion);
    if (!log_on_run_thread_ && physics_->inline_from_ns() >= 0) {
      // The worker's CPUs are taken (it fell back): can.log comes back to this thread too.
      hub_->StopBackgroundLog();
      log_on_run_thread_ = true;
    }
    return ok;
  }
  void StepDevices(std::int64_t t_ns, bool motion) override;
  void RecordTruth(std::int64_t t_ns, bool force) override {
    truth_->Record(t_ns, physics_->body(), physics_->wheels(), force);
  }
  void AdvanceBus(std::int64_t t_ns) override {
    sim::WallTimer timer(wall_.devices_bus_s);
    hub_->AdvanceTo(t_ns);
  }
  std::int64_t bus_now_ns() const override { return hub_->now_ns(); }
  void SendSync(std::int64_t t_ns) override;
  void AfterMotionStep() override { Progress(false); }

  // sim::FirmwareGate: on the virtual clock the firmware runs until it blocks wherever real
  // time takes what it sent.
  void Drain() override {
    if (timing_.virtual_clock()) {
      SettleFirmware();
    } else {
      sim::WallTimer timer(wall_.handover_s);
      link_->Drain(0, [this](const bus::CanFrame& f) { OnFirmwareFrame(f); });
    }
  }
  void AfterLastCycle() override;

 private:
  void Build();
  // Closed loop: the drives' power stages onto their wheels, before each physics step.
  void CommandDrives();
  void StartFirmware();
  // Virtual clock: the firmware runs at the bus's instant until every thread of it is blocked.
  void SettleFirmware();
  // --check-runahead, after the settle of a turn at `now_ns` that handed the firmware
  // `handed` (the frames sent to it since the last turn).
  void CheckRunahead(std::int64_t now_ns, bool deadline_turn, bool firmware_sent, bool handed_over,
                     const std::vector<bus::CanFrame>& handed);
  // The forecast's frames before now_ns were all handed over, and `handed` (when given) are
  // its frames at now_ns; else the run fails (the reason names both).
  bool MatchForecast(std::int64_t now_ns, const std::vector<bus::CanFrame>* handed);
  // --runahead, after the turn at now_ns: the forecast, its frames in the firmware's rings,
  // the clock granted until the firmware gives it back (firmware_ahead_ns_).
  void RunAhead(std::int64_t now_ns);
  // --stop-at: stops the firmware's process group for a debugger and says how to attach.
  void StopFirmwareForDebugger();
  // Virtual clock: runs the firmware alone (its clock moving to its own deadlines) until it has
  // opened the bus.
  void StartFirmwareOnVirtualClock();
  void OnFirmwareFrame(const bus::CanFrame& f);
  void StartWorker(std::int64_t steps);
  void RunPhases();
  void Progress(bool final);
  json Report(double wall_s);
  // can.log again in the scenario's other formats (logs:), beside it.
  void WriteOtherLogs();
  std::uint64_t MotionCycles() const { return bus_watch_->syncs_sent() - syncs_before_motion_; }
  // The time of an estimate: since the motion start, negative before it (not scored).
  double ScoredSeconds(std::int64_t t_ns) const {
    return motion_started_ ? run_.MotionSeconds(t_ns) : -1.0;
  }

  const Scenario& s_;
  const RunOptions& o_;
  std::uint64_t seed_ = 1;
  TimingPlan timing_;  // which clock, who produces SYNC, which bus (ResolveTiming)
  // SYNCs before the motion phase (a SYNC-producing firmware's boot): not counted as cycles.
  std::uint64_t syncs_before_motion_ = 0;
  bool motion_started_ = false;
  std::string out_;
  sim::RunContext run_;
  sim::CpuPlacement cpus_;
  std::vector<std::unique_ptr<Device>> devices_;
  // Declared after the devices: a worker still stepping (a run left by an exception) is stopped
  // before the devices whose readings it takes go.
  std::unique_ptr<PhysicsStage> physics_;
  std::unique_ptr<sim::BusHub> hub_;
  std::unique_ptr<firmware::FirmwareLink> link_;
  std::unique_ptr<firmware::VirtualClock> clock_;
  firmware::FirmwareProcess firmware_;
  std::unique_ptr<firmware::FirmwareBusWatch> bus_watch_;
  std::unique_ptr<scoring::EstimateDecoder> estimates_;
  std::unique_ptr<scoring::TruthRecorder> truth_;
  std::unique_ptr<FaultPlan> faults_;
  std::vector<WheelDrive> drives_;  // scratch of CommandDrives
  Clock::time_point wall0_, last_progress_;
  sim::WallAccount wall_;
  // The CPU seconds of this process's waited-for children (RUSAGE_CHILDREN) before the
  // firmware started (-1: no firmware started); the firmware's own after its exit.
  double children_cpu_before_s_ = -1;
  double firmware_cpu_s_ = -1;
  // --physics-thread auto: when the run's thread took the steps back from the worker (-1: no).
  std::int64_t physics_inline_from_ns_ = -1;
  bool log_on_run_thread_ = false;    // can.log written here again after the worker fell back
  bool firmware_stopped_ = false;     // StopFirmwareForDebugger
  std::uint64_t progress_calls_ = 0;  // Progress(false)
  std::vector<bus::CandumpRecord> bus_log_;  // can.log read back for logs: (WriteOtherLogs)
  // Runahead (--check-runahead, --runahead): the forecast of the current window and how much
  // of it was matched; the frames sent to the firmware since the last turn; the firmware's
  // frames so far.
  std::unique_ptr<BusForecast> forecast_;
  // --runahead: where the firmware moved its clock in the current window (-1: no window); what
  // windows after the firmware's last frame of a turn (by its id) did last time.
  std::int64_t firmware_ahead_ns_ = -1;
  static constexpr std::size_t kRunaheadMaxFrames = 512;
  static constexpr std::int64_t kRunaheadMaxNs = 500'000'000;
  static constexpr std::uint32_t kNoFrameSent = 0xFFFFFFFFu;
  // --runahead on: a window costs the firmware's library about what three turns of the host's
  // do on an idle machine (the grant, the kick of its agent, its own doorbells, the wake of the
  // host at its end), so one that saves fewer turns makes the run slower. auto measures both.
  static constexpr std::size_t kRunaheadMinTurnsSaved = 4;
  double turn_wall_s_ = 0;  // a turn of the firmware's outside windows, wall s (moving average)
  double before_motion_s_ = -1;  // wall s from the run's start to its motion phase
  struct RunaheadHistory {
    std::uint32_t skip = 0;     // turns to let pass before the next try
    std::uint32_t backoff = 0;  // what `skip` becomes after another window that did not pay
    std::int64_t ran_ns = -1;  // how far the firmware ran last time (-1: unknown)
    // auto: wall s the last windows took beyond what the turns they saved would have; they
    // pay when the median is below 0, so one window slowed by the machine (preempted, a page
    // fault) does not stop the next.
    std::array<double, 5> excess_s{};
    std::size_t windows = 0;
    double MedianExcess() const {
      const std::size_t n = std::min(windows, excess_s.size());
      std::array<double, 5> sorted = excess_s;
      for (std::size_t i = 1; i < n; ++i) {  // insertion sort: five at most
        for (std::size_t j = i; j > 0 && sorted[j] < sorted[j - 1]; --j) {
          std::swap(sorted[j], sorted[j - 1]);
        }
      }
      return n % 2 == 1 ? sorted[n / 2] : 0.5 * (sorted[n / 2 - 1] + sorted[n / 2]);
    }
  };
  std::map<std::uint32_t, RunaheadHistory> runahead_history_;
  // --runahead: the firmware's periodic sends (foreseen in a window), the ids no device reads
  // (taken at the first window: the devices' configuration fixes them).
  SendPatterns send_patterns_;
  firmware::RunaheadSendPlan send_plan_;  // the current window's (kept: its vectors' room)
  // The instants of the sends the firmware made on its way through the current window, and
  // how many of them the run took so far.
  std::vector<std::int64_t> sent_through_at_;
  std::size_t sent_taken_ = 0;
  std::optional<std::bitset<2048>> unread_ids_;
  // The end of the last window, when it ran to its horizon (-1: it did not), and its key.
  std::int64_t horizon_end_ns_ = -1;
  std::uint32_t horizon_key_ = 0;
  std::uint32_t last_sent_id_ = kNoFrameSent;  // the firmware's latest frame, and its instant
  std::int64_t last_sent_at_ns_ = -1;
  const sim::SyncSource* sync_ = nullptr;  // the emulator's SYNCs (motion phase), if it makes them
  std::size_t forecast_matched_ = 0;
  std::vector<bus::CanFrame> to_firmware_;
  std::uint64_t firmware_frames_seen_ = 0;
  struct RunaheadCount {
    std::uint64_t windows = 0, frames = 0, turns_saved = 0, turns_added = 0;
    std::uint64_t ended_by_send = 0, ended_by_deadline = 0, ended_by_horizon = 0;
    std::uint64_t no_forecast = 0;  // turns after which no forecast could be made
  } runahead_;
};

void Run::CommandDrives() {
  drives_.clear();
  for (const auto& d : devices_) {
    for (const WheelDrive& w : d->wheel_drives()) drives_.push_back(w);
  }
  physics_->SetDrives(drives_);
}

void Run::SendSync(std::int64_t t_ns) {
  bus::CanFrame sync;
  sync.id = bus::canopen::kSyncCobId;
  sync.len = 0;
  hub_->EnqueueSync(sync, t_ns);
  estimates_->OnSync(run_.MotionSeconds(t_ns));
  bus_watch_->OnSyncSent();
}

void Run::AfterLastCycle() {
  // No answer is awaited: the firmware gets the last cycle's frames (at most one period of bus)
  // and runs until it blocks, or in real time has that period of wall time to send.
  const std::int64_t period_ns = std::llround(s_.timing.sync_period_s * 1e9);
  if (timing_.virtual_clock()) {
    const std::int64_t until = hub_->now_ns() + period_ns;
    while (!run_.failed() && hub_->now_ns() < until) {
      hub_->AdvanceTo(std::min(until, hub_->now_ns() + physics_->step_ns() / 2));
      SettleFirmware();
    }
    return;
  }
  const auto until = Clock::now() + std::chrono::nanoseconds(period_ns);
  hub_->AdvanceTo(hub_->now_ns() + period_ns);
  sim::WallTimer timer(wall_.handover_s);
  for (auto now = Clock::now(); now < until && !run_.failed(); now = Clock::now()) {
    const auto left_ms = std::chrono::duration_cast<std::chrono::milliseconds>(until - now);
    link_->Drain(std::max<int>(1, static_cast<int>(left_ms.count())),
                 [this](const bus::CanFrame& f) { OnFirmwareFrame(f); });
  }
}

void Run::StepDevices(std::int64_t t_ns, bool motion) {
  sim::WallTimer timer(wall_.devices_bus_s);
  StepDevicesAt(
      t_ns, physics_->step_ns(), motion, physics_->body(), physics_->wheels(),
      [this](std::size_t d) { return physics_->readings(d); }, devices_, *hub_, *faults_, run_);
  if (motion) truth_->RecordMotionStep(t_ns, physics_->wheels());
}

void Run::OnFirmwareFrame(const bus::CanFrame& f) {
  ++firmware_frames_seen_;
  last_sent_id_ = f.id;
  last_sent_at_ns_ = hub_->now_ns();
  if (o_.runahead != RunOptions::Runahead::kOff) send_patterns_.Note(f, hub_->now_ns());
  // Into the bus model at the current virtual instant (it is logged when it completes).
  hub_->EnqueueFromFirmware(f);
  if (timing_.firmware_produces_sync && f.id == bus::canopen::kSyncCobId && !f.rtr) {
    // The firmware is the SYNC producer: its SYNCs number the cycles.
    estimates_->OnSync(ScoredSeconds(hub_->now_ns()));
    bus_watch_->OnSyncSent();
  }
  bus_watch_->OnFirmwareFrame(f);
  if (motion_started_) estimates_->OnFrame(f, ScoredSeconds(hub_->now_ns()));
}

void Run::SettleFirmware() {
  if (run_.failed() || !firmware_.running()) return;
  if (o_.stop_firmware_at_ns >= 0 && !firmware_stopped_ &&
      hub_->now_ns() >= o_.stop_firmware_at_ns) {
    StopFirmwareForDebugger();
  }
  const std::int64_t now = hub_->now_ns();
  if (firmware_ahead_ns_ >= 0) {
    // In a window: the firmware was handed these frames from its rings, at this instant.
    const bool ok = MatchForecast(now, &to_firmware_);
    to_firmware_.clear();
    if (!ok) return;
    if (now < firmware_ahead_ns_) {
      // It is past this turn: what it sent here on its way is taken at this instant.
      std::size_t sent_here = 0;
      while (sent_taken_ < sent_through_at_.size() && sent_through_at_[sent_taken_] <= now) {
        ++sent_taken_;
        ++sent_here;
      }
      link_->TakeSent(sent_here, [this](const bus::CanFrame& f) { OnFirmwareFrame(f); });
      return;
    }
    // Its own turn: what it sent at its instant is taken here, as the turn goes on.
    firmware_ahead_ns_ = -1;
    forecast_.reset();
  }
  // --check-runahead only: a scan of the firmware's waits and timers at every turn.
  const bool deadline_turn = o_.check_runahead && clock_->NextDeadlineNs() <= now;
  const std::uint64_t sent_before = firmware_frames_seen_;
  const std::uint64_t handovers_before = link_->handovers();
  const double handover_s_before = wall_.handover_s;
  clock_->SetNow(now);
  link_->Settle(*clock_, s_.timing.timeout_s, firmware_,
                [this](const bus::CanFrame& f) { OnFirmwareFrame(f); });
  const bool turn = link_->handovers() != handovers_before;
  if (o_.check_runahead) {
    CheckRunahead(now, deadline_turn, firmware_frames_seen_ != sent_before, turn, to_firmware_);
  } else if (o_.runahead != RunOptions::Runahead::kOff && (turn || now == horizon_end_ns_)) {
    if (turn) {
      const double turn_s = wall_.handover_s - handover_s_before;  // the link times its turns
      turn_wall_s_ = turn_wall_s_ == 0 ? turn_s : 0.9 * turn_wall_s_ + 0.1 * turn_s;
    }
    // After a turn: a settle that found the firmware blocked with nothing for it (most steps)
    // leaves it where it is, and the next turn's window starts from there as well.
    RunAhead(now);
  }
  to_firmware_.clear();
  // What runs on the host's clock: the run goes on, but may not be deterministic.
  auto warn = [this](const char* event, const std::vector<std::string>& found) {
    for (const std::string& what : found) {
      run_.events.push_back(
          json{{"t_s", run_.MotionSeconds(run_.now_ns)}, {"event", event}, {"detail", what}});
      fmt::print(stderr, "wheelhil run: warning: {}\n", what);
    }
  };
  warn("firmware_host_clock_wait", clock_->TakeHostClockWaits());
  warn("firmware_off_the_clock", clock_->TakeProcessesOffTheClock());
}

bool Run::MatchForecast(std::int64_t now_ns, const std::vector<bus::CanFrame>* handed) {
  auto frame_text = [](const bus::CanFrame& f) {
    std::string line = bus::FormatCandumpLine(0, "", f);
    return line.substr(line.find(' ') + 2);  // "ID#DATA" without the time and interface
  };
  auto mismatch = [&](const std::string& what) {
    run_.Fail(fmt::format("runahead check at t = {:.6f} s (bus time): {}",
                          static_cast<double>(now_ns) * 1e-9, what));
    forecast_.reset();
    return false;
  };
  const auto& fc = forecast_->frames();
  std::size_t& m = forecast_matched_;
  if (m < fc.size() && fc[m].t_ns < now_ns) {
    return mismatch(
        fmt::format("the forecast had {} at t = {:.6f} s; the run did not hand it "
                    "over then",
                    frame_text(fc[m].frame), static_cast<double>(fc[m].t_ns) * 1e-9));
  }
  if (handed == nullptr) return true;
  for (const bus::CanFrame& f : *handed) {
    if (m >= fc.size() || fc[m].t_ns != now_ns || !(fc[m].frame == f)) {
      return mismatch(
          fmt::format("the run handed the firmware {}; the forecast had {}", frame_text(f),
                      m >= fc.size() ? std::string("nothing more")
                                     : fmt::format("{} at t = {:.6f} s", frame_text(fc[m].frame),
                                                   static_cast<double>(fc[m].t_ns) * 1e-9)));
    }
    ++m;
    ++runahead_.frames;
  }
  if (m < fc.size() && fc[m].t_ns == now_ns) {
    return mismatch(fmt::format("the forecast had {} as well; the run did not hand it over",
                                frame_text(fc[m].frame)));
  }
  return true;
}

void Run::CheckRunahead(std::int64_t now_ns, bool deadline_turn, bool firmware_sent,
                        bool handed_over, const std::vector<bus::CanFrame>& handed) {
  if (forecast_) {
    if (!MatchForecast(now_ns, nullptr)) return;
    const char* end = nullptr;
    if (deadline_turn && now_ns != run_.now_ns) {
      // A deadline of the firmware's between two steps: the bus moves on to it (its frames
      // then complete at other instants), so the library yields at it.
      end = "deadline";
    } else if (now_ns > forecast_->reached_ns()) {
      end = "horizon";
    } else {
      if (!MatchForecast(now_ns, &handed)) return;
      end = firmware_sent ? "send" : now_ns == forecast_->reached_ns() ? "horizon" : nullptr;
      if (end == nullptr) {
        // The firmware ran on through this turn's frames: no hand-over.
        if (handed_over) ++runahead_.turns_saved;
        return;
      }
    }
    // The window ends with a hand-over; the run made one here unless the forecast ran out.
    if (!handed_over) ++runahead_.turns_added;
    const std::string_view e(end);
    ++(e == "send"       ? runahead_.ended_by_send
       : e == "deadline" ? runahead_.ended_by_deadline
                         : runahead_.ended_by_horizon);
    ++runahead_.windows;
    forecast_.reset();
  }
  if (run_.failed() || !motion_started_ || !physics_->worker_used()) return;
  // The next window: up to the emulator's next SYNC (its step comes first) and half a second.
  // A deadline of the firmware's at a step's end takes its turn with the step's frames (the
  // window runs on through it); one between two steps ends the window when it comes.
  std::int64_t until = now_ns + 500'000'000;
  if (sync_ != nullptr) until = std::min(until, sync_->NextEventNs());
  forecast_ = std::make_unique<BusForecast>(*hub_, devices_, run_, physics_->step_ns());
  forecast_matched_ = 0;
  (void)forecast_->RunTo(until, *physics_, *faults_);
  if (forecast_->reached_ns() == run_.now_ns) {
    ++runahead_.no_forecast;
    forecast_.reset();
  }
}

void Run::RunAhead(std::int64_t now_ns) {
  // A kernel bus has no rings to put frames ahead in, and the firmware's waits on its sockets
  // are the kernel's: it could move its clock through nothing.
  if (run_.failed() || !motion_started_ || !physics_->worker_used() || sync_ != nullptr ||
      !link_->private_bus() || !firmware_.running() || firmware_stopped_) {
    return;
  }
  // What the firmware sent in this turn says how long its next run through frames will be: a
  // window after the same frame of its (its SYNC, which the devices answer at once) that did
  // not pay last time is not made again for the next 16 such turns, then 32, ... 1024 while it
  // keeps not paying, to follow a firmware or a load that changes. Turns without a frame of its
  // share one history. A window pays (auto) when it took less wall time, its forecast and its
  // last turn included, than the turns it saved (the instants the firmware moved its clock to
  // itself: frames and its own deadlines) and that last turn would have taken; with --runahead
  // on, when it ran through frames of kRunaheadMinTurnsSaved instants.
  // A window that ran to its horizon goes on with the next, as one window would.
  const bool goes_on = now_ns == horizon_end_ns_;
  const std::uint32_t key = goes_on                      ? horizon_key_
                            : last_sent_at_ns_ == now_ns ? last_sent_id_
                                                         : kNoFrameSent;
  horizon_end_ns_ = -1;
  RunaheadHistory& history = runahead_history_[key];
  if (history.skip > 0 && !goes_on) {
    --history.skip;
    return;
  }
  const auto window_start = Clock::now();
  const std::uint64_t advances_before = clock_->local_advances();
  std::int64_t until = 0;
  bool sends_through = false;
  {
    sim::WallTimer timer(wall_.forecast_s);
    forecast_ = std::make_unique<BusForecast>(*hub_, devices_, run_, physics_->step_ns());
    forecast_matched_ = 0;
    // A quarter further than the firmware ran after the same frame last time (the work beyond
    // where it sends is lost), half a second or 512 frames (the rings hold 1024) at most.
    const std::int64_t step = physics_->step_ns();
    const std::int64_t span =
        history.ran_ns < 0
            ? kRunaheadMaxNs
            : std::min(kRunaheadMaxNs, history.ran_ns + history.ran_ns / 4 + 8 * step);
    // The sends of its own it may make on its way (runahead_sends.h): what reaches the run
    // alone, through the bus.
    sends_through = link_->SendsReachOnlyTheRun();
    if (sends_through) {
      send_plan_.foreseen =
          send_patterns_.Foresee(now_ns, now_ns + span, step, bus::vtime::kMaxForeseenSends);
    } else {
      send_plan_.foreseen.clear();
    }
    (void)forecast_->RunTo(now_ns + span, *physics_, *faults_, kRunaheadMaxFrames,
                           send_plan_.foreseen);
    send_plan_.gaps.clear();
    send_plan_.bit_ns = 0;
    if (sends_through && hub_->faulty_bus() == nullptr) {
      if (!unread_ids_) unread_ids_ = UnreadStandardIds(devices_);
      send_plan_.unread_ids = *unread_ids_;
      send_plan_.gaps_first_ns = now_ns;
      send_plan_.gaps = forecast_->SendGaps(now_ns, step);
      send_plan_.bit_ns = hub_->bit_time_ns();
    }
    // Its frames into the firmware's rings, up to the first that cannot go there (then none
    // of its instant: the firmware stops before it).
    until = forecast_->reached_ns();
    // --stop-at: the firmware stops for its debugger at that instant, not past it.
    if (o_.stop_firmware_at_ns >= 0) until = std::min(until, o_.stop_firmware_at_ns - 1);
    for (const ForecastFrame& f : forecast_->frames()) {
      if (!link_->Prepare(f.frame, f.t_ns)) {
        until = f.t_ns - 1;
        break;
      }
    }
  }
  if (until <= now_ns) {
    (void)link_->RunAheadDropPrepared();
    forecast_.reset();
    return;
  }
  clock_->GrantRunahead(until, physics_->step_ns(), run_.now_ns,
                        sends_through ? &send_plan_ : nullptr);
  if (!clock_->KickRunahead()) {
    clock_->RevokeRunahead();
    (void)link_->RunAheadDropPrepared();
    forecast_.reset();
    return;
  }
  if (!link_->RunAhead(*clock_, s_.timing.timeout_s, firmware_)) return;
  ++runahead_.windows;
  firmware_ahead_ns_ = clock_->now_ns();
  clock_->TakeSendsThroughAt(sent_through_at_);
  sent_taken_ = 0;
  // The turns it saved: the instants of frames it ran through before the one it stopped at
  // (there the run takes its turn as ever).
  std::size_t turns_saved = 0;
  std::int64_t last_instant = now_ns;
  for (const ForecastFrame& f : forecast_->frames()) {
    if (f.t_ns > firmware_ahead_ns_) break;
    if (f.t_ns < firmware_ahead_ns_ && f.t_ns != last_instant) ++turns_saved;
    last_instant = f.t_ns;
  }
  RunaheadHistory& after = runahead_history_[key];
  const double excess_s =
      WallSeconds(window_start) -
      static_cast<double>(clock_->local_advances() - advances_before + 1) * turn_wall_s_;
  after.excess_s[after.windows++ % after.excess_s.size()] = excess_s;
  const bool paid = o_.runahead == RunOptions::Runahead::kOn ? turns_saved >= kRunaheadMinTurnsSaved
                                                             : after.MedianExcess() < 0;
  if (!paid) {
    after.backoff = std::min<std::uint32_t>(1024, after.backoff == 0 ? 16 : 2 * after.backoff);
    after.skip = after.backoff;
  } else {
    after.backoff = 0;
  }
  runahead_history_[key].ran_ns = firmware_ahead_ns_ - now_ns;
  if (firmware_ahead_ns_ == until && paid) {
    horizon_end_ns_ = until;
    horizon_key_ = key;
  }
  if (firmware_ahead_ns_ <= now_ns) {
    firmware_ahead_ns_ = -1;
    forecast_.reset();
  }
}

void Run::StopFirmwareForDebugger() {
  firmware_stopped_ = true;
  const pid_t pid = firmware_.pid();
  ::kill(-pid, SIGSTOP);
  const double t_s = static_cast<double>(hub_->now_ns()) * 1e-9;
  run_.events.push_back(json{{"t_s", run_.MotionSeconds(run_.now_ns)},
                             {"event", "firmware_stopped"},
                             {"pid", pid},
                             {"bus_time_s", t_s}});
  fmt::print(
      stderr,
      "wheelhil run: the firmware (pid {}) is stopped at t = {:.6f} s of virtual time (can.log's "
      "clock); virtual time waits for it. Attach: gdb -p {} -ex 'handle SIG64 nostop "
      "noprint pass' (the virtual clock's wake-up signal), then continue; or let it go "
      "on without a debugger: kill -CONT -{}\n",
      pid, t_s, pid, pid);
  if (o_.on_firmware_stopped) o_.on_firmware_stopped(pid);
}

void Run::StartFirmwareOnVirtualClock() {
  const std::int64_t limit_ns = std::llround(10e9);
  for (;;) {
    SettleFirmware();
    if (run_.failed() || link_->FirmwareConnected()) return;
    const std::int64_t next = clock_->NextDeadlineNs();
    if (next == sim::kNever || next > limit_ns) {
      run_.Fail(fmt::format("the firmware did not open {} within 10 s of virtual time (it {})",
                            link_->interface(),
                            next == sim::kNever ? "blocked with no deadline" : "kept sleeping"));
      return;
    }
    run_.now_ns = next;
    hub_->AdvanceTo(next);
  }
}

void Run::Build() {
  physics_ = std::make_unique<PhysicsStage>(s_, seed_, run_);
  devices_ = BuildScenarioDevices(
      DeviceBuildContext{s_, seed_, o_.dbc_dir, physics_->vehicle().wheel_truth()});
  auto fw_dbc = std::make_shared<const bus::DbcDatabase>(
      bus::DbcDatabase::LoadFile(o_.dbc_dir + "/wheelhil_fw.dbc"));
  CanBusConfig bc;
  bc.bitrate_bps = s_.sensors.bitrate_bps;
  hub_ = std::make_unique<sim::BusHub>(bc, devices_, run_);
  link_ = std::make_unique<firmware::FirmwareLink>(o_.can_iface, timing_.pacing(), run_);
  if (timing_.virtual_clock()) {
    clock_ = std::make_unique<firmware::VirtualClock>(link_->runtime_dir());
    clock_->SetSpinCost(std::llround(s_.timing.spin_cost_s * 1e9));
    clock_->SetSharesCpu(cpus_.cpu() >= 0);
    link_->UseVirtualClock(*clock_);
    link_->AccountHandoversIn(wall_.handover_s);
  }
  if (link_->private_bus() && o_.on_private_bus) {
    o_.on_private_bus(link_->interface(), link_->runtime_dir());
  }
  hub_->OpenLog(out_ + "/can.log", link_->interface());
  hub_->SetFirmwareSend([this](const bus::CanFrame& f) {
    if (o_.check_runahead || o_.runahead != RunOptions::Runahead::kOff) to_firmware_.push_back(f);
    // The firmware got the frames of its window up to its own clock from its rings.
    if (firmware_ahead_ns_ >= 0 && run_.now_ns <= firmware_ahead_ns_) return true;
    return link_->Send(f);
  });
  bus_watch_ = std::make_unique<firmware::FirmwareBusWatch>(fw_dbc, *hub_, run_);
  hub_->SetObserver(bus_watch_.get());
  estimates_ = std::make_unique<scoring::EstimateDecoder>(
      s_.firmware.outputs ? scoring::OutputBinding::Resolve(*s_.firmware.outputs, o_.dbc_dir)
                          : scoring::OutputBinding());
  scoring::TruthRecorderOptions to;
  to.drive_wheels = s_.platform.drive_wheels;
  to.slip_threshold_m_s = s_.slip_threshold_m_s;
  to.every_ns = std::min<std::int64_t>(10'000'000, std::llround(s_.timing.sync_period_s * 1e9));
  to.step_ns = physics_->step_ns();
  truth_ = std::make_unique<scoring::TruthRecorder>(to);
  faults_ = std::make_unique<FaultPlan>(s_, seed_, o_.dbc_dir);
}

void Run::StartFirmware() {
  std::string why;
  if (s_.firmware.command.empty()) {
    if (link_->private_bus() && !link_->WaitForConnection(firmware_, s_.timing.timeout_s, why)) {
      run_.Fail("no firmware attached: " + why);
    }
    return;
  }
  std::string cmd = s_.firmware.command;
  if (!s_.firmware.config.empty()) {
    // The firmware's own config with the scenario's overrides, nothing else.
    const std::string cfg_path = fs::absolute(out_ + "/firmware_config.yaml").string();
    scoring::WriteText(cfg_path, firmware::DerivedWheelhilFwConfig(s_.firmware.config,
                                                                   s_.firmware.overrides_yaml));
    cmd = firmware::Substitute(cmd, "${CONFIG}", cfg_path);
  }
  cmd = firmware::Substitute(firmware::Substitute(cmd, "${CAN}", link_->interface()), "${BIN}",
                             o_.bin_dir);
  cmd = firmware::Substitute(cmd, "${SCENARIO_DIR}",
                             fs::absolute(s_.source_path).parent_path().string());
  std::vector<std::pair<std::string, std::string>> env;
  if (link_->private_bus() && o_.ucan_child_env) env = o_.ucan_child_env(link_->runtime_dir());
  env.emplace_back("WHEELHIL_DBC_DIR", o_.dbc_dir);
  // Runahead: the firmware's sockets get their own doorbell (bus/ucan_protocol.h).
  if (timing_.virtual_clock() && o_.runahead != RunOptions::Runahead::kOff)
    env.emplace_back(bus::ucan::kOwnBellEnv, "1");
  if (timing_.virtual_clock()) {
    // The clock's library goes first: the bus library's own waits are then virtual too. On a
    // kernel bus it is the only one, found where the bus library would be.
    const std::string lib = link_->private_bus() || !o_.ucan_child_env
                                ? VtimeLibrary(env)
                                : VtimeLibrary(o_.ucan_child_env(link_->runtime_dir()));
    if (!fs::exists(lib)) {
      throw std::invalid_argument(
          fmt::format("timing.clock: virtual: {} not found (build target wheelhil_vtime)", lib));
    }
    bool preloaded = false;
    for (auto& [key, value] : env) {
      if (key != "LD_PRELOAD") continue;
      value = lib + ":" + value;
      preloaded = true;
    }
    if (!preloaded) env.emplace_back("LD_PRELOAD", lib);
    for (auto& kv : clock_->ChildEnvironment(lib)) env.push_back(kv);
    if (const std::string why_not = firmware::WhyNotVirtualClock(cmd); !why_not.empty()) {
      throw std::invalid_argument(
          fmt::format("{}: timing.clock: virtual: {}", s_.source_path, why_not));
    }
    clock_->ExpectFirstProcess();
  }
  link_->BeforeFirmwareStarts();
  children_cpu_before_s_ = ChildrenCpuSeconds();
  firmware_.Start(cmd, env, out_ + "/firmware.log");
  if (timing_.virtual_clock()) {
    clock_->SetFirstProcessPid(firmware_.pid());
    StartFirmwareOnVirtualClock();
    return;
  }
  if (!link_->WaitForConnection(firmware_, s_.timing.timeout_s, why)) run_.Fail(why);
}

void Run::StartWorker(std::int64_t steps) {
  using PT = RunOptions::PhysicsThread;
  if (o_.physics_thread == PT::kOff || steps <= 0) return;
  cpu_set_t others;
  const bool have_others = cpus_.OtherCpus(&others);
  if (o_.physics_thread == PT::kAuto && !have_others) return;
  if (CPU_COUNT(&others) == 0) CPU_SET(cpus_.cpu() >= 0 ? cpus_.cpu() : 0, &others);  // kOn
  const cpu_set_t* where = cpus_.cpu() >= 0 || o_.physics_thread == PT::kOn ? &others : nullptr;
  physics_->StartWorker(steps, where, devices_, o_.physics_thread == PT::kAuto);
  // The lines of the frames from here on are formatted there as well.
  hub_->StartBackgroundLog(where);
}

void Run::RunPhases() {
  sim::LockstepWait lockstep_wait;
  sim::RealtimeWait realtime_wait;
  sim::EventLoop loop(run_, timing_.lockstep() ? static_cast<sim::WaitPolicy&>(lockstep_wait)
                                               : static_cast<sim::WaitPolicy&>(realtime_wait));
  sim::StepSource tick(*this, *this, run_);
  // On the virtual clock the firmware's own deadlines are instants of every phase.
  sim::FirmwareDeadlineSource firmware_deadlines(
      *this, *this, [this] { return clock_ ? clock_->NextDeadlineNs() : sim::kNever; });
  auto sources = [&](std::vector<sim::EventSource*> v) {
    if (timing_.virtual_clock()) v.push_back(&firmware_deadlines);
    return v;
  };
  auto steps_done = [&] { return tick.NextEventNs() == sim::kNever; };

  // Boot: the nodes boot, the firmware configures and starts them.
  const std::int64_t boot_limit_ns = std::llround(10e9);
  tick.Start({.motion = false, .record_truth = true, .steps = -1});
  loop.Run({"boot", sources({&tick}), [&] {
              if (run_.now_ns > boot_limit_ns) {
                std::string waiting;
                for (const auto& d : devices_) {
                  if (!d->Ready()) waiting += (waiting.empty() ? "" : ", ") + d->name();
                }
                run_.Fail(
                    fmt::format("the CANopen nodes were not started (NMT start) within 10 s "
                                "of virtual time: {}",
                                waiting.empty() ? "every node waits for the firmware's "
                                                  "SDO/NMT answer"
                                                : waiting));
              }
              return std::all_of(devices_.begin(), devices_.end(),
                                 [](const auto& d) { return d->Ready(); }) &&
                     bus_watch_->awaiting_nodes().empty();
            }});

  // Settle: the vehicle at rest on its suspension defines the start.
  tick.Start({.motion = false,
              .record_truth = false,
              .steps = std::llround(0.2e9) / physics_->step_ns() +
                       (std::llround(0.2e9) % physics_->step_ns() != 0 ? 1 : 0)});
  loop.Run({"settle", sources({&tick}), steps_done});

  // Motion: SYNC every period; lockstep waits for the firmware's status of each cycle. A run
  // that failed before still gets its motion origin here (sim_time_s 0 in its report).
  const std::int64_t step_ns = physics_->step_ns();
  const std::int64_t period_ns = std::llround(s_.timing.sync_period_s * 1e9);
  const std::int64_t steps_per_cycle = period_ns / step_ns;
  const std::int64_t cycles = std::llround(s_.timing.duration_s * 1e9) / period_ns;
  run_.motion0_ns = run_.now_ns;
  run_.motion0_s = static_cast<double>(run_.now_ns) * 1e-9;
  motion_started_ = true;
  before_motion_s_ = WallSeconds(wall0_);
  syncs_before_motion_ = bus_watch_->syncs_sent();
  physics_->StartMotion(run_.now_ns);
  truth_->StartMotion(run_.now_ns, physics_->vehicle().body_truth());
  // Its bus time (can.log's clock) aligns can.log with truth.csv.
  run_.events.push_back(
      json{{"t_s", 0.0}, {"event", "motion_start"}, {"bus_time_s", run_.motion0_s}});
  faults_->Arm(run_.now_ns, devices_, *hub_);
  // Closed loop: the physics depends on the bus, so it cannot run ahead.
  if (timing_.lockstep() && !run_.failed() && !s_.firmware_motion)
    StartWorker(cycles * steps_per_cycle);
  tick.Start({.motion = true, .record_truth = true, .steps = cycles * steps_per_cycle});
  sim::SyncSource sync(*this, *this, run_, tick, run_.now_ns, steps_per_cycle * step_ns, cycles);
  if (timing_.firmware_produces_sync) {
    loop.Run({"motion", sources({&tick}), steps_done});
  } else {
    sync_ = &sync;
    loop.Run({"motion", sources({&tick, &sync}),
              [&] { return steps_done() && sync.NextEventNs() == sim::kNever; }});
  }
}

void Run::Progress(bool final) {
  const bool lines = !o_.progress && o_.progress_lines_s > 0;
  if (!o_.progress && !lines) return;
  if (lines && final) return;  // the summary follows
  // A clock read per step costs as much as a step's bus model: every 64th step is often enough.
  if (!final && (++progress_calls_ % 64 != 0 ||
                 WallSeconds(last_progress_) < (lines ? o_.progress_lines_s : 0.2))) {
    return;
  }
  last_progress_ = Clock::now();
  const double sim = run_.MotionSeconds(run_.now_ns);
  const double wall = WallSeconds(wall0_);
  fmt::print(stderr, "{}{}: t = {:7.2f} / {:.2f} s  cycle {:6}  {:7.1f}x real time{}",
             lines ? "" : "\r", s_.name, std::max(0.0, sim), s_.timing.duration_s,
             MotionCycles(), wall > 0 ? std::max(0.0, sim) / wall : 0.0,
             final || lines ? "\n" : "");
}

void Run::WriteOtherLogs() {
  if (s_.log_formats.empty()) return;
  try {
    // can.log is the bus log's one record (formatted as the frames completed): read once, for
    // every other format and run.mcap.
    bus_log_ = bus::ReadCanLog(out_ + "/can.log", bus::CanLogFormat::kCandump);
    for (const std::string& format : s_.log_formats) {
      if (format == "mcap") continue;  // after the scoring it also holds
      bus::WriteCanLog(out_ + "/can." + format,
                       format == "asc" ? bus::CanLogFormat::kAsc : bus::CanLogFormat::kBlf,
                       bus_log_);
    }
  } catch (const std::invalid_argument& e) {
    run_.Fail(fmt::format("the bus log in the formats of logs: {}", e.what()));
  }
}

json Run::Report(double wall_s) {
  json r;
  r["scenario"] = s_.name;
  r["seed"] = seed_;
  const double sim = std::max(0.0, run_.MotionSeconds(run_.now_ns));
  r["sim_time_s"] = sim;
  r["cycles"] = MotionCycles();
  r["sync_period_s"] = s_.timing.sync_period_s;
  json metrics = json::object();
  std::vector<std::string> wheel_names;
  for (const auto& w : s_.platform.vehicle.wheels) wheel_names.push_back(w.name);
  scoring::RecordedRun recorded{*truth_, *estimates_, s_.timing.sync_period_s, wheel_names,
                                scoring::SlipIntervals(*truth_), std::nullopt, false, {}};
  if (s_.firmware_motion && s_.firmware_motion->goal) {
    const Eigen::Vector3d& g = *s_.firmware_motion->goal;
    recorded.goal = scoring::PoseSample{0.0, g.x(), g.y(), g.z()};
    recorded.goal_has_heading = s_.firmware_motion->goal_has_heading;
  }
  recorded.run_events = run_.events;
  scoring::ScoreRun(recorded, s_.metric_components, metrics, run_.events);
  metrics["bus"] = hub_->Metrics();
  if (auto f = faults_->Metrics(devices_, *hub_)) metrics["faults"] = *f;
  r["metrics"] = metrics;
  // Where the wall time went (docs/performance.md, "Reading a run's wall block").
  const double virtual_s = static_cast<double>(run_.now_ns) * 1e-9;
  const std::uint64_t handovers = link_ ? link_->handovers() : 0;
  const double staged_s =
      wall_.physics_s + wall_.devices_bus_s + wall_.handover_s + wall_.forecast_s;
  r["wall"] = json{
      {"wall_time_s", wall_s},
      {"real_time_factor", wall_s > 0 ? sim / wall_s : 0.0},
      {"cpu", cpus_.cpu()},
      {"physics_thread", physics_->worker_used()},
      {"physics_inline_from_s",
       physics_inline_from_ns_ >= 0 ? json(run_.MotionSeconds(physics_inline_from_ns_)) : json()},
      {"virtual_s", virtual_s},
      {"before_motion_s", before_motion_s_ >= 0 ? json(before_motion_s_) : json()},
      {"handovers", handovers},
      {"handovers_per_sim_s", virtual_s > 0 ? handovers / virtual_s : 0.0},
      {"handover_s", wall_.handover_s},
      {"handover_us_each", handovers > 0 ? wall_.handover_s / handovers * 1e6 : 0.0},
      {"firmware_cpu_s", firmware_cpu_s_ >= 0 ? json(firmware_cpu_s_) : json()},
      {"kernel_looks", clock_ ? json(clock_->kernel_looks()) : json()},
      {"blocked_seen_in_kernel", clock_ ? json(clock_->blocked_seen_in_kernel()) : json()},
      {"physics_s", wall_.physics_s},
      {"devices_bus_s", wall_.devices_bus_s},
      {"forecast_s", wall_.forecast_s},
      {"other_s", std::max(0.0, wall_s - staged_s)}};
  if (o_.runahead != RunOptions::Runahead::kOff && clock_) {
    r["wall"]["runahead"] = json{{"mode", o_.runahead == RunOptions::Runahead::kOn ? "on" : "auto"},
                                 {"windows", runahead_.windows},
                                 {"frames_run_through", runahead_.frames},
                                 {"local_advances", clock_->local_advances()},
                                 {"sends_through", clock_->sends_through()}};
  }
  if (o_.check_runahead) {
    // Hand-overs with runahead: every one of the run's but those of the turns a window ran
    // through, plus one at each window's end that was no hand-over of the run's.
    const std::uint64_t with_runahead = handovers - runahead_.turns_saved + runahead_.turns_added;
    r["wall"]["runahead_check"] =
        json{{"handovers", with_runahead},
             {"handovers_per_sim_s", virtual_s > 0 ? with_runahead / virtual_s : 0.0},
             {"windows", runahead_.windows},
             {"frames_run_through", runahead_.frames},
             {"ended_by_send", runahead_.ended_by_send},
             {"ended_by_deadline", runahead_.ended_by_deadline},
             {"ended_by_horizon", runahead_.ended_by_horizon},
             {"turns_without_forecast", runahead_.no_forecast}};
  }
  return r;
}

RunResult Run::Execute() {
  seed_ = o_.seed.value_or(s_.seed);
  out_ = o_.out_dir;
  std::error_code ec;
  fs::create_directories(out_, ec);
  if (ec || !fs::is_directory(out_)) {
    throw std::invalid_argument(fmt::format("--out {}: cannot create the directory", out_));
  }
  if (!fs::exists(o_.dbc_dir + "/wheelhil_fw.dbc")) {
    throw std::invalid_argument(
        fmt::format("no DBC files in '{}' (set WHEELHIL_DBC_DIR)", o_.dbc_dir));
  }
  timing_ = ResolveTiming(TimingChoice{s_.timing, s_.source_path, o_.realtime, o_.can_iface,
                                       !s_.firmware.command.empty()});
  if (o_.stop_firmware_at_ns >= 0 && !timing_.virtual_clock()) {
    throw std::invalid_argument(fmt::format(
        "{}: --stop-at stops the firmware on the virtual clock, which this run does not have "
        "(it needs lockstep, the private bus and a firmware.command)",
        s_.source_path));
  }
  if (timing_.lockstep()) cpus_.ConfineToOneCpu(o_.cpu);
  wall0_ = Clock::now();
  last_progress_ = wall0_;
  Build();
  run_.events.push_back(
      json{{"t_s", 0.0},
           {"event", "run_start"},
           {"seed", seed_},
           {"lockstep", timing_.lockstep()},
           {"clock", timing_.clock_name()},
           {"sync_producer", timing_.firmware_produces_sync ? "firmware" : "emulator"},
           {"bus", o_.can_iface.empty() ? "ucan" : "socketcan"}});
  StartFirmware();
  RunPhases();

  physics_inline_from_ns_ = physics_->inline_from_ns();
  physics_->StopWorker();  // a failed run leaves it steps ahead
  Progress(true);
  hub_->DrainToLog();
  const double wall_s = WallSeconds(wall0_);
  faults_->FlushEvents(run_);
  if (timing_.virtual_clock()) {
    // The run is recorded; the firmware's clock goes on (deadline to deadline) until it exits.
    firmware_.Stop([this] {
      if (const std::int64_t next = clock_->NextDeadlineNs(); next != sim::kNever) {
        clock_->SetNow(next);
      }
      link_->KeepAlive(*clock_);
    });
  } else {
    firmware_.Stop();
  }
  if (children_cpu_before_s_ >= 0) firmware_cpu_s_ = ChildrenCpuSeconds() - children_cpu_before_s_;
  hub_->CloseLog();
  WriteOtherLogs();
  run_.TakeInterrupt();
  if (run_.failed()) {
    run_.events.push_back(json{
        {"t_s", run_.MotionSeconds(run_.now_ns)}, {"event", "failure"}, {"reason", run_.failure}});
  }
  json report = Report(wall_s);
  json expectations = json::array();
  const bool all_ok =
      scoring::EvaluateExpectations(s_.expectations, report["metrics"], expectations);
  report["expectations"] = expectations;
  const bool passed = all_ok && !run_.failed();
  report["verdict"] = passed ? "pass" : "fail";
  if (run_.failed()) report["failure"] = run_.failure;
  scoring::ReplayRobot robot;
  robot.half_length_m = s_.platform.vehicle.half_extents_m.x();
  robot.half_width_m = s_.platform.vehicle.half_extents_m.y();
  robot.bus_bitrate_bps = s_.sensors.bitrate_bps;
  for (std::size_t w = 0; w < s_.platform.vehicle.wheels.size(); ++w) {
    const auto& spec = s_.platform.vehicle.wheels[w];
    const auto& drives = s_.platform.drive_wheels;
    const auto it = std::find(drives.begin(), drives.end(), w);
    robot.wheels.push_back({spec.name, spec.mount_B.x(), spec.mount_B.y(), spec.radius_m,
                            it == drives.end() ? -1 : static_cast<int>(it - drives.begin())});
  }
  scoring::WriteRunArtefacts(out_, report, *truth_, *estimates_, run_.events, robot);
  RunResult result;
  result.report = report;
  result.failure = run_.failure;
  result.exit_code = passed ? 0 : 1;
  if (std::find(s_.log_formats.begin(), s_.log_formats.end(), "mcap") != s_.log_formats.end()) {
    try {
      scoring::WriteRunMcap(
          out_ + "/run.mcap",
          scoring::RunRecord{bus_log_, run_.motion0_ns, *truth_, *estimates_, run_.events}, robot);
    } catch (const std::exception& e) {
      fmt::print(stderr, "wheelhil run: run.mcap: {}\n", e.what());
      result.exit_code = 1;
    }
  }
  link_->Close();
  return result;
}

}  // namespace

RunResult RunScenario(const Scenario& scenario, const RunOptions& options) {
  Run run(scenario, options);
  return run.Execute();
}

}  // namespace wheelhil::emulator::scenario
