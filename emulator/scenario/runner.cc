#include "emulator/scenario/runner.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <memory>
#include <stdexcept>

#include <fmt/format.h>

#include "bus/canopen.h"
#include "bus/dbc.h"
#include "emulator/devices/device.h"
#include "emulator/firmware/firmware_link.h"
#include "emulator/firmware/firmware_process.h"
#include "emulator/firmware/lockstep_handshake.h"
#include "emulator/firmware/wheelhil_fw_config.h"
#include "emulator/scenario/device_registry.h"
#include "emulator/scenario/fault_plan.h"
#include "emulator/scenario/physics_stage.h"
#include "emulator/scoring/artefacts.h"
#include "emulator/scoring/estimate_decoder.h"
#include "emulator/scoring/expectations.h"
#include "emulator/scoring/metric_components.h"
#include "emulator/scoring/run_artefacts.h"
#include "emulator/scoring/truth_recorder.h"
#include "emulator/sim/bus_hub.h"
#include "emulator/sim/cpu_placement.h"
#include "emulator/sim/event_loop.h"
#include "emulator/sim/run_context.h"

namespace wheelhil::emulator::scenario {

namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using Clock = std::chrono::steady_clock;

double WallSeconds(Clock::time_point since) {
  return std::chrono::duration<double>(Clock::now() - since).count();
}

// One run: builds the stages, runs the phases of the event loop, scores and writes the result.
class Run {
 public:
  Run(const Scenario& s, const RunOptions& o) : s_(s), o_(o) {}
  RunResult Execute();

 private:
  class Tick;
  class SyncProducer;

  void Build();
  void StartFirmware();
  // The stages of one physics step that ends at t_ns (see Tick).
  void StepDevices(std::int64_t t_ns, bool motion);
  // Lockstep: waits until `done` (wall-clock timeout); false on timeout or failure.
  bool WaitFirmware(const std::function<bool()>& done);
  void OnFirmwareFrame(const bus::CanFrame& f);
  void WaitStatus(int cycle, std::int64_t k);
  void StartWorker(std::int64_t steps);
  void RunPhases();
  void Progress(bool final);
  json Report(double wall_s);

  const Scenario& s_;
  const RunOptions& o_;
  std::uint64_t seed_ = 1;
  bool lockstep_ = true;
  std::string out_;
  sim::RunContext run_;
  sim::CpuPlacement cpus_;
  std::vector<std::unique_ptr<Device>> devices_;
  // Declared after the devices: a worker still stepping (a run left by an exception) is stopped
  // before the devices whose readings it takes go.
  std::unique_ptr<PhysicsStage> physics_;
  std::unique_ptr<sim::BusHub> hub_;
  std::unique_ptr<firmware::FirmwareLink> link_;
  firmware::FirmwareProcess firmware_;
  std::unique_ptr<firmware::LockstepHandshake> handshake_;
  std::unique_ptr<scoring::EstimateDecoder> estimates_;
  std::unique_ptr<scoring::TruthRecorder> truth_;
  std::unique_ptr<FaultPlan> faults_;
  Clock::time_point wall0_, last_progress_;
};

// The physics step ending at its instant and everything that depends on it, in this order:
// physics, node faults, devices, truth, bus, firmware link.
class Run::Tick final : public sim::EventSource {
 public:
  struct Options {
    bool motion = false;
    bool record_truth = true;
    bool wait_boot_answers = false;  // lockstep start-up: the firmware's reaction to each node
    std::int64_t ticks = -1;         // ticks to run, -1: until the phase is done
  };
  explicit Tick(Run& run) : r_(run) {}
  void Start(const Options& o) {
    o_ = o;
    fired_ = 0;
    next_ns_ = r_.run_.now_ns + r_.physics_->step_ns();
    physics_failed_ = false;
  }
  std::int64_t NextEventNs() const override {
    return o_.ticks >= 0 && fired_ >= o_.ticks ? sim::kNever : next_ns_;
  }
  // In motion a cycle's steps run to its end after a failure (the next SYNC stops the run).
  bool StopsOnFailure() const override { return !o_.motion || physics_failed_; }
  void Fire(std::int64_t t_ns) override;
  /// The next tick is the first of cycle `cycle` (SYNC number mod 256, the k-th of the run).
  void OpenCycle(int cycle, std::int64_t k) {
    cycle_ = cycle;
    cycle_k_ = k;
    first_of_cycle_ = true;
  }
  void Stop() { o_.ticks = fired_; }
  /// The cycle whose FW_Status is awaited after the next SYNC (-1: none).
  int pending_status_cycle = -1;

