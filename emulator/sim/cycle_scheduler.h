#pragma once
/// The event sources of a run's phases: StepSource, the physics step ending at its instant and
/// every stage that depends on it, and SyncSource, the SYNC at each cycle start. They only
/// order the stages; the run implements them (RunStages) and says how the firmware is waited
/// for (FirmwareGate), so the order can be tested with fakes.
///
/// A step to t runs, in this order: physics (t - step to t), devices (node faults, the devices
/// at t, delayed frames, device fault windows), truth, bus (to t), firmware: real time takes
/// what the firmware sent; lockstep start-up waits for its reaction to every boot-up and SDO
/// answer; the first step of a cycle waits for the cycle's FW_Status once every sync answer is
/// on the wire, else the next SYNC closes the cycle. A SYNC at t: truth (forced), the SYNC,
/// the bus to t + step/2, the status of a pending cycle, and at the last SYNC the last cycle's
/// status. After a failure the steps of the current cycle still run; the next SYNC ends the
/// phase. Thread-compatible.

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
  /// Puts a SYNC on the bus at t_ns; returns its cycle number (mod 256).
  virtual int SendSync(std::int64_t t_ns) = 0;
  /// Called after every motion step (a progress line).
  virtual void AfterMotionStep() {}
};

/// The firmware as the sources wait for it.
class FirmwareGate {
 public:
  virtual ~FirmwareGate() = default;
  virtual bool lockstep() const = 0;
  /// Real time: hands over what the firmware sent so far.
  virtual void Drain() = 0;
  /// Lockstep start-up: waits for the reaction to every pending boot-up and SDO answer
  /// (a timeout is a failure in the run).
  virtual void WaitBootAnswers() = 0;
  /// The latest SYNC is on the wire and every device that answers SYNC answered it.
  virtual bool CycleCompleteOnBus() const = 0;
  virtual bool LatestSyncOnWire() const = 0;
  /// Waits for the FW_Status of `cycle` (mod 256), the k-th cycle of the run.
  virtual void WaitStatus(int cycle, std::int64_t k) = 0;
  /// The same for the last cycle (its own message).
  virtual void WaitLastStatus(int cycle, std::int64_t k) = 0;
};

class StepSource final : public EventSource {
 public:
  struct Options {
    bool motion = false;
    bool record_truth = true;
    bool wait_boot_answers = false;  // lockstep start-up
    std::int64_t steps = -1;         // steps to run, -1: until the phase is done
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

  /// The next step is the first of cycle `cycle` (mod 256), the k-th of the run.
  void OpenCycle(int cycle, std::int64_t k);
  /// No further step in this phase.
  void Stop() { o_.steps = fired_; }
  /// The cycle whose FW_Status the next SYNC awaits (-1: none).
  int pending_status_cycle = -1;

 private:
  RunStages& stages_;
  FirmwareGate& gate_;
  RunContext& run_;
  Options o_;
  std::int64_t fired_ = 0;
  std::int64_t next_ns_ = 0;
  bool physics_failed_ = false;
  bool first_of_cycle_ = false;
  int cycle_ = -1;
  std::int64_t cycle_k_ = 0;
};

class SyncSource final : public EventSource {
 public:
  /// SYNC k = 0..cycles at t0_ns + k * cycle_ns; `period_ns` bounds the bus waits.
  SyncSource(RunStages& stages, FirmwareGate& gate, RunContext& run, StepSource& steps,
             std::int64_t t0_ns, std::int64_t cycle_ns, std::int64_t period_ns,
             std::int64_t cycles)
      : stages_(stages), gate_(gate), run_(run), steps_(steps), t0_ns_(t0_ns), cycle_ns_(cycle_ns),
        period_ns_(period_ns), cycles_(cycles) {}
  std::int64_t NextEventNs() const override {
    return k_ <= cycles_ ? t0_ns_ + k_ * cycle_ns_ : kNever;
  }
  void Fire(std::int64_t t_ns) override;

 private:
  // Moves the bus on in half steps (at most one period) until `done`.
  void AdvanceBusUntil(const std::function<bool()>& done);
  void CloseLastCycle(int cycle);

  RunStages& stages_;
  FirmwareGate& gate_;
  RunContext& run_;
  StepSource& steps_;
  std::int64_t t0_ns_, cycle_ns_, period_ns_, cycles_;
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
