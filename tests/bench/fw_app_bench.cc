// Per-cycle cost of the firmware program's frame path (no sockets): decode, cycle assembly,
// estimator step, output encoding. Run: build-*/bin/fw_app_bench
#include <benchmark/benchmark.h>

#include <cmath>
#include <vector>

#include "bus/dbc.h"
#include "bus/dbc_codec.h"
#include "firmware_stub/fw_app.h"

namespace {

using namespace wheelhil;

const std::string kDbc = std::string(WHEELHIL_SOURCE_DIR) + "/bus/dbc";

const char* kPaper002 = R"(
estimator: paper002
canopen: {heartbeat_period_s: 0, heartbeat_timeout_s: 0, tpdo_transmission_type: 0}
sync: {period_s: 0.001}
accel: {frame_id: 0x170}
paper002:
  wheel_radius_m: 0.05
  wheel_mount_radius_m: 0.2
  counts_per_rev: 4096
  wheels:
    - {node_id: 1, angle_deg: 0}
    - {node_id: 2, angle_deg: 120}
    - {node_id: 3, angle_deg: 240}
  accel_mount_radius_m: 0.15
)";

bus::CanFrame Tpdo(const bus::DbcDatabase& db, int node, std::uint32_t pos) {
  return bus::EncodeMessage(*db.FindMessage(0x180 + node, false),
                            {{"PositionValue", static_cast<double>(pos)}, {"SpeedValue", 0}});
}

/// One 1 ms paper-002 cycle: SYNC out, accel + 3 TPDO1 in, 5 output frames out.
void BM_FwAppCyclePaper002(benchmark::State& state) {
  const fw::FwConfig c = fw::ParseFwConfig(kPaper002, "bench.yaml");
  const fw::FwProtocol p = fw::FwProtocol::LoadDir(kDbc, {1, 2, 3}, 0, 0x170);
  const auto co = bus::DbcDatabase::LoadFile(kDbc + "/cia406_encoder.dbc");
  fw::FwApp app(c, p);
  std::vector<bus::CanFrame> out;
  out.reserve(64);
  std::int64_t t = 0;
  app.Start(t, out);
  for (int n = 1; n <= 3; ++n) {
    bus::CanFrame boot;
    boot.id = 0x700u + n;
    boot.len = 1;
    app.OnFrame(boot, t, out);
  }
  bus::CanFrame accel;
  accel.id = 0x170;
  accel.len = 8;  // All-zero channels, counter 0, checksum 0: valid.
  std::uint32_t k = 0;
  std::vector<bus::CanFrame> tpdos(3);
  for (auto _ : state) {
    state.PauseTiming();
    for (int n = 0; n < 3; ++n) tpdos[n] = Tpdo(co, n + 1, k * (n + 1));
    accel.data[7] = static_cast<std::uint8_t>((k & 15) | ((k & 15) << 4));
    ++k;
    out.clear();
    state.ResumeTiming();
    t += 1'000'000;
    app.OnFrame(accel, t, out);
    app.Poll(t, out);  // SYNC.
    for (const auto& f : tpdos) app.OnFrame(f, t, out);
    benchmark::DoNotOptimize(out.data());
  }
  if (app.stats().cycles != static_cast<std::uint64_t>(state.iterations())) {
    state.SkipWithError("not one closed cycle per iteration");
  }
}
BENCHMARK(BM_FwAppCyclePaper002);

void BM_ClassifyAndDecodeTpdo(benchmark::State& state) {
  const fw::FwProtocol p = fw::FwProtocol::LoadDir(kDbc, {1, 2, 3}, 0, 0);
  const auto co = bus::DbcDatabase::LoadFile(kDbc + "/cia406_encoder.dbc");
  const bus::CanFrame f = Tpdo(co, 2, 123456);
  for (auto _ : state) {
    std::uint8_t node = 0;
    std::uint32_t pos = 0;
    std::int16_t speed = 0;
    benchmark::DoNotOptimize(p.Classify(f, node));
    benchmark::DoNotOptimize(p.DecodeTpdo1(f, pos, speed));
    benchmark::DoNotOptimize(pos);
  }
}
BENCHMARK(BM_ClassifyAndDecodeTpdo);

void BM_EncodeStatusFrame(benchmark::State& state) {
  const fw::FwProtocol p = fw::FwProtocol::LoadDir(kDbc, {1, 2}, 0, 0);
  fw::OutValues v;
  v.Set(fw::OutField::kCycle, 17);
  v.Set(fw::OutField::kState, 3);
  v.Set(fw::OutField::kBadFrameCount, 5);
  bus::CanFrame f;
  for (auto _ : state) {
    benchmark::DoNotOptimize(p.EncodeOutput(fw::OutMessage::kStatus, v, f));
    benchmark::DoNotOptimize(f.data.data());
  }
}
BENCHMARK(BM_EncodeStatusFrame);

}  // namespace

BENCHMARK_MAIN();