 private:
  Run& r_;
  Options o_;
  std::int64_t fired_ = 0;
  std::int64_t next_ns_ = 0;
  bool physics_failed_ = false;
  bool first_of_cycle_ = false;
  int cycle_ = -1;
  std::int64_t cycle_k_ = 0;
};

void Run::Tick::Fire(std::int64_t t_ns) {
  ++fired_;
  next_ns_ = t_ns + r_.physics_->step_ns();
  const std::int64_t step_ns = r_.physics_->step_ns();
  if (!r_.physics_->Step(t_ns - step_ns, o_.motion)) {
    physics_failed_ = true;
  } else {
    r_.run_.now_ns = t_ns;
    r_.StepDevices(t_ns, o_.motion);
  }
  const std::int64_t now = r_.run_.now_ns;
  if (o_.record_truth) r_.truth_->Record(now, r_.physics_->body(), r_.physics_->wheels(), false);
  r_.hub_->AdvanceTo(now);
  if (!r_.lockstep_) {
    r_.link_->Drain(0, [this](const bus::CanFrame& f) { r_.OnFirmwareFrame(f); });
  } else if (o_.wait_boot_answers) {
    const auto& awaiting = r_.handshake_->awaiting_nodes();
    if (!awaiting.empty() && !r_.WaitFirmware([&] { return awaiting.empty(); })) {
      r_.run_.Fail(fmt::format(
          "timeout: the firmware did not answer node {}'s boot-up/SDO within {} s (wall)",
          *awaiting.begin(), r_.s_.timing.timeout_s));
    }
  } else if (first_of_cycle_) {
    // The firmware's answer is fixed by the frames it was given once the cycle's last
    // sync-answer is on the wire; if one is missing, the next SYNC closes the cycle.
    first_of_cycle_ = false;
    if (r_.handshake_->CycleCompleteOnBus()) {
      r_.WaitStatus(cycle_, cycle_k_);
    } else {
      pending_status_cycle = cycle_;
    }
  }
  if (o_.motion) r_.Progress(false);
}

// SYNC at the start of each cycle k = 0..cycles; the last one only closes cycle cycles-1.
class Run::SyncProducer final : public sim::EventSource {
 public:
  SyncProducer(Run& run, Tick& tick, std::int64_t t0_ns, std::int64_t cycle_ns,
               std::int64_t period_ns, std::int64_t cycles)
      : r_(run), tick_(tick), t0_ns_(t0_ns), cycle_ns_(cycle_ns), period_ns_(period_ns),
        cycles_(cycles) {}
  std::int64_t NextEventNs() const override {
    return k_ <= cycles_ ? t0_ns_ + k_ * cycle_ns_ : sim::kNever;
  }
  void Fire(std::int64_t t_ns) override;

 private:
  // Moves the bus on (half steps, at most one period) until `done`.
  void AdvanceBusUntil(const std::function<bool()>& done);
  void CloseLastCycle(int want);

