#pragma once
/// Bullet's collision configuration for this module's worlds, which make no contact pairs: the
/// vehicles' chassis collide with nothing (their wheels are ray casts) and the terrain's world
/// holds static meshes only, ray-cast against. Bullet's default pools (4096 persistent manifolds
/// and 4096 collision algorithms, written in full when made: ~1.5 ms of page faults in every run)
/// go unused there; a pool that runs out falls back to the heap, so small ones change nothing.

#include <memory>

#include <btBulletCollisionCommon.h>

namespace wheelhil::emulator::physics {

inline std::unique_ptr<btDefaultCollisionConfiguration> MakeCollisionConfiguration() {
  btDefaultCollisionConstructionInfo info;
  info.m_defaultMaxPersistentManifoldPoolSize = 16;
  info.m_defaultMaxCollisionAlgorithmPoolSize = 16;
  return std::make_unique<btDefaultCollisionConfiguration>(info);
}

}  // namespace wheelhil::emulator::physics
