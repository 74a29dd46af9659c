#pragma once
/// The event sources of a run's phases: StepSource, the physics step ending at its instant and
/// every stage that depends on it, and SyncSource, the SYNC at each cycle start. They only
/// order the stages; the run implements them (RunStages) and says how the firmware is waited
/// for (FirmwareGate), so the order can be tested with fakes.
///
/// A step to t runs, in this order: physics (t - step to t), devices (node faults, the devices
/// at t, delayed frames, device fault windows), truth, bus (to t), firmware (Drain: on the
/// virtual clock it runs until all of it is blocked; in real time the run takes what it sent).
/// A SYNC at t: truth (forced), the SYNC, the bus to t + step/2, and after the last SYNC the
/// firmware's last cycle (AfterLastCycle). After a failure the steps of the current cycle still
/// run; the next SYNC ends the phase. Thread-compatible.

#include <cstdint>
#include <functional>
#include <utility>

#include "emulator/sim/event_loop.h"
#include "emulator/sim/run_context.h"

namespace wheelhil::emulator::sim {

/// The stages the sources order (implemented by the run).
class RunStages {
 public:
  virtual ~RunStages() = default;
  virtual std::int64_t step_ns() const = 0;
  /// The physics from t_end_ns - step to t_end_ns; false when it failed (reason in the run).
  virtual bool StepPhysics(std::int64_t t_end_ns, bool motion) = 0;
  /// Node faults, every device at t_ns, delayed frames, device fault windows, motion truth.
  virtual void StepDevices(std::int64_t t_ns, bool motion) = 0;
  /// A truth row at t_ns (on the truth period, or always with `force`).
  virtual void RecordTruth(std::int64_t t_ns, bool force) = 0;
  virtual void AdvanceBus(std::int64_t t_ns) = 0;
  virtual std::int64_t bus_now_ns() const = 0;
  /// Puts a SYNC on the bus at t_ns.
  virtual void SendSync(std::int64_t t_ns) = 0;
  /// Called after every motion step (a progress line).
  virtual void AfterMotionStep() {}
};

/// The firmware as the sources hand it the bus.
class FirmwareGate {
 public:
  virtual ~FirmwareGate() = default;
  /// The firmware takes what the bus brought it: on the virtual clock it runs until all of it
  /// is blocked; in real time the run takes what it sent so far.
  virtual void Drain() = 0;
  /// After the last SYNC: the firmware gets the last cycle's frames (at most one period of bus)
  /// and its answers are taken.
  virtual void AfterLastCycle() = 0;
};

class StepSource final : public EventSource {
 public:
  struct Options {
    bool motion = false;
    bool record_truth = true;
    std::int64_t steps = -1;  // steps to run, -1: until the phase is done
  };
  StepSource(RunStages& stages, FirmwareGate& gate, RunContext& run)
      : stages_(stages), gate_(gate), run_(run) {}

  /// Starts a phase: the next step ends one step after run.now_ns.
  void Start(const Options& options);
  std::int64_t NextEventNs() const override {
    return o_.steps >= 0 && fired_ >= o_.steps ? kNever : next_ns_;
  }
  bool StopsOnFailure() const override { return !o_.motion || physics_failed_; }
  void Fire(std::int64_t t_ns) override;

  /// No further step in this phase.
  void Stop() { o_.steps = fired_; }

 private:
  RunStages& stages_;
  FirmwareGate& gate_;
  RunContext& run_;
  Options o_;
  std::int64_t fired_ = 0;
  std::int64_t next_ns_ = 0;
  bool physics_failed_ = false;
};

class SyncSource final : public EventSource {
 public:
  /// SYNC k = 0..cycles at t0_ns + k * cycle_ns.
  SyncSource(RunStages& stages, FirmwareGate& gate, RunContext& run, StepSource& steps,
             std::int64_t t0_ns, std::int64_t cycle_ns, std::int64_t cycles)
      : stages_(stages),
        gate_(gate),
        run_(run),
        steps_(steps),
        t0_ns_(t0_ns),
        cycle_ns_(cycle_ns),
        cycles_(cycles) {}
  std::int64_t NextEventNs() const override {
    return k_ <= cycles_ ? t0_ns_ + k_ * cycle_ns_ : kNever;
  }
  void Fire(std::int64_t t_ns) override;

 private:
  RunStages& stages_;
  FirmwareGate& gate_;
  RunContext& run_;
  StepSource& steps_;
  std::int64_t t0_ns_, cycle_ns_, cycles_;
  std::int64_t k_ = 0;
};

/// The firmware's own deadlines on the virtual clock (a timer, a sleep, a poll timeout): at
/// each, the bus moves on to that instant and the firmware runs until it blocks (Drain).
class FirmwareDeadlineSource final : public EventSource {
 public:
  FirmwareDeadlineSource(RunStages& stages, FirmwareGate& gate,
                         std::function<std::int64_t()> next_deadline_ns)
      : stages_(stages), gate_(gate), next_(std::move(next_deadline_ns)) {}
  std::int64_t NextEventNs() const override { return next_(); }
  void Fire(std::int64_t t_ns) override {
    if (t_ns > stages_.bus_now_ns()) stages_.AdvanceBus(t_ns);
    gate_.Drain();
  }

 private:
  RunStages& stages_;
  FirmwareGate& gate_;
  std::function<std::int64_t()> next_;
};

}  // namespace wheelhil::emulator::sim