  Run& r_;
  Tick& tick_;
  std::int64_t t0_ns_, cycle_ns_, period_ns_, cycles_;
  std::int64_t k_ = 0;
};

void Run::SyncProducer::AdvanceBusUntil(const std::function<bool()>& done) {
  const std::int64_t half_step = r_.physics_->step_ns() / 2;
  for (const std::int64_t until = r_.run_.now_ns + period_ns_;
       !done() && r_.hub_->now_ns() < until;) {
    r_.hub_->AdvanceTo(std::min(until, r_.hub_->now_ns() + half_step));
  }
}

void Run::SyncProducer::Fire(std::int64_t t_ns) {
  const std::int64_t k = k_++;
  sim::RunContext& run = r_.run_;
  r_.truth_->Record(t_ns, r_.physics_->body(), r_.physics_->wheels(), true);
  bus::CanFrame sync;
  sync.id = bus::canopen::kSyncCobId;
  sync.len = 0;
  r_.hub_->EnqueueSync(sync, t_ns);
  const int want = static_cast<int>(r_.handshake_->syncs_sent() % 256);
  r_.estimates_->OnSync(want, run.MotionSeconds(t_ns));
  r_.handshake_->OnSyncSent();
  // The SYNC and the frames answering it (the readings at this instant) go out before the
  // physics moves on.
  r_.hub_->AdvanceTo(t_ns + r_.physics_->step_ns() / 2);
  if (r_.lockstep_ && tick_.pending_status_cycle >= 0) {
    // The previous cycle was incomplete on the bus: this SYNC closes it once it is on the wire
    // (an error burst or a flood can hold it back beyond half a step).
    AdvanceBusUntil([&] { return r_.handshake_->LatestSyncOnWire(); });
    r_.WaitStatus(std::exchange(tick_.pending_status_cycle, -1), k - 1);
  }
  if (k < cycles_) {
    tick_.OpenCycle(want, k);
    return;
  }
  tick_.Stop();
  if (run.failed()) return;
  // The last cycle: no physics step follows, so the bus finishes its frames (at most one
  // period) before the answer is awaited.
  if (r_.lockstep_) AdvanceBusUntil([&] { return r_.handshake_->CycleCompleteOnBus(); });
  CloseLastCycle(want);
}

void Run::SyncProducer::CloseLastCycle(int want) {
  sim::RunContext& run = r_.run_;
  if (run.failed()) return;
  if (!r_.lockstep_ || r_.handshake_->CycleCompleteOnBus()) {
    if (!r_.WaitFirmware([&] { return r_.handshake_->StatusSeen(want); })) {
      run.Fail(fmt::format("timeout: no FW_Status for the last cycle {} within {} s", cycles_,
                           r_.s_.timing.timeout_s));
    }
  } else {
    // A sync answer of the last SYNC never came (silent node, dropped frame): no later SYNC
    // closes that cycle, so its answer is not awaited.
    run.events.push_back(json{{"t_s", run.MotionSeconds(run.now_ns)},
                              {"event", "last_cycle_incomplete"},
                              {"cycle", cycles_}});
  }
}

void Run::StepDevices(std::int64_t t_ns, bool motion) {
  if (motion) faults_->StepNodeFaults(t_ns, physics_->step_ns(), devices_, run_);
  DeviceWorld world;
  world.body = &physics_->body();
  world.wheels = &physics_->wheels();
  for (std::size_t d = 0; d < devices_.size(); ++d) {
    world.readings = physics_->readings(d);
    devices_[d]->Poll(t_ns, world, hub_->port(d));
  }
  // Frames a frame fault delayed (or a duplicate's copy) that are due now; fault windows.
  hub_->ReleaseDelayed();
  for (auto& d : devices_) d->EndStep(t_ns);
  if (motion) truth_->RecordMotionStep(t_ns, physics_->wheels());
}

void Run::OnFirmwareFrame(const bus::CanFrame& f) {
  // Into the bus model at the current virtual instant (it is logged when it completes).
  hub_->EnqueueFromFirmware(f);
  handshake_->OnFirmwareFrame(f);
  estimates_->OnFrame(f);
}

bool Run::WaitFirmware(const std::function<bool()>& done) {
  return link_->WaitFor(done, s_.timing.timeout_s, firmware_,
                        [this](const bus::CanFrame& f) { OnFirmwareFrame(f); });
}

void Run::WaitStatus(int cycle, std::int64_t k) {
  if (!WaitFirmware([&] { return handshake_->StatusSeen(cycle); })) {
    run_.Fail(fmt::format("timeout: no FW_Status for cycle {} within {} s (wall) at t = {:.3f} s",
                          k, s_.timing.timeout_s, run_.MotionSeconds(run_.now_ns)));
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
  link_ = std::make_unique<firmware::FirmwareLink>(o_.can_iface, lockstep_, run_);
  hub_->OpenLog(out_ + "/can.log", link_->interface());
  hub_->SetFirmwareSend([this](const bus::CanFrame& f) { return link_->Send(f); });
  handshake_ = std::make_unique<firmware::LockstepHandshake>(fw_dbc, *hub_, run_);
  hub_->SetObserver(handshake_.get());
  estimates_ = std::make_unique<scoring::EstimateDecoder>(fw_dbc);
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
    // A firmware config is wheelhil-fw's convention: it gets the run's SYNC settings.
    const std::string cfg_path = fs::absolute(out_ + "/firmware_config.yaml").string();
    scoring::WriteText(cfg_path, firmware::DerivedWheelhilFwConfig(
                                     s_.firmware.config, s_.firmware.overrides_yaml,
                                     {s_.timing.sync_period_s, lockstep_}));
    cmd = firmware::Substitute(cmd, "${CONFIG}", cfg_path);
  }
  cmd = firmware::Substitute(firmware::Substitute(cmd, "${CAN}", link_->interface()), "${BIN}",
                             o_.bin_dir);
  std::vector<std::pair<std::string, std::string>> env;
  if (link_->private_bus() && o_.ucan_child_env) env = o_.ucan_child_env(link_->runtime_dir());
  env.emplace_back("WHEELHIL_DBC_DIR", o_.dbc_dir);
  link_->BeforeFirmwareStarts();
  firmware_.Start(cmd, env, out_ + "/firmware.log");
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
  physics_->StartWorker(steps, where, devices_);
  // The lines of the frames from here on are formatted there as well.
  hub_->StartBackgroundLog(where);
}

void Run::RunPhases() {
  sim::LockstepWait lockstep_wait;
  sim::RealtimeWait realtime_wait;
  sim::EventLoop loop(run_, lockstep_ ? static_cast<sim::WaitPolicy&>(lockstep_wait)
                                      : static_cast<sim::WaitPolicy&>(realtime_wait));
  Tick tick(*this);

  // Boot: the nodes boot, the firmware configures and starts them.
  const std::int64_t boot_limit_ns = std::llround(10e9);
  tick.Start({.motion = false, .record_truth = true, .wait_boot_answers = true});
  // A run that failed before the motion still has its motion origin here (sim_time_s 0).
  loop.Run({"boot",
            {&tick},
            [&] {
              if (run_.now_ns > boot_limit_ns) {
                run_.Fail("the encoder nodes were not started (NMT start) within 10 s of "
                          "virtual time");
              }
              return std::all_of(devices_.begin(), devices_.end(),
                                 [](const auto& d) { return d->Ready(); }) &&
                     handshake_->awaiting_nodes().empty();
            }});

  // Settle: the vehicle at rest on its suspension defines the start.
  tick.Start({.motion = false,
              .record_truth = false,
              .ticks = std::llround(0.2e9) / physics_->step_ns() +
                       (std::llround(0.2e9) % physics_->step_ns() != 0 ? 1 : 0)});
  loop.Run({"settle", {&tick}, nullptr});

  // Motion: SYNC every period; lockstep waits for the firmware's status of each cycle.
  const std::int64_t step_ns = physics_->step_ns();
  const std::int64_t period_ns = std::llround(s_.timing.sync_period_s * 1e9);
  const std::int64_t steps_per_cycle = period_ns / step_ns;
  const std::int64_t cycles = std::llround(s_.timing.duration_s * 1e9) / period_ns;
  run_.motion0_ns = run_.now_ns;
  run_.motion0_s = static_cast<double>(run_.now_ns) * 1e-9;
  physics_->StartMotion(run_.now_ns);
  truth_->StartMotion(run_.now_ns, physics_->vehicle().body_truth());
  run_.events.push_back(json{{"t_s", 0.0}, {"event", "motion_start"}});
  faults_->Arm(run_.now_ns, devices_, *hub_);
  std::vector<firmware::SyncAnswer> answers;
  for (std::size_t d = 0; d < devices_.size(); ++d) {
    if (const auto a = devices_[d]->sync_answer()) {
      answers.push_back({static_cast<int>(d), a->id, a->len});
    }
  }
  handshake_->ExpectSyncAnswers(std::move(answers));
  if (lockstep_ && !run_.failed()) StartWorker(cycles * steps_per_cycle);
  tick.Start({.motion = true, .record_truth = true, .ticks = cycles * steps_per_cycle});
  SyncProducer sync(*this, tick, run_.now_ns, steps_per_cycle * step_ns, period_ns, cycles);
  loop.Run({"motion", {&tick, &sync}, nullptr});
}

void Run::Progress(bool final) {
  if (!o_.progress) return;
  if (!final && WallSeconds(last_progress_) < 0.2) return;
  last_progress_ = Clock::now();
  const double sim = run_.MotionSeconds(run_.now_ns);
  const double wall = WallSeconds(wall0_);
  fmt::print(stderr, "\r{}: t = {:7.2f} / {:.2f} s  cycle {:6}  {:7.1f}x real time{}", s_.name,
             std::max(0.0, sim), s_.timing.duration_s, handshake_->syncs_sent(),
             wall > 0 ? std::max(0.0, sim) / wall : 0.0, final ? "\n" : "");
}

json Run::Report(double wall_s) {
  json r;
  r["scenario"] = s_.name;
  r["seed"] = seed_;
  const double sim = std::max(0.0, run_.MotionSeconds(run_.now_ns));
  r["sim_time_s"] = sim;
  r["cycles"] = handshake_->syncs_sent();
  r["sync_period_s"] = s_.timing.sync_period_s;
  json metrics = json::object();
  std::vector<std::string> wheel_names;
  for (const auto& w : s_.platform.vehicle.wheels) wheel_names.push_back(w.name);
  const scoring::RecordedRun recorded{*truth_, *estimates_, s_.timing.sync_period_s,
                                      wheel_names, scoring::SlipIntervals(*truth_)};
  scoring::ScoreRun(recorded, s_.metric_components, metrics, run_.events);
  metrics["bus"] = hub_->Metrics();
  if (auto f = faults_->Metrics(devices_, *hub_)) metrics["faults"] = *f;
  r["metrics"] = metrics;
  r["wall"] = json{{"wall_time_s", wall_s},
                   {"real_time_factor", wall_s > 0 ? sim / wall_s : 0.0},
                   {"cpu", cpus_.cpu()},
                   {"physics_thread", physics_->worker_used()}};
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
  lockstep_ = s_.timing.lockstep && !o_.realtime;
  if (lockstep_) cpus_.ConfineToOneCpu(o_.cpu);
  wall0_ = Clock::now();
  last_progress_ = wall0_;
  Build();
  run_.events.push_back(json{{"t_s", 0.0},
                             {"event", "run_start"},
                             {"seed", seed_},
                             {"lockstep", lockstep_},
                             {"bus", o_.can_iface.empty() ? "ucan" : "socketcan"}});
  StartFirmware();
  RunPhases();

  physics_->StopWorker();  // a failed run leaves it steps ahead
  Progress(true);
  hub_->DrainToLog();
  const double wall_s = WallSeconds(wall0_);
  faults_->FlushEvents(run_);
  firmware_.Stop();
  hub_->CloseLog();
  if (run_.failed()) {
    run_.events.push_back(json{{"t_s", run_.MotionSeconds(run_.now_ns)},
                               {"event", "failure"},
                               {"reason", run_.failure}});
  }
  json report = Report(wall_s);
  json expectations = json::array();
  const bool all_ok =
      scoring::EvaluateExpectations(s_.expectations, report["metrics"], expectations);
  report["expectations"] = expectations;
  const bool passed = all_ok && !run_.failed();
  report["verdict"] = passed ? "pass" : "fail";
  if (run_.failed()) report["failure"] = run_.failure;
  scoring::WriteRunArtefacts(out_, report, *truth_, *estimates_, run_.events);
  RunResult result;
  result.report = report;
  result.failure = run_.failure;
  result.exit_code = passed ? 0 : 1;
  link_->Close();
  return result;
}

}  // namespace

RunResult RunScenario(const Scenario& scenario, const RunOptions& options) {
  Run run(scenario, options);
  return run.Execute();
}

}  // namespace wheelhil::emulator::scenario
