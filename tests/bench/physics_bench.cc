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

BENCHMARK(BM_PlatformFlat)->DenseRange(0, 2);
BENCHMARK(BM_PlatformMesh)->DenseRange(0, 2);
BENCHMARK(BM_ManyPlatformsFlat)->Arg(1)->Arg(4)->Arg(16);

}  // namespace

BENCHMARK_MAIN();
