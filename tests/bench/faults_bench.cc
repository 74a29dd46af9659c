// Cost of the accelerometer / DBC IMU nodes and of the fault filters on their frames.
#include <benchmark/benchmark.h>

#include <cstdint>
#include <memory>
#include <vector>

#include "bus/dbc.h"
#include "emulator/devices/accel4_node.h"
#include "emulator/devices/frame_checksum.h"
#include "emulator/faults/frame_faults.h"
#include "emulator/faults/sensor_faults.h"

namespace wheelhil::emulator {
namespace {

std::shared_ptr<const bus::DbcDatabase> Accel4Dbc() {
  static const auto db = std::make_shared<const bus::DbcDatabase>(
      bus::DbcDatabase::LoadFile(WHEELHIL_SOURCE_DIR "/bus/dbc/wheelhil_accel4.dbc"));
  return db;
}

// One 0x170 frame: four sensor samples, DBC encoding, counter and checksum.
void BM_Accel4NodeSample(benchmark::State& state) {
  auto params = Paper002AccelParams(0.15, 1000.0, 1);
  for (auto& p : params) p.noise_density_m_s2_sqrt_hz = 0.002;
  Accel4Node node(Accel4Dbc(), params, 0);
  BodyKinematics k;
  k.a_WBo_B = {0.3, -0.2, 0.0};
  k.omega_WB_B = {0, 0, 1.5};
  bus::CanFrame f;
  for (auto _ : state) {
    benchmark::DoNotOptimize(node.Sample(k, f));
    benchmark::DoNotOptimize(f);
  }
}
BENCHMARK(BM_Accel4NodeSample);

// A frame through a filter with all four content faults active (wrong counter re-encodes via the
// DBC and re-computes the checksum).
void BM_FrameFaultFilterContentFaults(benchmark::State& state) {
  std::vector<FrameFault> faults(4);
  faults[0].kind = FrameFaultKind::kDrop;
  faults[0].probability = 0.0;
  faults[1].kind = FrameFaultKind::kCorrupt;
  faults[2].kind = FrameFaultKind::kWrongCounter;
  faults[2].counter_signal = "ACC4_Counter";
  faults[2].checksum_signal = "ACC4_Checksum";
  faults[3].kind = FrameFaultKind::kWrongChecksum;
  faults[3].checksum_signal = "ACC4_Checksum";
  for (auto& f : faults) f.id = 0x170;
  FrameFaultFilter filter(faults, Accel4Dbc(), 1);
  Accel4Node node(Accel4Dbc(), Paper002AccelParams(0.15, 1000.0, 1), 0);
  std::vector<NodeFrame> in(1);
  node.EncodeSample({1.0, 2.0, 3.0, 4.0}, in[0].frame);
  std::int64_t t = 0;
  for (auto _ : state) {
    in[0].due_ns = t;
    benchmark::DoNotOptimize(filter.Process(in, t));
    t += 1'000'000;
  }
}
BENCHMARK(BM_FrameFaultFilterContentFaults);

void BM_SensorFaultInjectorNoiseBias(benchmark::State& state) {
  SensorFaultInjector inj(
      "gyro", {{SensorFaultKind::kBiasStep, {0}, 0.01}, {SensorFaultKind::kNoiseScale, {0}, 3.0}},
      0.001, 1);
  std::int64_t t = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(inj.Apply(0.5, t));
    t += 1'000'000;
  }
}
BENCHMARK(BM_SensorFaultInjectorNoiseBias);

void BM_Crc8SaeJ1850EightBytes(benchmark::State& state) {
  std::uint8_t bytes[8] = {1, 2, 3, 4, 5, 6, 7, 8};
  for (auto _ : state) {
    ++bytes[0];
    benchmark::DoNotOptimize(Crc8SaeJ1850(bytes));
  }
}
BENCHMARK(BM_Crc8SaeJ1850EightBytes);

}  // namespace
}  // namespace wheelhil::emulator

BENCHMARK_MAIN();
