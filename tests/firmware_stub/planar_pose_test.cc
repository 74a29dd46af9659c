#include "firmware_stub/planar_pose.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

namespace wheelhil::fw {
namespace {

// One step of a constant twist (v forward, w turn) over dt from heading th0 at the origin.
Pose2 ExactArc(double v, double w, double dt, double th0) {
  const double th1 = th0 + w * dt;
  return {v / w * (std::sin(th1) - std::sin(th0)), -v / w * (std::cos(th1) - std::cos(th0)), th1};
}

TEST(AdvancePose, StraightLineIsTheSameForEveryRule) {
  const Pose2 start{1.0, 2.0, std::numbers::pi / 2};
  for (HeadingRule rule : {HeadingRule::kStart, HeadingRule::kMidpoint, HeadingRule::kExactArc}) {
    const Pose2 p = AdvancePose(start, 0.5, 0.0, 0.0, rule);
    EXPECT_NEAR(p.x_m, 1.0, 1e-15);
    EXPECT_NEAR(p.y_m, 2.5, 1e-15);
    EXPECT_DOUBLE_EQ(p.theta_rad, start.theta_rad);
  }
}

TEST(AdvancePose, ExactArcMatchesTheCircleAndOthersErrAsPredicted) {
  const double v = 0.4, w = 0.8, dt = 0.5, th0 = 0.3;
  const Pose2 truth = ExactArc(v, w, dt, th0);
  const Pose2 start{0.0, 0.0, th0};
  const Pose2 exact = AdvancePose(start, v * dt, 0.0, w * dt, HeadingRule::kExactArc);
  EXPECT_NEAR(exact.x_m, truth.x_m, 1e-15);
  EXPECT_NEAR(exact.y_m, truth.y_m, 1e-15);
  EXPECT_DOUBLE_EQ(exact.theta_rad, truth.theta_rad);

  // Midpoint: right direction, chord too long by ds*(1 - sinc(dth/2)) ~ ds*dth^2/24.
  const Pose2 mid = AdvancePose(start, v * dt, 0.0, w * dt, HeadingRule::kMidpoint);
  const double mid_err = std::hypot(mid.x_m - truth.x_m, mid.y_m - truth.y_m);
  const double h = w * dt / 2;
  EXPECT_NEAR(mid_err, v * dt * (1.0 - std::sin(h) / h), 1e-15);

  // Start heading: error ~ ds*dth/2.
  const Pose2 st = AdvancePose(start, v * dt, 0.0, w * dt, HeadingRule::kStart);
  const double st_err = std::hypot(st.x_m - truth.x_m, st.y_m - truth.y_m);
  EXPECT_NEAR(st_err, v * dt * w * dt / 2, 0.05 * v * dt * w * dt / 2);
  EXPECT_GT(st_err, 10 * mid_err);
}

TEST(AdvancePose, LateralDisplacementRotatesWithHeading) {
  const Pose2 p = AdvancePose({0.0, 0.0, std::numbers::pi / 2}, 0.0, 1.0, 0.0, HeadingRule::kStart);
  EXPECT_NEAR(p.x_m, -1.0, 1e-15);  // Body +y (left) points to world -x when facing +y.
  EXPECT_NEAR(p.y_m, 0.0, 1e-15);
}

TEST(AdvancePose, TinyTurnUsesTheSeriesWithoutLosingPrecision) {
  const Pose2 p = AdvancePose({}, 1.0, 0.0, 1e-9, HeadingRule::kExactArc);
  EXPECT_NEAR(p.x_m, 1.0, 1e-15);
  EXPECT_NEAR(p.y_m, 0.5e-9, 1e-20);
}

}  // namespace
}  // namespace wheelhil::fw
