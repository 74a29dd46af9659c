#include "firmware_stub/planar_pose.h"

#include <cmath>

namespace wheelhil::fw {

Pose2 AdvancePose(const Pose2& X_WB, double dx_B_m, double dy_B_m, double dtheta_rad,
                  HeadingRule rule) noexcept {
  double heading = X_WB.theta_rad;
  double scale = 1.0;
  if (rule != HeadingRule::kStart) heading += 0.5 * dtheta_rad;
  if (rule == HeadingRule::kExactArc) {
    const double h = 0.5 * dtheta_rad;
    // sin(h)/h; the series keeps full precision for tiny h.
    scale = std::abs(h) < 1e-4 ? 1.0 - h * h / 6.0 : std::sin(h) / h;
  }
  const double c = std::cos(heading);
  const double s = std::sin(heading);
  Pose2 out;
  out.x_m = X_WB.x_m + scale * (c * dx_B_m - s * dy_B_m);
  out.y_m = X_WB.y_m + scale * (s * dx_B_m + c * dy_B_m);
  out.theta_rad = X_WB.theta_rad + dtheta_rad;
  return out;
}

}  // namespace wheelhil::fw
