#pragma once
// Shared helpers for the physics tests: platform paths, a world with a floor, body-frame motion.

#include <cmath>
#include <memory>
#include <string>

#include "emulator/physics/physics_world.h"
#include "emulator/platforms/platform.h"

namespace wheelhil::emulator::testing {

inline std::string SourcePath(const std::string& rel) {
  return std::string(WHEELHIL_SOURCE_DIR) + "/" + rel;
}

inline platforms::Platform LoadShipped(const std::string& name) {
  return platforms::LoadPlatformFile(SourcePath("scenarios/platforms/" + name + ".yaml"));
}

/// One platform on a floor (plane by default) with mu_peak / mu_slide.
struct Rig {
  explicit Rig(const std::string& platform_name, double mu_peak = 0.8, double mu_slide = 0.7,
               double slope_deg = 0.0, double yaw = 0.0)
      : platform(LoadShipped(platform_name)) {
    const double s = slope_deg * M_PI / 180.0;
    world.terrain().AddPlane(Eigen::Vector3d(-std::sin(s), 0, std::cos(s)), Eigen::Vector3d::Zero(),
                             Friction{mu_peak, mu_slide});
    vehicle = &world.AddVehicle(platform.vehicle, 0, 0, yaw);
  }
  Rig(platforms::Platform p, bool /*no_floor*/) : platform(std::move(p)) {}

  void Command(double vx, double vy, double wz) {
    platforms::CommandTwist(*vehicle, platform, platforms::BodyTwist{vx, vy, wz});
  }
  physics::PhysicsWorld world;
  platforms::Platform platform;
  physics::RollerVehicle* vehicle = nullptr;
};

}  // namespace wheelhil::emulator::testing
