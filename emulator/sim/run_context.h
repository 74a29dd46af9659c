#pragma once
/// What every stage of a run shares: the virtual clock (integer ns since the run start), the
/// instant the motion phase started, the run's event log (events.jsonl, in the order things
/// happened; sorted by time, stably, when the run is scored) and the reason the run failed.
/// A stage that meets a run-time failure records it with Fail and returns; the loop stops at
/// the end of the current stage. Thread-compatible.

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace wheelhil::emulator::sim {

struct RunContext {
  std::int64_t now_ns = 0;  ///< Virtual time of the latest completed step.
  double motion0_s = 0;     ///< Motion start (s since the run start); 0 before it.
  std::int64_t motion0_ns = 0;
  std::vector<nlohmann::json> events;
  std::string failure;  ///< Empty while the run goes on.

  bool failed() const { return !failure.empty(); }
  /// The first failure wins: it is the cause, later ones are consequences.
  void Fail(std::string why) {
    if (failure.empty()) failure = std::move(why);
  }
  /// Seconds since the motion start of t_ns (since the run start before the motion).
  double MotionSeconds(std::int64_t t_ns) const {
    return static_cast<double>(t_ns) * 1e-9 - motion0_s;
  }
};

}  // namespace wheelhil::emulator::sim
