#include "emulator/physics/physics_world.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <btBulletDynamicsCommon.h>
#include <fmt/format.h>

#include "emulator/physics/collision_configuration.h"

namespace wheelhil::emulator::physics {
namespace {

// Every chassis is added with collision mask 0 and the terrain lives in a collision world of
// its own, so Bullet's collision detection in this world never finds a pair: per step it only
// refreshes broadphase AABBs nobody reads. Its one effect on the dynamics is the guard in
// btCollisionWorld::updateSingleAabb, which disables a body whose swept AABB is not finite or
// longer than 1e6 m (a blown-up state). The pass is skipped only while every object is a
// mask-0 rigid body whose state keeps that guard far away (finite, swept extent under 1e5 m);
// otherwise Bullet's own pass runs, so the results are those of Bullet's pass either way.
class NoPairsDynamicsWorld : public btDiscreteDynamicsWorld {
 public:
  using btDiscreteDynamicsWorld::btDiscreteDynamicsWorld;

  void performDiscreteCollisionDetection() override {
    if (!CollisionPassChangesNothing())
      btDiscreteDynamicsWorld::performDiscreteCollisionDetection();
  }

 private:
  bool CollisionPassChangesNothing() {
    const btScalar dt = getDispatchInfo().m_timeStep;
    for (int i = 0; i < m_collisionObjects.size(); ++i) {
      const btCollisionObject* o = m_collisionObjects[i];
      const btRigidBody* b = btRigidBody::upcast(o);
      if (b == nullptr || o->getBroadphaseHandle() == nullptr ||
          o->getBroadphaseHandle()->m_collisionFilterMask != 0) {
        return false;
      }
      const btTransform& X = o->getWorldTransform();
      const btVector3& v = b->getLinearVelocity();
      const btVector3& w = b->getAngularVelocity();
      btVector3 lo, hi;
      o->getCollisionShape()->getAabb(btTransform::getIdentity(), lo, hi);
      const btScalar size = (hi - lo).length();
      const btScalar reach = 2 * size + v.length() * dt;
      if (!(std::isfinite(X.getOrigin().length2()) && std::isfinite(X.getBasis()[0].length2()) &&
            std::isfinite(X.getBasis()[1].length2()) && std::isfinite(X.getBasis()[2].length2()) &&
            std::isfinite(w.length2()) && std::isfinite(reach) && reach < btScalar(1e5))) {
        return false;
      }
    }
    return true;
  }
};

}  // namespace

PhysicsWorld::PhysicsWorld(const WorldOptions& options)
    : step_s_(options.step_s), gravity_W_(options.gravity_W) {
  if (!(std::isfinite(step_s_) && step_s_ > 0 && step_s_ <= 0.1)) {
    throw std::invalid_argument(
        fmt::format("world: step_s ({}) must be finite and in (0, 0.1]", step_s_));
  }
  if (!gravity_W_.allFinite()) throw std::invalid_argument("world: gravity_W: must be finite");
  terrain_ = std::make_unique<Terrain>();
  config_ = MakeCollisionConfiguration();
  dispatcher_ = std::make_unique<btCollisionDispatcher>(config_.get());
  broadphase_ = std::make_unique<btDbvtBroadphase>();
  solver_ = std::make_unique<btSequentialImpulseConstraintSolver>();
  world_ = std::make_unique<NoPairsDynamicsWorld>(dispatcher_.get(), broadphase_.get(),
                                                  solver_.get(), config_.get());
  world_->setGravity(btVector3(0, 0, 0));  // vehicles apply gravity with their contacts
  world_->setInternalTickCallback(&PhysicsWorld::PreTick, this, /*isPreTick=*/true);
}

PhysicsWorld::~PhysicsWorld() {
  for (auto& v : vehicles_) {
    world_->removeAction(v.get());
    world_->removeRigidBody(v->chassis());
  }
}

void PhysicsWorld::PreTick(btDynamicsWorld* world, float /*dt*/) {
  auto* self = static_cast<PhysicsWorld*>(world->getWorldUserInfo());
  for (auto& v : self->vehicles_) v->PreStep(self->step_s_);
}

RollerVehicle& PhysicsWorld::AddVehicleAt(const VehicleSpec& spec, const Eigen::Isometry3d& X_WB) {
  auto v = std::make_unique<RollerVehicle>(spec, terrain_.get(), X_WB, gravity_W_);
  // Group 1, mask 0: the chassis takes part in no collision pair at all.
  world_->addRigidBody(v->chassis(), /*group=*/1, /*mask=*/0);
  world_->addAction(v.get());
  vehicles_.push_back(std::move(v));
  return *vehicles_.back();
}

RollerVehicle& PhysicsWorld::AddVehicle(const VehicleSpec& spec, double x, double y, double yaw) {
  SurfaceHit hit;
  if (!terrain_->Raycast(Eigen::Vector3d(x, y, 1e3), -Eigen::Vector3d::UnitZ(), 2e3, &hit)) {
    throw std::invalid_argument(
        fmt::format("vehicle '{}': start position ({}, {}): no floor under it", spec.name, x, y));
  }
  // Orientation: z along the floor normal, x at heading yaw (projected onto the floor).
  const Eigen::Vector3d z = hit.normal_W;
  Eigen::Vector3d x_dir(std::cos(yaw), std::sin(yaw), 0);
  x_dir = (x_dir - z * z.dot(x_dir)).normalized();
  const Eigen::Vector3d y_dir = z.cross(x_dir);
  Eigen::Matrix3d R;
  R.col(0) = x_dir;
  R.col(1) = y_dir;
  R.col(2) = z;
  // Height: the mean over wheels of the static equilibrium (load shared evenly).
  const double share =
      spec.mass_kg * gravity_W_.norm() / std::max<std::size_t>(1, spec.wheels.size());
  double h = 0;
  for (const auto& w : spec.wheels) {
    const auto& q = w.suspension;
    const double len =
        std::clamp(q.free_length_m - share / q.stiffness_n_m, q.min_length_m, q.max_length_m);
    h += w.radius_m + len - w.mount_B.z();
  }
  h /= std::max<std::size_t>(1, spec.wheels.size());
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = R;
  X.translation() = hit.point_W + z * h;
  return AddVehicleAt(spec, X);
}

void PhysicsWorld::Step() noexcept {
  const auto dt = static_cast<btScalar>(step_s_);
  world_->stepSimulation(dt, /*maxSubSteps=*/0, dt);
  ++steps_;
}

void PhysicsWorld::StepFor(double duration_s) noexcept {
  const auto n = static_cast<std::int64_t>(std::llround(duration_s / step_s_));
  for (std::int64_t i = 0; i < n; ++i) Step();
}

}  // namespace wheelhil::emulator::physics
