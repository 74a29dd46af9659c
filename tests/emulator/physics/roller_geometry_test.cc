// Discrete-roller geometry (emulator/physics/roller_geometry.h) against an independent
// computation: the lowest point of the ellipsoid roller found by searching its surface, the
// roller axis rotated with the wheel, and the closed forms of the MuJoCo peer's wheel.

#include "emulator/physics/roller_geometry.h"

#include <cmath>
#include <numbers>
#include <stdexcept>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <Eigen/Geometry>

namespace wheelhil::emulator::physics {
namespace {

constexpr double kPi = std::numbers::pi;

// The MuJoCo peer's wheel (gen_model.py): R 50 mm, 10 rollers, semi-axes 8 / 8 / 27.13 mm.
WheelSpec PeerWheel(double roller_angle_deg = -45) {
  WheelSpec w;
  w.name = "peer";
  w.kind = WheelKind::kMecanum;
  w.radius_m = 0.05;
  w.roller_angle_rad = roller_angle_deg * kPi / 180;
  w.rollers.count = 10;
  w.rollers.length_m = 2 * std::sqrt(0.008 * 0.008 + 2 * 0.042 * 0.008);
  return w;
}

// Lowest surface point of the roller at phase phi, by search over the ellipsoid's surface:
// centre at centre_radius below the axle rotated by phi, axis in the tangent plane at alpha.
struct Lowest {
  Eigen::Vector3d point;
  Eigen::Vector3d axis;
  Eigen::Vector3d centre;
};
Lowest SearchLowest(const RollerGeometry& g, double phi) {
  const Eigen::AngleAxisd spin(phi, Eigen::Vector3d::UnitY());  // positive spin about the axle
  const Eigen::Vector3d centre = spin * Eigen::Vector3d(0, 0, -g.centre_radius_m);
  const Eigen::Vector3d axis =
      spin * Eigen::Vector3d(std::sin(g.roller_angle_rad), std::cos(g.roller_angle_rad), 0);
  const Eigen::Vector3d e1 = axis.unitOrthogonal(), e2 = axis.cross(e1);
  auto at = [&](double t, double p) {
    return Eigen::Vector3d(centre + g.half_length_m * std::cos(t) * axis +
                           g.roller_radius_m * std::sin(t) * (std::cos(p) * e1 + std::sin(p) * e2));
  };
  double best_t = 0, best_p = 0, best_z = 1e9;
  double span_t = kPi, span_p = kPi;
  double ct = kPi / 2, cp = 0;
  for (int level = 0; level < 6; ++level) {
    const int n = 200;
    for (int i = 0; i <= n; ++i) {
      for (int j = 0; j <= n; ++j) {
        const double t = ct - span_t + 2 * span_t * i / n;
        const double p = cp - span_p + 2 * span_p * j / n;
        const double z = at(t, p).z();
        if (z < best_z) {
          best_z = z;
          best_t = t;
          best_p = p;
        }
      }
    }
    ct = best_t;
    cp = best_p;
    span_t *= 0.05;
    span_p *= 0.05;
  }
  return {at(best_t, best_p), axis, centre};
}

TEST(RollerGeometry, PeerWheelRadiusFollowsFromTheEnvelope) {
  const RollerGeometry g = MakeRollerGeometry(PeerWheel(), "test");
  EXPECT_NEAR(g.roller_radius_m, 0.008, 1e-9);
  EXPECT_NEAR(g.centre_radius_m, 0.042, 1e-9);
  // Second order: d^2 h / d phi^2 = 0 at the centre, so h stays at R within a micrometre at
  // 3 deg of phase (a 4th-order term), and dips 0.26 mm at the hand-over (gen_model.py's
  // envelope 0.04974..0.05 m).
  EXPECT_NEAR(RollerContactAt(g, 0, 0.0).rolling_radius_m, 0.05, 1e-12);
  EXPECT_NEAR(RollerContactAt(g, 0, 3 * kPi / 180).rolling_radius_m, 0.05, 1e-6);
  const double dip = 0.05 - RollerContactAt(g, 0, kPi / 10).rolling_radius_m;
  EXPECT_NEAR(dip, 0.000258, 0.000005);
}

TEST(RollerGeometry, ContactIsTheLowestPointOfTheRollerSurface) {
  for (const double alpha_deg : {-45.0, 45.0, 90.0}) {
    WheelSpec w = PeerWheel(alpha_deg);
    if (alpha_deg == 90.0) {
      w.kind = WheelKind::kOmni;
      w.rollers.length_m = 0.03;
    }
    const RollerGeometry g = MakeRollerGeometry(w, "test");
    for (const double phi : {-0.3, -0.17, -0.05, 0.0, 0.02, 0.11, 0.2, 0.3}) {
      SCOPED_TRACE(::testing::Message() << "alpha " << alpha_deg << " phi " << phi);
      const RollerContact c = RollerContactAt(g, 0, phi);
      const Lowest s = SearchLowest(g, phi);
      EXPECT_NEAR(c.rolling_radius_m, -s.point.z(), 1e-9);
      EXPECT_NEAR(c.forward_offset_m, s.point.x(), 2e-6);
      EXPECT_NEAR(c.lateral_offset_m, s.point.y(), 2e-6);
      // Distance from the contact to the roller's axis.
      const Eigen::Vector3d rel = s.point - s.centre;
      EXPECT_NEAR(c.roller_radius_m, (rel - rel.dot(s.axis) * s.axis).norm(), 2e-6);
      // Effective angle: the roller axis projected on the floor, from the axle (y).
      EXPECT_NEAR(c.roller_angle_rad(), std::atan2(s.axis.x(), s.axis.y()), 1e-12);
      if (alpha_deg != 90.0) {
        EXPECT_NEAR(std::tan(c.roller_angle_rad()), std::tan(alpha_deg * kPi / 180) * std::cos(phi),
                    1e-12);
      }
    }
  }
}

TEST(RollerGeometry, ContactRunsAlongTheRollerAndJumpsToTheNext) {
  const RollerGeometry g = MakeRollerGeometry(PeerWheel(), "test");
  const double pitch = 2 * kPi / 10;
  // Just before and after the first hand-over (half a pitch).
  const RollerContact before = LowestRollerContact(g, 0.5 * pitch - 1e-6);
  const RollerContact after = LowestRollerContact(g, 0.5 * pitch + 1e-6);
  EXPECT_EQ(before.roller, 0);
  EXPECT_EQ(after.roller, 1);
  EXPECT_NEAR(before.rolling_radius_m, after.rolling_radius_m, 1e-8);   // no step in height
  EXPECT_NEAR(before.lateral_offset_m, -after.lateral_offset_m, 1e-8);  // the lateral jump
  EXPECT_NEAR(std::abs(before.lateral_offset_m), 0.010592, 1e-6);  // closed form
  EXPECT_NEAR(before.roller_angle_rad(), after.roller_angle_rad(), 1e-8);
  // Monotone run along the roller: the lateral offset grows with the phase.
  double last = -1;
  for (int k = -9; k <= 9; ++k) {
    const RollerContact c = LowestRollerContact(g, 3 * pitch + k * pitch / 20);
    EXPECT_EQ(c.roller, 3);
    EXPECT_GT(c.lateral_offset_m * (g.roller_angle_rad < 0 ? -1 : 1), last);
    last = c.lateral_offset_m * (g.roller_angle_rad < 0 ? -1 : 1);
  }
  // Negative angles wrap to the last rollers.
  EXPECT_EQ(LowestRollerContact(g, -pitch).roller, 9);
  EXPECT_EQ(LowestRollerContact(g, -21 * pitch).roller, 9);
}

TEST(RollerGeometry, MeanEffectiveRollerTangentIsSincOfHalfThePitch) {
  // <tan(alpha_eff)> / tan(alpha) = <cos phi> = sin(pi/N) / (pi/N) over a pitch: the loss of
  // sideways speed a discrete wheel has (MuJoCo peer report: 97.1 / 98.1 / 98.5 % for 8/10/12).
  for (const int n : {8, 10, 12}) {
    WheelSpec w = PeerWheel(45);
    w.rollers.count = n;
    const RollerGeometry g = MakeRollerGeometry(w, "test");
    const int samples = 20000;
    double sum = 0;
    for (int k = 0; k < samples; ++k) {
      sum += std::tan(LowestRollerContact(g, 2 * kPi * (k + 0.5) / samples).roller_angle_rad());
    }
    EXPECT_NEAR(sum / samples, std::sin(kPi / n) / (kPi / n), 1e-6) << n;
  }
}

TEST(RollerGeometry, DoubleOmniRowsAlternateAndStagger) {
  WheelSpec w;
  w.name = "double";
  w.kind = WheelKind::kOmni;
  w.radius_m = 0.025;
  w.roller_angle_rad = kPi / 2;
  w.rollers = RollerSpec{.count = 6, .length_m = 0.018, .rows = 2, .row_offset_m = 0.006};
  const RollerGeometry g = MakeRollerGeometry(w, "test");
  const double pitch = 2 * kPi / 6;
  for (int k = 0; k < 12; ++k) {
    const RollerContact c = LowestRollerContact(g, k * 0.5 * pitch);  // each roller's centre
    EXPECT_NEAR(c.rolling_radius_m, 0.025, 1e-12);
    EXPECT_NEAR(c.lateral_offset_m, k % 2 == 0 ? 0.006 : -0.006, 1e-12);
    EXPECT_EQ(c.roller, k % 2 == 0 ? k / 2 : 6 + k / 2);
    EXPECT_NEAR(c.roller_angle_rad(), kPi / 2, 1e-12);
  }
  // Half-way between (a quarter pitch): the rows hand over, both reach the same depth.
  const RollerContact mid = LowestRollerContact(g, 0.25 * pitch);
  EXPECT_NEAR(mid.rolling_radius_m, RollerContactAt(g, 6, 0.25 * pitch).rolling_radius_m, 1e-12);
  EXPECT_LT(mid.rolling_radius_m, 0.025);
}

TEST(RollerGeometry, ImpossibleRollersAreRefusedWithTheField) {
  WheelSpec w = PeerWheel();
  w.rollers.length_m = 0.12;  // longer than the envelope allows at 45 deg
  EXPECT_THAT([&] { (void)MakeRollerGeometry(w, "plat: wheels[0]"); },
              ::testing::ThrowsMessage<std::invalid_argument>(
                  ::testing::HasSubstr("plat: wheels[0]: rollers.length_m (0.12) is too long")));
  w = PeerWheel();
  w.rollers.count = 3;  // gaps between three short rollers
  EXPECT_THAT([&] { (void)MakeRollerGeometry(w, "x"); },
              ::testing::ThrowsMessage<std::invalid_argument>(
                  ::testing::HasSubstr("rollers.count (3) leaves gaps")));
  w = PeerWheel();
  w.rollers.rows = 3;
  EXPECT_THROW((void)MakeRollerGeometry(w, "x"), std::invalid_argument);
  w = PeerWheel();
  w.rollers.radius_m = 0.06;
  EXPECT_THROW((void)MakeRollerGeometry(w, "x"), std::invalid_argument);
}

}  // namespace
}  // namespace wheelhil::emulator::physics
