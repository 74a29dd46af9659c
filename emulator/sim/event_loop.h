#pragma once
/// The run's discrete-event loop. Virtual time is integer ns since the run start. Each event
/// source says when it next needs the clock (NextEventNs) and what it does then (Fire); the
/// loop advances to the earliest instant over the sources of the current phase, lets the wait
/// policy relate that instant to the wall clock, and fires every source due then in the
/// phase's order. A run is a sequence of phases (boot, settle, motion) of this one loop.
///
/// Lockstep and real time differ only in the wait policy: lockstep never waits for the wall
/// clock (the firmware runs on the virtual clock until all of it is blocked instead); real time
/// waits for each instant's absolute wall-clock deadline (realtime/realtime_pacer.h), anchored
/// at the start of the phase.
///
/// A source that meets a failure records it in the RunContext. Before firing a source the loop
/// ends the phase if the run failed and that source says it stops on failure.
/// Thread-compatible.

#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "emulator/sim/run_context.h"

namespace wheelhil::emulator::sim {

inline constexpr std::int64_t kNever = std::numeric_limits<std::int64_t>::max();

class EventSource {
 public:
  virtual ~EventSource() = default;
  /// The next instant the source needs the clock (kNever: none in this phase).
  virtual std::int64_t NextEventNs() const = 0;
  /// Does what is due at t_ns (== NextEventNs()) and schedules its next instant.
  virtual void Fire(std::int64_t t_ns) = 0;
  /// After a failure, the phase ends before this source fires again.
  virtual bool StopsOnFailure() const { return true; }
};

/// How virtual instants relate to the wall clock.
class WaitPolicy {
 public:
  virtual ~WaitPolicy() = default;
  /// A phase starts at virtual t_ns.
  virtual void StartPhase(std::int64_t t_ns) { (void)t_ns; }
  /// The loop is about to fire the events at virtual t_ns.
  virtual void WaitFor(std::int64_t t_ns) { (void)t_ns; }
};

/// Lockstep: virtual time runs as fast as the stages (and the firmware's answers) allow.
class LockstepWait final : public WaitPolicy {};

/// Real time: virtual instant t is fired at the wall-clock instant anchor_wall + (t - anchor_t),
/// the anchor taken at each phase start (an absolute deadline: lateness does not accumulate).
class RealtimeWait final : public WaitPolicy {
 public:
  void StartPhase(std::int64_t t_ns) override;
  void WaitFor(std::int64_t t_ns) override;

 private:
  std::int64_t anchor_t_ns_ = 0;
  std::int64_t anchor_wall_ns_ = 0;
};

struct Phase {
  std::string name;
  /// Fired in this order when due at the same instant.
  std::vector<EventSource*> sources;
  /// Checked before each instant: the phase is over.
  std::function<bool()> done;
};

class EventLoop {
 public:
  EventLoop(RunContext& run, WaitPolicy& wait) : run_(run), wait_(wait) {}

  /// Runs `phase` until done(), a failure (see EventSource::StopsOnFailure) or no source has an
  /// instant left. Returns the number of instants fired.
  std::uint64_t Run(const Phase& phase);

 private:
  RunContext& run_;
  WaitPolicy& wait_;
};

}  // namespace wheelhil::emulator::sim
