#pragma once
/// Where a lockstep run executes. Lockstep is strictly sequential, and on one CPU each hand-over
/// between the emulator and the firmware is a cheap local context switch instead of a cross-CPU
/// wake-up; SCHED_BATCH keeps a woken side from preempting the one still writing its frames.
/// ConfineToOneCpu puts the calling thread (and so the broker and the firmware process, created
/// later) on one CPU at SCHED_BATCH; the destructor gives the thread back its CPU set and
/// policy, so a library call leaves no trace. WorkerCpus: the CPUs the run may use besides its
/// own, for the physics worker. Thread-compatible.

#include <sched.h>

#include <optional>

namespace wheelhil::emulator::sim {

class CpuPlacement {
 public:
  CpuPlacement() = default;
  ~CpuPlacement() { Release(); }
  CpuPlacement(const CpuPlacement&) = delete;
  CpuPlacement& operator=(const CpuPlacement&) = delete;

  /// `cpu`: nullopt the CPU the thread runs on now, -1 no confinement. Throws
  /// std::invalid_argument for a CPU this process may not run on.
  void ConfineToOneCpu(std::optional<int> cpu);
  void Release();
  /// The CPU the run is confined to, -1 none.
  int cpu() const { return cpu_; }
  /// The CPUs the run may use besides its own; false when there are none.
  bool OtherCpus(cpu_set_t* out) const;

 private:
  int cpu_ = -1;
  cpu_set_t saved_cpus_{};
  int saved_policy_ = -1;
  sched_param saved_param_{};
};

}  // namespace wheelhil::emulator::sim
