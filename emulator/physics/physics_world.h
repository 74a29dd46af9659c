#pragma once
/// The physics world: a Bullet btDiscreteDynamicsWorld stepped at a fixed step (1 kHz default),
/// a Terrain, and RollerVehicles whose wheel forces are solved in Bullet's pre-tick callback (so
/// they act within the same step). No wall clock, single-threaded: the same inputs give
/// bit-identical trajectories. Chassis do not collide with each other or with the terrain; the
/// wheels carry them. Thread-compatible.

#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "emulator/physics/roller_vehicle.h"
#include "emulator/physics/terrain.h"
#include "emulator/physics/vehicle_spec.h"

class btDefaultCollisionConfiguration;
class btCollisionDispatcher;
class btBroadphaseInterface;
class btSequentialImpulseConstraintSolver;
class btDiscreteDynamicsWorld;
class btDynamicsWorld;

namespace wheelhil::emulator::physics {

struct WorldOptions {
  double step_s = 1e-3;                                      ///< fixed step, s
  Eigen::Vector3d gravity_W = Eigen::Vector3d(0, 0, -9.81);  ///< m/s^2
};

class PhysicsWorld {
 public:
  /// Throws std::invalid_argument if step_s is not in (0, 0.1] or gravity is not finite.
  explicit PhysicsWorld(const WorldOptions& options = {});
  ~PhysicsWorld();
  PhysicsWorld(const PhysicsWorld&) = delete;
  PhysicsWorld& operator=(const PhysicsWorld&) = delete;

  /// The floor. Add planes/meshes/patches before adding vehicles.
  [[nodiscard]] Terrain& terrain() noexcept { return *terrain_; }

  /// Adds a vehicle standing on the terrain under (x, y) with heading yaw (about the floor
  /// normal there), its suspension near static equilibrium. Throws if there is no floor there
  /// or the spec is invalid.
  RollerVehicle& AddVehicle(const VehicleSpec& spec, double x_m, double y_m, double yaw_rad);
  /// Adds a vehicle at an explicit chassis pose.
  RollerVehicle& AddVehicleAt(const VehicleSpec& spec, const Eigen::Isometry3d& X_WB);

  /// Advances one fixed step.
  void Step() noexcept;
  /// Advances round(duration_s / step_s) steps.
  void StepFor(double duration_s) noexcept;

  [[nodiscard]] double time_s() const noexcept { return static_cast<double>(steps_) * step_s_; }
  [[nodiscard]] std::int64_t step_count() const noexcept { return steps_; }
  [[nodiscard]] double step_s() const noexcept { return step_s_; }
  [[nodiscard]] std::size_t vehicle_count() const noexcept { return vehicles_.size(); }
  [[nodiscard]] RollerVehicle& vehicle(std::size_t i) noexcept { return *vehicles_[i]; }

 private:
  static void PreTick(btDynamicsWorld* world, float dt);

  double step_s_;
  Eigen::Vector3d gravity_W_;
  std::int64_t steps_ = 0;
  std::unique_ptr<Terrain> terrain_;
  std::unique_ptr<btDefaultCollisionConfiguration> config_;
  std::unique_ptr<btCollisionDispatcher> dispatcher_;
  std::unique_ptr<btBroadphaseInterface> broadphase_;
  std::unique_ptr<btSequentialImpulseConstraintSolver> solver_;
  std::unique_ptr<btDiscreteDynamicsWorld> world_;
  std::vector<std::unique_ptr<RollerVehicle>> vehicles_;
};

}  // namespace wheelhil::emulator::physics
