#include "firmware_stub/paper001_follower_odometry.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <numbers>
#include <stdexcept>

#include "firmware_stub/encoder_counter.h"

namespace wheelhil::fw {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

constexpr double kD = 0.20;      // Follower mount radius [m].
constexpr double kR = 0.025;     // Follower radius [m].
constexpr double kCpr = 4096.0;  // Counts per revolution.
const double kSqrt3 = std::sqrt(3.0);

FollowerOdometryConfig Config(HeadingRule rule, int bits = 32) {
  FollowerOdometryConfig c;
  c.geometry.mount_radius_m = kD;
  c.follower_radius_m = kR;
  c.counts_per_rev = kCpr;
  c.counter_bits = bits;
  c.heading_rule = rule;
  return c;
}

TEST(FollowerKinematics, DefaultAnglesReproduceThePapersEq2Matrix) {
  FollowerGeometry g;
  g.mount_radius_m = kD;
  const FollowerTwist v{0.3, -0.7, 1.1};
  const auto rim = FollowerRimSpeeds(g, v);
  EXPECT_NEAR(rim[0], -v.vx_m_s + kD * v.omega_rad_s, 1e-15);
  EXPECT_NEAR(rim[1], 0.5 * v.vx_m_s - kSqrt3 / 2 * v.vy_m_s + kD * v.omega_rad_s, 1e-15);
  EXPECT_NEAR(rim[2], 0.5 * v.vx_m_s + kSqrt3 / 2 * v.vy_m_s + kD * v.omega_rad_s, 1e-15);
}

TEST(FollowerKinematics, Eq5AndEq2RoundTripRecoversTheBodyVelocity) {
  FollowerGeometry g;
  g.mount_radius_m = kD;
  for (const FollowerTwist v : {FollowerTwist{0.0, 0.5, 0.0}, FollowerTwist{0.5, 0.0, 0.0},
                                FollowerTwist{0.0, 0.0, -1.0}, FollowerTwist{0.2, -0.4, 0.7}}) {
    const auto rim = FollowerRimSpeeds(g, v);
    const FollowerTwist b = BodyTwistFromRimSpeeds(g, rim);
    EXPECT_NEAR(b.vx_m_s, v.vx_m_s, 1e-14);
    EXPECT_NEAR(b.vy_m_s, v.vy_m_s, 1e-14);
    EXPECT_NEAR(b.omega_rad_s, v.omega_rad_s, 1e-14);
    for (double th : {0.0, 0.6, -2.5}) {
      // Eq 5 written out, as printed in the paper.
      const double c = std::cos(th), s = std::sin(th);
      const double xd =
          -2.0 / 3 * c * rim[0] + (c + kSqrt3 * s) / 3 * rim[1] + (c - kSqrt3 * s) / 3 * rim[2];
      const double yd =
          -2.0 / 3 * s * rim[0] + (s - kSqrt3 * c) / 3 * rim[1] + (s + kSqrt3 * c) / 3 * rim[2];
      const double thd = (rim[0] + rim[1] + rim[2]) / (3 * kD);
      const FollowerTwist w = WorldTwistFromRimSpeeds(g, rim, th);
      EXPECT_NEAR(w.vx_m_s, xd, 1e-14);
      EXPECT_NEAR(w.vy_m_s, yd, 1e-14);
      EXPECT_NEAR(w.omega_rad_s, thd, 1e-14);
      EXPECT_NEAR(w.vx_m_s, c * v.vx_m_s - s * v.vy_m_s, 1e-14);
      EXPECT_NEAR(w.vy_m_s, s * v.vx_m_s + c * v.vy_m_s, 1e-14);
    }
  }
}

TEST(FollowerKinematics, NonDefaultAnglesRoundTrip) {
  FollowerGeometry g;
  g.mount_radius_m = 0.15;
  g.angles_rad = {0.1, 2.0, 4.0};  // Not 120 deg apart, still independent.
  const FollowerTwist v{-0.2, 0.35, 0.4};
  const FollowerTwist b = BodyTwistFromRimSpeeds(g, FollowerRimSpeeds(g, v));
  EXPECT_NEAR(b.vx_m_s, v.vx_m_s, 1e-13);
  EXPECT_NEAR(b.vy_m_s, v.vy_m_s, 1e-13);
  EXPECT_NEAR(b.omega_rad_s, v.omega_rad_s, 1e-13);
}

TEST(FollowerKinematics, ForwardFrameConversion) {
  const FollowerTwist f = PaperToForwardTwist({0.1, 0.5, 0.2});  // Right 0.1, forward 0.5.
  EXPECT_DOUBLE_EQ(f.vx_m_s, 0.5);
  EXPECT_DOUBLE_EQ(f.vy_m_s, -0.1);  // Right is -y in an x-forward, y-left frame.
  const Pose2 p = PaperToForwardPose({1.0, 3.0, 0.4});
  EXPECT_DOUBLE_EQ(p.x_m, 3.0);
  EXPECT_DOUBLE_EQ(p.y_m, -1.0);
  EXPECT_DOUBLE_EQ(p.theta_rad, 0.4);
}

// Drives the odometry with the counts a constant body twist v_P produces, sampled every T
// (rounded cumulative counts, as a real counter would hold), starting at raw value `offset`.
Pose2 RunConstantTwist(FollowerOdometry& odo, const FollowerTwist& v, double T, int steps,
                       std::uint64_t offset) {
  const auto rim = FollowerRimSpeeds(odo.config().geometry, v);
  odo.Reset();
  auto raw = [&](int k) {
    std::array<std::uint64_t, 3> r{};
    for (int j = 0; j < 3; ++j) {
      const double counts = std::round(MetersToCounts(rim[j] * T * k, kCpr, kR));
      r[j] = offset + static_cast<std::uint64_t>(static_cast<std::int64_t>(counts));
    }
    return r;
  };
  for (int k = 0; k <= steps; ++k) odo.UpdateCounts(raw(k));
  return odo.pose();
}

// Closed-form pose in V after time t of constant body twist v (in P).
Pose2 AnalyticPose(const FollowerTwist& v, double t) {
  const double w = v.omega_rad_s;
  if (std::abs(w) < 1e-12) return {v.vx_m_s * t, v.vy_m_s * t, 0.0};
  const double th = w * t;
  const double s = std::sin(th), c = std::cos(th);
  return {(s * v.vx_m_s - (1 - c) * v.vy_m_s) / w, ((1 - c) * v.vx_m_s + s * v.vy_m_s) / w, th};
}

TEST(FollowerOdometry, StraightLineForwardSidewaysAndDiagonal) {
  FollowerOdometry odo(Config(HeadingRule::kStart));
  const double count_m = CountsToMeters(1, kCpr, kR);  // 38 um.
  for (const FollowerTwist v :
       {FollowerTwist{0.0, 0.4, 0.0}, FollowerTwist{0.4, 0.0, 0.0},
        FollowerTwist{0.4 / std::numbers::sqrt2, 0.4 / std::numbers::sqrt2, 0.0}}) {
    const Pose2 p = RunConstantTwist(odo, v, 0.01, 500, 0);  // 5 s, 2 m.
    const Pose2 truth = AnalyticPose(v, 5.0);
    // Rounded counts: heading error <= 3 * 0.5 count / (3d); position error stays of the order
    // of a count plus that heading error times the distance.
    EXPECT_NEAR(p.theta_rad, 0.0, 0.5 * count_m / kD + 1e-12);
    EXPECT_NEAR(p.x_m, truth.x_m, 2 * count_m + 2.0 * 0.5 * count_m / kD);
    EXPECT_NEAR(p.y_m, truth.y_m, 2 * count_m + 2.0 * 0.5 * count_m / kD);
  }
}

TEST(FollowerOdometry, ConstantTwistArcMatchesTheAnalyticArc) {
  const FollowerTwist v{0.1, 0.3, 0.5};  // Forward-right while turning left.
  const double T = 0.01;
  const int steps = 1000;  // 10 s, 5 rad, 3.2 m.
  const Pose2 truth = AnalyticPose(v, steps * T);

  FollowerOdometry exact(Config(HeadingRule::kExactArc));
  const Pose2 pe = RunConstantTwist(exact, v, T, steps, 0);
  const double count_m = CountsToMeters(1, kCpr, kR);
  EXPECT_NEAR(pe.theta_rad, truth.theta_rad, 0.5 * count_m / kD + 1e-12);
  EXPECT_LT(std::hypot(pe.x_m - truth.x_m, pe.y_m - truth.y_m), 0.5e-3);

  FollowerOdometry mid(Config(HeadingRule::kMidpoint));
  const Pose2 pm = RunConstantTwist(mid, v, T, steps, 0);
  EXPECT_LT(std::hypot(pm.x_m - truth.x_m, pm.y_m - truth.y_m), 0.5e-3);

  // Paper eq 8 (heading at the start of the period): for a constant twist every step is the
  // exact one turned by -h and stretched by 1/sinc(h), h = omega*T/2, so the end point is the
  // true one mapped by that same similarity about the start: error = |e^{-ih}/sinc(h) - 1| |p|.
  FollowerOdometry start(Config(HeadingRule::kStart));
  const Pose2 ps = RunConstantTwist(start, v, T, steps, 0);
  const double h = v.omega_rad_s * T / 2;
  const double stretch = h / std::sin(h);
  const double predicted = std::hypot(stretch * std::cos(h) - 1.0, stretch * std::sin(h)) *
                           std::hypot(truth.x_m, truth.y_m);
  const double err_start = std::hypot(ps.x_m - truth.x_m, ps.y_m - truth.y_m);
  std::printf(
      "constant twist 10 s: error exact-arc %.3f mm, midpoint %.3f mm, eq-8 start %.3f mm"
      " (predicted %.3f mm)\n",
      1e3 * std::hypot(pe.x_m - truth.x_m, pe.y_m - truth.y_m),
      1e3 * std::hypot(pm.x_m - truth.x_m, pm.y_m - truth.y_m), 1e3 * err_start, 1e3 * predicted);
  EXPECT_NEAR(err_start, predicted, 0.3e-3);
  EXPECT_GT(err_start, 1e-3);
}

TEST(FollowerOdometry, SpinInPlaceClockwise) {
  FollowerOdometry odo(Config(HeadingRule::kStart));
  const FollowerTwist v{0.0, 0.0, -std::numbers::pi / 4};  // Clockwise, 2 turns in 16 s.
  const Pose2 p = RunConstantTwist(odo, v, 0.02, 800, 0);
  EXPECT_NEAR(p.theta_rad, -4 * std::numbers::pi, 0.5 * CountsToMeters(1, kCpr, kR) / kD);
  EXPECT_NEAR(p.x_m, 0.0, 1e-3);
  EXPECT_NEAR(p.y_m, 0.0, 1e-3);
}

TEST(FollowerOdometry, CounterWrapIsInvisible) {
  const FollowerTwist v{0.1, 0.3, 0.5};
  FollowerOdometry a(Config(HeadingRule::kExactArc, 32));
  FollowerOdometry b(Config(HeadingRule::kExactArc, 32));
  FollowerOdometry c(Config(HeadingRule::kExactArc, 16));
  const Pose2 pa = RunConstantTwist(a, v, 0.01, 1000, 1u << 20);
  const Pose2 pb = RunConstantTwist(b, v, 0.01, 1000, 0xFFFFFFFFull - 500);  // Wraps at once.
  const Pose2 pc = RunConstantTwist(c, v, 0.01, 1000, 0xFF00);  // Wraps a 16-bit counter.
  EXPECT_EQ(pa.x_m, pb.x_m);
  EXPECT_EQ(pa.y_m, pb.y_m);
  EXPECT_EQ(pa.theta_rad, pb.theta_rad);
  EXPECT_EQ(pa.x_m, pc.x_m);
  EXPECT_EQ(pa.theta_rad, pc.theta_rad);
  EXPECT_NE(pa.x_m, 0.0);
}

TEST(FollowerOdometry, RejectsBadConfigAndInput) {
  auto c = Config(HeadingRule::kStart);
  c.follower_radius_m = 0.0;
  EXPECT_THAT([&] { FollowerOdometry{c}; },
              ThrowsMessage<std::invalid_argument>(HasSubstr("follower_radius_m (0)")));
  c = Config(HeadingRule::kStart);
  c.geometry.angles_rad = {0.0, std::numbers::pi, 2 * std::numbers::pi};  // Collinear.
  EXPECT_THAT([&] { FollowerOdometry{c}; },
              ThrowsMessage<std::invalid_argument>(HasSubstr("degenerate")));
  c = Config(HeadingRule::kStart, 65);
  EXPECT_THAT([&] { FollowerOdometry{c}; },
              ThrowsMessage<std::invalid_argument>(HasSubstr("counter_bits (65)")));
  FollowerOdometry odo(Config(HeadingRule::kStart));
  EXPECT_FALSE(odo.StepRimDisplacements({0.0, NAN, 0.0}));
  EXPECT_EQ(odo.pose().x_m, 0.0);
}

}  // namespace
}  // namespace wheelhil::fw
