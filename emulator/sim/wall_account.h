#pragma once
/// Where a run's wall-clock time goes (report.json "wall", docs/performance.md): the stages the
/// run's own thread runs, each timed around its call, and the hand-overs to the firmware.
/// Seconds of wall time; what no stage holds (scoring, progress, the loop) is the rest.
/// Thread-compatible: the run's thread only.

#include <chrono>
#include <cstdint>

namespace wheelhil::emulator::sim {

struct WallAccount {
  double physics_s = 0;      ///< Physics steps, waiting for the physics worker included.
  double devices_bus_s = 0;  ///< Devices' readings and frames, the bus model, can.log.
  double handover_s = 0;     ///< The firmware's turns: from handing it the CPU to its return.
  double forecast_s = 0;     ///< Runahead: the bus forecasts and putting their frames ahead.
};

/// Adds the wall time of its scope to `into` (two steady_clock reads: ~50 ns).
class WallTimer {
 public:
  explicit WallTimer(double& into) : into_(into), t0_(std::chrono::steady_clock::now()) {}
  ~WallTimer() {
    into_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count();
  }
  WallTimer(const WallTimer&) = delete;
  WallTimer& operator=(const WallTimer&) = delete;

 private:
  double& into_;
  std::chrono::steady_clock::time_point t0_;
};

}  // namespace wheelhil::emulator::sim
