// Per-cycle cost of the reference firmware's estimators (papers 000, 001, 002). The firmware runs
// them at 4 Hz (000), 50-100 Hz (001) and 1 kHz (002); these numbers say how much of a cycle
// each takes.
//   build/bin/estimators_bench

#include <benchmark/benchmark.h>

#include <array>
#include <cstdint>

#include "bus/normality.h"
#include "firmware_stub/paper000_slip_estimator.h"
#include "firmware_stub/paper001_follower_odometry.h"
#include "firmware_stub/paper002_velocity_fusion.h"

namespace wheelhil::fw {
namespace {

void BM_SlipCorrectingOdometryStep(benchmark::State& state) {
  SlipEstimatorConfig c;
  c.track_width_m = 0.5;
  c.residual_mean_rad = -0.034e-3;
  c.residual_sigma_rad = 1.69e-3;
  SlipCorrectingOdometry est(c);
  std::uint64_t k = 0;
  for (auto _ : state) {
    // Every 8th interval the right wheel spins, so both branches are exercised.
    const double extra = (++k % 8 == 0) ? 0.02 : 0.0;
    benchmark::DoNotOptimize(est.Step(0.0625, 0.0625 + extra, 1e-4));
  }
  benchmark::DoNotOptimize(est.pose_corrected());
}
BENCHMARK(BM_SlipCorrectingOdometryStep);

void BM_FollowerOdometryUpdateCounts(benchmark::State& state) {
  FollowerOdometryConfig c;
  c.geometry.mount_radius_m = 0.2;
  c.follower_radius_m = 0.025;
  c.counts_per_rev = 4096;
  FollowerOdometry odo(c);
  std::array<std::uint64_t, 3> raw = {0xFFFFFF00u, 100, 2000};
  for (auto _ : state) {
    raw[0] += 37;
    raw[1] -= 12;
    raw[2] += 5;
    odo.UpdateCounts(raw);
  }
  benchmark::DoNotOptimize(odo.pose());
}
BENCHMARK(BM_FollowerOdometryUpdateCounts);

void BM_VelocityFusionStepRaw(benchmark::State& state) {
  VelocityFusionConfig c;
  c.accel_mount_radius_m = 0.15;
  VelocityFusion fusion(c);
  double x = 0.0;
  std::uint64_t k = 0;
  for (auto _ : state) {
    x += 1e-4;
    const double jolt = (++k % 300 < 30) ? 0.4 : 0.0;  // Periodic disturbances.
    benchmark::DoNotOptimize(
        fusion.StepRaw({x, 0.0, 0.0}, {jolt, 0.0, 0.0, -jolt}, {0.0, 0.0, 0.0}));
  }
  benchmark::DoNotOptimize(fusion.last());
}
BENCHMARK(BM_VelocityFusionStepRaw);

void BM_SkewnessKurtosisHistogram(benchmark::State& state) {
  const std::array<double, 10> centres = {-4.5, -3.5, -2.5, -1.5, -0.5, 0.5, 1.5, 2.5, 3.5, 4.5};
  const std::array<std::uint64_t, 10> counts = {9, 21, 92, 163, 232, 218, 151, 74, 30, 10};
  for (auto _ : state) {
    benchmark::DoNotOptimize(bus::SkewnessKurtosisTestHistogram(centres, counts));
  }
}
BENCHMARK(BM_SkewnessKurtosisHistogram);

}  // namespace
}  // namespace wheelhil::fw

BENCHMARK_MAIN();
