#include "emulator/physics/roller_geometry.h"

#include <cmath>
#include <numbers>
#include <stdexcept>

#include <fmt/format.h>

namespace wheelhil::emulator::physics {

namespace {

constexpr double kPi = std::numbers::pi;

// The contact of roller `roller` at phase phi (wheel angle past its centre's lowest).
RollerContact ContactAtPhase(const RollerGeometry& g, int roller, double phi) noexcept {
  const int row = roller / g.count;
  const double s = g.sin_angle, c = g.cos_angle;
  const double a = g.roller_radius_m, b = g.half_length_m;
  const double sp = std::sin(phi), cp = std::cos(phi);
  const double uz2 = s * s * sp * sp;  // squared vertical part of the tilted roller axis
  const double d = b * b - a * a;
  const double S = std::sqrt(a * a + d * uz2);
  RollerContact out;
  out.roller = roller;
  out.phase_rad = phi;
  out.rolling_radius_m = g.centre_radius_m * cp + S;
  const double row_offset = g.rows == 2 ? (row == 0 ? g.row_offset_m : -g.row_offset_m) : 0.0;
  out.lateral_offset_m = d * s * c * sp / S + row_offset;
  out.forward_offset_m = -g.centre_radius_m * sp + d * s * s * sp * cp / S;
  // The roller axis projected on the floor: (s cos(phi), c) in (rolling, axle), normalised.
  const double n = std::sqrt(1 - uz2);
  out.roller_sin = s * cp / n;
  out.roller_cos = c / n;
  out.roller_radius_m = a * a * n / S;
  return out;
}

[[noreturn]] void Fail(const std::string& where, const std::string& field, double value,
                       const std::string& rule) {
  throw std::invalid_argument(fmt::format("{}: rollers.{} ({}) {}", where, field, value, rule));
}

}  // namespace

RollerGeometry MakeRollerGeometry(const WheelSpec& w, const std::string& where) {
  const RollerSpec& r = w.rollers;
  RollerGeometry g;
  g.count = r.count;
  g.rows = r.rows;
  g.wheel_radius_m = w.radius_m;
  g.roller_angle_rad = w.roller_angle_rad;
  g.sin_angle = std::sin(w.roller_angle_rad);
  g.cos_angle = std::cos(w.roller_angle_rad);
  g.half_length_m = 0.5 * r.length_m;
  g.row_offset_m = r.row_offset_m;
  if (r.count < 3 || r.count > 64) Fail(where, "count", r.count, "must be in [3, 64]");
  if (r.rows != 1 && r.rows != 2) Fail(where, "rows", r.rows, "must be 1 or 2");
  if (!(std::isfinite(r.length_m) && r.length_m > 0)) {
    Fail(where, "length_m", r.length_m, "must be finite and > 0");
  }
  if (!(std::isfinite(r.row_offset_m) && r.row_offset_m >= 0 && r.row_offset_m < w.radius_m)) {
    Fail(where, "row_offset_m", r.row_offset_m, "must be in [0, wheel radius)");
  }
  const double s = g.sin_angle, c = g.cos_angle;
  const double R = w.radius_m, b = g.half_length_m;
  if (r.radius_m > 0) {
    g.roller_radius_m = r.radius_m;
  } else if (c * c < 1e-12) {
    g.roller_radius_m = b * b / R;  // omni: a = b^2 / R
  } else {
    // The smaller root of a^2 c^2 - R a + b^2 s^2 = 0: the envelope matches the cylinder to
    // second order in the phase.
    const double disc = R * R - 4 * c * c * s * s * b * b;
    if (disc < 0) {
      Fail(where, "length_m", r.length_m,
           fmt::format("is too long for a wheel of radius {} m at this roller angle (at most {} "
                       "m with an envelope of the wheel's radius)",
                       R, 2 * R / std::abs(2 * s * c)));
    }
    g.roller_radius_m = (R - std::sqrt(disc)) / (2 * c * c);
  }
  if (!(std::isfinite(g.roller_radius_m) && g.roller_radius_m > 0 && g.roller_radius_m < R)) {
    Fail(where, "radius_m", g.roller_radius_m, "must be in (0, wheel radius)");
  }
  g.centre_radius_m = R - g.roller_radius_m;
  // Whether the nearest roller is always the lowest: h falls with |phase| out to 1.5 pitches.
  double last = ContactAtPhase(g, 0, 0.0).rolling_radius_m;
  for (int k = 1; k <= 300; ++k) {
    const double h = ContactAtPhase(g, 0, 1.5 * (2 * kPi / g.count) * k / 300).rolling_radius_m;
    if (h > last) g.nearest_is_lowest = false;
    last = h;
  }
  // The hub (at most the roller centres' radius) must not reach the floor at the hand-over.
  const RollerContact handover = RollerContactAt(g, 0, kPi / (g.count * g.rows));
  if (handover.rolling_radius_m <= g.centre_radius_m) {
    Fail(where, "count", r.count,
         fmt::format("leaves gaps: at the hand-over the rollers reach only {:.4f} m below the "
                     "axle, not beyond their centres at {:.4f} m (more or longer rollers)",
                     handover.rolling_radius_m, g.centre_radius_m));
  }
  return g;
}

double RollerContact::roller_angle_rad() const noexcept {
  return std::atan2(roller_sin, roller_cos);
}

RollerContact RollerContactAt(const RollerGeometry& g, int roller, double angle_rad) noexcept {
  const int k = roller % g.count;
  const double pitch = 2 * kPi / g.count;
  const double centre = k * pitch + (roller / g.count == 1 ? 0.5 * pitch : 0.0);
  return ContactAtPhase(g, roller, std::remainder(angle_rad - centre, 2 * kPi));
}

RollerContact LowestRollerContact(const RollerGeometry& g, double angle_rad) noexcept {
  const double pitch = 2 * kPi / g.count;
  RollerContact best;
  best.rolling_radius_m = -1;
  const long long span = g.nearest_is_lowest ? 0 : 1;
  for (int row = 0; row < g.rows; ++row) {
    const double start = row == 1 ? 0.5 * pitch : 0.0;
    const long long nearest = std::llround((angle_rad - start) / pitch);
    // A roller profile other than the matched one may make a neighbour lower near the
    // hand-over: then the neighbours are looked at too.
    for (long long j = nearest - span; j <= nearest + span; ++j) {
      const int k = static_cast<int>(((j % g.count) + g.count) % g.count);
      const double phi = angle_rad - start - static_cast<double>(j) * pitch;
      const RollerContact rc = ContactAtPhase(g, row * g.count + k, phi);
      if (rc.rolling_radius_m > best.rolling_radius_m) best = rc;
    }
  }
  return best;
}

}  // namespace wheelhil::emulator::physics
