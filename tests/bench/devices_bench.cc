// Cost of the sensor models, the exact frame-length computation and the bus timing model.
#include <benchmark/benchmark.h>

#include <cstdint>
#include <vector>

#include "bus/can_frame.h"
#include "emulator/devices/can_bus_model.h"
#include "emulator/sensors/accelerometer_model.h"
#include "emulator/sensors/encoder_model.h"
#include "emulator/sensors/gyro_model.h"

namespace wheelhil::emulator {
namespace {

void BM_CanFrameBitsExact(benchmark::State& state) {
  const std::uint8_t bytes[8] = {0x12, 0x34, 0x56, 0x78, 0x9A, 0xBC, 0xDE, 0xF0};
  bus::CanFrame f = bus::CanFrame::Classic(0x181, bytes);
  for (auto _ : state) {
    f.data[0] = static_cast<std::uint8_t>(f.data[0] + 1);
    benchmark::DoNotOptimize(CanFrameBits(f, StuffingMode::kExact));
  }
}
BENCHMARK(BM_CanFrameBitsExact);

// One simulated second of four nodes sending one 8-byte frame each per ms at 1 Mbit/s.
void BM_CanBusModelOneSecond4kFrames(benchmark::State& state) {
  const std::uint8_t bytes[8] = {1, 2, 3, 4, 5, 6, 7, 8};
  for (auto _ : state) {
    CanBusModel bus({.bitrate_bps = 1'000'000, .stuffing = StuffingMode::kExact});
    const int nodes[4] = {bus.AddNode("a"), bus.AddNode("b"), bus.AddNode("c"), bus.AddNode("d")};
    std::size_t n = 0;
    for (std::int64_t k = 0; k < 1000; ++k) {
      for (int i = 0; i < 4; ++i) {
        benchmark::DoNotOptimize(
            bus.Enqueue(nodes[i], bus::CanFrame::Classic(0x181 + i, bytes), k * 1'000'000));
      }
      n += bus.AdvanceTo((k + 1) * 1'000'000).size();
    }
    benchmark::DoNotOptimize(n);
  }
  state.SetItemsProcessed(state.iterations() * 4000);
}
BENCHMARK(BM_CanBusModelOneSecond4kFrames)->Unit(benchmark::kMicrosecond);

void BM_EncoderSample(benchmark::State& state) {
  EncoderModel enc(
      {.lines_per_rev = 2048, .missed_count_prob = 1e-4, .glitch_prob = 1e-4, .seed = 1});
  double angle = 0.0;
  for (auto _ : state) {
    angle += 0.01;
    benchmark::DoNotOptimize(enc.Sample(angle));
  }
}
BENCHMARK(BM_EncoderSample);

void BM_GyroSample(benchmark::State& state) {
  GyroModel gyro({.rate_hz = 1000.0,
                  .bias_random_walk_rad_s_sqrt_s = 1e-4,
                  .noise_density_rad_s_sqrt_hz = 1e-3,
                  .resolution_rad_s = 1e-4,
                  .range_rad_s = 5.0,
                  .bandwidth_hz = 50.0,
                  .seed = 1});
  for (auto _ : state) benchmark::DoNotOptimize(gyro.SampleRate(0.5));
}
BENCHMARK(BM_GyroSample);

void BM_Accelerometer3AxisSample(benchmark::State& state) {
  AccelerometerModel acc(
      {.r_BP_B = Eigen::Vector3d(0.2, 0.1, 0.0),
       .axes_B = {Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ()},
       .noise_density_m_s2_sqrt_hz = 1e-3,
       .seed = 1});
  BodyKinematics k;
  k.omega_WB_B = Eigen::Vector3d(0.0, 0.0, 1.0);
  for (auto _ : state) benchmark::DoNotOptimize(acc.Sample(k).data());
}
BENCHMARK(BM_Accelerometer3AxisSample);

}  // namespace
}  // namespace wheelhil::emulator

BENCHMARK_MAIN();
