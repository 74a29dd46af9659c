#include "emulator/sim/cpu_placement.h"

#include <stdexcept>

#include <fmt/format.h>

namespace wheelhil::emulator::sim {

void CpuPlacement::ConfineToOneCpu(std::optional<int> requested) {
  if (requested && *requested == -1) return;
  cpu_set_t allowed;
  CPU_ZERO(&allowed);
  if (::sched_getaffinity(0, sizeof(allowed), &allowed) != 0) return;
  const int cpu = requested ? *requested : ::sched_getcpu();
  if (cpu < 0 || cpu >= CPU_SETSIZE || !CPU_ISSET(cpu, &allowed)) {
    if (requested) {
      throw std::invalid_argument(fmt::format(
          "--cpu {}: not a CPU this process may run on (see `taskset -p $$`; -1: no pinning)",
          cpu));
    }
    return;
  }
  cpu_set_t one;
  CPU_ZERO(&one);
  CPU_SET(cpu, &one);
  saved_cpus_ = allowed;
  if (::sched_setaffinity(0, sizeof(one), &one) == 0) cpu_ = cpu;
  saved_policy_ = ::sched_getscheduler(0);
  (void)::sched_getparam(0, &saved_param_);
  // Refused only under a real-time policy; then the run keeps it.
  sched_param none{};
  if (saved_policy_ == SCHED_OTHER) (void)::sched_setscheduler(0, SCHED_BATCH, &none);
}

void CpuPlacement::Release() {
  if (cpu_ >= 0) (void)::sched_setaffinity(0, sizeof(saved_cpus_), &saved_cpus_);
  if (saved_policy_ == SCHED_OTHER) (void)::sched_setscheduler(0, SCHED_OTHER, &saved_param_);
  cpu_ = -1;
  saved_policy_ = -1;
}

bool CpuPlacement::OtherCpus(cpu_set_t* out) const {
  CPU_ZERO(out);
  if (cpu_ >= 0) {
    *out = saved_cpus_;
    CPU_CLR(cpu_, out);
  } else if (::sched_getaffinity(0, sizeof(*out), out) != 0) {
    CPU_ZERO(out);
  }
  return CPU_COUNT(out) - (cpu_ >= 0 ? 0 : 1) >= 1;
}

}  // namespace wheelhil::emulator::sim
