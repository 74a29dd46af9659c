#pragma once
/// Fault windows and the record of injected faults (emulator/faults). Every injector reports the
/// start and end of each of its faults, at the fault's own scheduled instants, to a FaultEventLog
/// the scenario runner writes out as events.jsonl (one FaultEventJson line per event).
/// Thread-compatible.

#include <cstdint>
#include <limits>
#include <string>
#include <string_view>
#include <vector>

namespace wheelhil::emulator {

/// The virtual-time window [t0_ns, t1_ns) a fault is active in. A fault injected "at a time"
/// has t1_ns = kForever.
struct FaultWindow {
  static constexpr std::int64_t kForever = std::numeric_limits<std::int64_t>::max();
  std::int64_t t0_ns = 0;
  std::int64_t t1_ns = kForever;

  bool Contains(std::int64_t t_ns) const { return t_ns >= t0_ns && t_ns < t1_ns; }
  /// t0 >= 0 and t1 > t0.
  bool IsValid() const { return t0_ns >= 0 && t1_ns > t0_ns; }
};

/// One recorded fault event.
struct FaultEvent {
  std::int64_t t_ns = 0;
  std::string category;  ///< "sensor", "device", "frame", "bus".
  std::string kind;      ///< e.g. "bias_step", "silent", "drop", "flood".
  std::string phase;     ///< "start", "end" or "applied" (an instantaneous action).
  std::string target;    ///< Sensor / node name, "id 0x170 mask 0x7ff", ...
  std::string detail;    ///< Parameters, human readable.
};

/// Append-only list of fault events, in the order injectors recorded them.
class FaultEventLog {
 public:
  void Record(FaultEvent e) { events_.push_back(std::move(e)); }
  const std::vector<FaultEvent>& events() const { return events_; }
  /// Events sorted by time (stable: same-time events keep their recording order).
  std::vector<FaultEvent> SortedByTime() const;
  void Clear() { events_.clear(); }
  std::size_t size() const { return events_.size(); }
  /// Back to its first `n` events (what a forecast's copies of the injectors recorded goes).
  void Truncate(std::size_t n) {
    if (n < events_.size()) events_.resize(n);
  }

 private:
  std::vector<FaultEvent> events_;
};

/// One JSON object on one line (no trailing newline):
/// {"t_ns":..,"t_s":..,"category":"..","kind":"..","phase":"..","target":"..","detail":".."}
std::string FaultEventJson(const FaultEvent& e);

namespace faults_internal {
/// Start/end bookkeeping of one fault window: records "start" at t0 once time reaches t0 and
/// "end" at t1 once time reaches t1 (never for kForever).
class WindowPhase {
 public:
  void Advance(std::int64_t t_ns, const FaultWindow& w, FaultEventLog* log,
               std::string_view category, std::string_view kind, std::string_view target,
               std::string_view detail);
  /// True when Advance(t_ns, w, ...) would record an event (callers build details only then).
  bool Pending(std::int64_t t_ns, const FaultWindow& w) const {
    return (!started_ && t_ns >= w.t0_ns) ||
           (!ended_ && w.t1_ns != FaultWindow::kForever && t_ns >= w.t1_ns);
  }

 private:
  bool started_ = false;
  bool ended_ = false;
};
}  // namespace faults_internal

}  // namespace wheelhil::emulator
