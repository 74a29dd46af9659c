// Physics step cost: each platform alone on the analytic flat floor and on a mesh floor, and 16
// platforms in one world. Reports simulated seconds per wall second as the counter `realtime_x`
// (goal: >= 500 for one platform on the flat floor at 1 kHz, >= 200 on a mesh floor, linear in
// the number of platforms).

#include <string>

#include <benchmark/benchmark.h>

#include "emulator/physics/physics_world.h"
#include "emulator/platforms/platform.h"

namespace {

using wheelhil::emulator::Friction;
using wheelhil::emulator::MeshOptions;
using wheelhil::emulator::physics::PhysicsWorld;
using wheelhil::emulator::platforms::BodyTwist;
using wheelhil::emulator::platforms::CommandTwist;
using wheelhil::emulator::platforms::LoadPlatformFile;
using wheelhil::emulator::platforms::Platform;

const char* const kPlatforms[] = {"diff2", "mecanum4_omni3", "ortho3"};

void RunWorld(benchmark::State& state, const std::string& name, bool mesh, int count) {
  const Platform p =
      LoadPlatformFile(std::string(WHEELHIL_SOURCE_DIR) + "/scenarios/platforms/" + name + ".yaml");
  PhysicsWorld world;
  if (mesh) {
    world.terrain().AddMesh(std::string(WHEELHIL_SOURCE_DIR) + "/meshes/uneven_tiles.obj",
                            MeshOptions{});
  } else {
    world.terrain().AddPlane(Eigen::Vector3d::UnitZ(), Eigen::Vector3d::Zero(), Friction{0.8, 0.7});
  }
  for (int i = 0; i < count; ++i) {
    auto& v = world.AddVehicle(p.vehicle, -1.5 + 0.75 * (i % 4), -1.5 + 0.75 * (i / 4), 0);
    CommandTwist(v, p, BodyTwist{0.05, 0.0, 0.05});
  }
  world.StepFor(0.2);
  for (auto _ : state) world.Step();
  state.counters["realtime_x"] = benchmark::Counter(
      static_cast<double>(state.iterations()) * world.step_s(), benchmark::Counter::kIsRate);
  state.counters["vehicles"] = count;
}

void BM_PlatformFlat(benchmark::State& state) {
  RunWorld(state, kPlatforms[state.range(0)], false, 1);
  state.SetLabel(kPlatforms[state.range(0)]);
}
void BM_PlatformMesh(benchmark::State& state) {
  RunWorld(state, kPlatforms[state.range(0)], true, 1);
  state.SetLabel(kPlatforms[state.range(0)]);
}
void BM_ManyPlatformsFlat(benchmark::State& state) {
  RunWorld(state, "mecanum4_omni3", false, static_cast<int>(state.range(0)));
}

// Terrain::FrictionAt over N oil spots laid out like paper000_slip's random patches (two tracks
// along 9 m), queried at points along the tracks; reports ns per query.
void BM_FrictionPatchLookup(benchmark::State& state) {
  wheelhil::emulator::Terrain terrain;
  const int n = static_cast<int>(state.range(0));
  for (int k = 0; k < n; ++k) {
    const double x = 0.5 + 9.0 * (k + 0.5) / n, y = (k % 2 == 0) ? 0.16 : -0.16;
    wheelhil::emulator::FrictionPatch patch;
    patch.name = "spot";
    patch.polygon_W = {
        {x - 0.1, y - 0.06}, {x + 0.1, y - 0.06}, {x + 0.1, y + 0.06}, {x - 0.1, y + 0.06}};
    patch.friction = Friction{0.006, 0.0045};
    terrain.AddPatch(patch);
  }
  const Friction base{0.8, 0.7};
  double x = 0;
  double sum = 0;
  for (auto _ : state) {
    x = x > 10.0 ? 0.0 : x + 0.0013;
    sum += terrain.FrictionAt(Eigen::Vector3d(x, 0.16, 0), base).mu_peak;
    sum += terrain.FrictionAt(Eigen::Vector3d(x, -0.16, 0), base).mu_peak;
    sum += terrain.FrictionAt(Eigen::Vector3d(x, 0.0, 0), base).mu_peak;
    sum += terrain.FrictionAt(Eigen::Vector3d(x, 0.3, 0), base).mu_peak;
  }
  benchmark::DoNotOptimize(sum);
  state.SetItemsProcessed(state.iterations() * 4);
}

BENCHMARK(BM_PlatformFlat)->DenseRange(0, 2);
BENCHMARK(BM_FrictionPatchLookup)->Arg(16)->Arg(256);
BENCHMARK(BM_PlatformMesh)->DenseRange(0, 2);
BENCHMARK(BM_ManyPlatformsFlat)->Arg(1)->Arg(4)->Arg(16);

}  // namespace

BENCHMARK_MAIN();
