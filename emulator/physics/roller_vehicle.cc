// One file on purpose (~700 lines): one vehicle's step over its per-wheel state. PreStep (ray
// casts, suspension, motor, roller-contact friction and the contact solver) is still one long
// function; splitting it into named stages is open work.
#include "emulator/physics/roller_vehicle.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include <btBulletDynamicsCommon.h>
#include <fmt/format.h>

namespace wheelhil::emulator::physics {

namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;

constexpr double kPi = std::numbers::pi;
constexpr double kAnchorGain = 0.2;  // fraction of the accumulated creep removed per step
constexpr double kRayMargin_m = 0.02;
constexpr double kSolverTolerance = 1e-6;  // m/s (or rad/s) change of any row per sweep
constexpr std::size_t kMaxWheels = 32;

Vector3d ToEigen(const btVector3& v) { return {v.x(), v.y(), v.z()}; }
btVector3 ToBt(const Vector3d& v) {
  return btVector3(static_cast<btScalar>(v.x()), static_cast<btScalar>(v.y()),
                   static_cast<btScalar>(v.z()));
}

void Require(bool ok, const std::string& where, const std::string& field, double value,
             const char* rule) {
  if (!ok) {
    throw std::invalid_argument(fmt::format("{}: {} ({}) {}", where, field, value, rule));
  }
}

// One velocity-level row of the contact/motor solve.
struct Row {
  Vector3d lin;    // direction of the impulse on the chassis
  Vector3d ang;    // r x lin
  Vector3d iang;   // Iinv * ang
  Vector3d lin_m;  // lin / m
  // No default initialisers: a step's rows are filled completely where they are added.
  double jw;    // coefficient on the wheel spin rate
  double jw_i;  // jw / wheel inertia
  double jr;    // coefficient on the spin of the wheel's roller in contact
  double jr_i;  // jr / roller inertia
  int wheel;
  double inv_k;          // 1 / (effective inverse mass + cfm)
  double cfm;            // softness: row velocity error per unit impulse (0 = rigid)
  double target;         // desired row velocity
  double lo, hi;         // impulse bounds (box rows)
  double* lambda;        // accumulated impulse (persistent, warm start)
  int partner;           // circle-clamped pair: index of the lateral row
  double radius;         // circle radius for the pair (impulse)
  double lateral_scale;  // ellipse: lateral bound = radius * scale
};

// std::hypot(a, b) >= limit, with the hypot call only near the boundary: the squared norm
// decides when it is more than 1e-9 (relative) away from limit^2, far above its rounding.
bool Saturated(double a, double b, double limit) noexcept {
  if (limit > 1e-100 && limit < 1e100) {
    const double s2 = a * a + b * b;
    const double l2 = limit * limit;
    if (s2 < l2 * (1 - 1e-9)) return false;
    if (s2 > l2 * (1 + 1e-9)) return true;
  }
  return std::hypot(a, b) >= limit;
}

}  // namespace

void ValidateVehicleSpec(const VehicleSpec& s, const std::string& where) {
  Require(std::isfinite(s.mass_kg) && s.mass_kg > 0, where, "mass_kg", s.mass_kg,
          "must be finite and > 0");
  for (int k = 0; k < 3; ++k) {
    Require(std::isfinite(s.inertia_kg_m2[k]) && s.inertia_kg_m2[k] > 0, where,
            fmt::format("inertia_kg_m2[{}]", k), s.inertia_kg_m2[k], "must be finite and > 0");
  }
  Require(s.wheels.size() >= 1 && s.wheels.size() <= kMaxWheels, where, "wheels",
          static_cast<double>(s.wheels.size()), "must list 1 to 32 wheels");
  Require(s.slip_threshold_m_s > 0, where, "slip_threshold_m_s", s.slip_threshold_m_s,
          "must be > 0");
  Require(s.stribeck_velocity_m_s > 0, where, "stribeck_velocity_m_s", s.stribeck_velocity_m_s,
          "must be > 0");
  Require(s.solver_iterations >= 1 && s.solver_iterations <= 1000, where, "solver_iterations",
          s.solver_iterations, "must be in [1, 1000]");
  for (std::size_t i = 0; i < s.wheels.size(); ++i) {
    const WheelSpec& w = s.wheels[i];
    const std::string f = fmt::format("wheels[{}] '{}'.", i, w.name);
    Require(w.mount_B.allFinite(), where, f + "mount_m", 0, "must be finite");
    Require(std::isfinite(w.radius_m) && w.radius_m > 0, where, f + "radius_m", w.radius_m,
            "must be finite and > 0");
    Require(std::isfinite(w.inertia_kg_m2) && w.inertia_kg_m2 > 0, where, f + "inertia_kg_m2",
            w.inertia_kg_m2, "must be finite and > 0");
    Require(w.rolling_resistance >= 0 && w.rolling_resistance < 1, where, f + "rolling_resistance",
            w.rolling_resistance, "must be in [0, 1)");
    Require(w.bearing_friction_nm >= 0, where, f + "bearing_friction_nm", w.bearing_friction_nm,
            "must be >= 0");
    Require(w.bearing_viscous_nm_s >= 0, where, f + "bearing_viscous_nm_s", w.bearing_viscous_nm_s,
            "must be >= 0");
    Require(w.lateral_mu_scale > 0, where, f + "lateral_mu_scale", w.lateral_mu_scale,
            "must be > 0");
    if (w.kind == WheelKind::kMecanum || w.kind == WheelKind::kOmni ||
        w.kind == WheelKind::kOrthogonal) {
      Require(std::abs(std::sin(w.roller_angle_rad)) > 0.1, where, f + "roller_angle_deg",
              w.roller_angle_rad * 180 / kPi, "must not be near 0 (a roller parallel to the axle)");
    }
    if (w.rollers.count != 0) {
      Require(w.kind == WheelKind::kMecanum || w.kind == WheelKind::kOmni, where, f + "rollers",
              w.rollers.count, "discrete rollers are for mecanum and omni wheels");
      (void)MakeRollerGeometry(w, where + ": " + f.substr(0, f.size() - 1));
      const RollerSpec& rs = w.rollers;
      Require(std::isfinite(rs.inertia_kg_m2) && rs.inertia_kg_m2 >= 0, where,
              f + "rollers.inertia_kg_m2", rs.inertia_kg_m2, "must be finite and >= 0");
      Require(std::isfinite(rs.bearing_friction_nm) && rs.bearing_friction_nm >= 0, where,
              f + "rollers.bearing_friction_nm", rs.bearing_friction_nm, "must be finite and >= 0");
      Require(std::isfinite(rs.bearing_viscous_nm_s) && rs.bearing_viscous_nm_s >= 0, where,
              f + "rollers.bearing_viscous_nm_s", rs.bearing_viscous_nm_s,
              "must be finite and >= 0");
    }
    if (w.kind == WheelKind::kOrthogonal) {
      Require(w.handover_dip_m >= 0 && w.handover_dip_m < 0.5 * w.radius_m, where,
              f + "handover_dip_m", w.handover_dip_m, "must be in [0, radius/2)");
      Require(w.handover_zone_rad > 0 && w.handover_zone_rad <= kPi / 2, where,
              f + "handover_zone_deg", w.handover_zone_rad * 180 / kPi, "must be in (0, 90]");
    }
    const SuspensionSpec& q = w.suspension;
    Require(q.min_length_m >= 0 && q.min_length_m < q.max_length_m, where,
            f + "suspension.min_length_m", q.min_length_m, "must be >= 0 and < max_length_m");
    Require(q.free_length_m > 0, where, f + "suspension.free_length_m", q.free_length_m,
            "must be > 0");
    Require(q.stiffness_n_m > 0, where, f + "suspension.stiffness_n_m", q.stiffness_n_m,
            "must be > 0");
    Require(q.damping_n_s_m >= 0, where, f + "suspension.damping_n_s_m", q.damping_n_s_m,
            "must be >= 0");
    Require(q.bump_stiffness_n_m >= 0, where, f + "suspension.bump_stiffness_n_m",
            q.bump_stiffness_n_m, "must be >= 0");
    Require(q.hub_mass_kg > 0, where, f + "suspension.hub_mass_kg", q.hub_mass_kg, "must be > 0");
    Require(q.tire_stiffness_n_m > 0, where, f + "suspension.tire_stiffness_n_m",
            q.tire_stiffness_n_m, "must be > 0");
    Require(q.tire_damping_n_s_m >= 0, where, f + "suspension.tire_damping_n_s_m",
            q.tire_damping_n_s_m, "must be >= 0");
    if (w.driven) {
      Require(w.kind != WheelKind::kCaster, where, f + "motor", 0, "a caster cannot be driven");
      const MotorSpec& m = w.motor;
      Require(m.gear_ratio > 0, where, f + "motor.gear_ratio", m.gear_ratio, "must be > 0");
      Require(m.torque_constant_nm_a > 0, where, f + "motor.torque_constant_nm_a",
              m.torque_constant_nm_a, "must be > 0");
      Require(m.max_current_a > 0, where, f + "motor.max_current_a", m.max_current_a,
              "must be > 0");
      Require(m.max_torque_nm > 0, where, f + "motor.max_torque_nm", m.max_torque_nm,
              "must be > 0");
      Require(m.rotor_inertia_kg_m2 >= 0, where, f + "motor.rotor_inertia_kg_m2",
              m.rotor_inertia_kg_m2, "must be >= 0");
      Require(m.winding_resistance_ohm >= 0, where, f + "motor.winding_resistance_ohm",
              m.winding_resistance_ohm, "must be >= 0");
      Require(m.supply_voltage_v > 0, where, f + "motor.supply_voltage_v", m.supply_voltage_v,
              "must be > 0");
      Require(m.max_accel_rad_s2 >= 0, where, f + "motor.max_accel_rad_s2", m.max_accel_rad_s2,
              "must be >= 0");
      Require(m.speed_gain_nm_s_rad > 0, where, f + "motor.speed_gain_nm_s_rad",
              m.speed_gain_nm_s_rad, "must be > 0");
      Require(m.integral_gain_nm_rad >= 0, where, f + "motor.integral_gain_nm_rad",
              m.integral_gain_nm_rad, "must be >= 0");
    }
  }
}

RollerVehicle::RollerVehicle(const VehicleSpec& spec, const Terrain* terrain,
                             const Eigen::Isometry3d& X_WB, const Vector3d& gravity_W)
    : spec_(spec), terrain_(terrain), gravity_W_(gravity_W) {
  ValidateVehicleSpec(spec_, fmt::format("vehicle '{}'", spec_.name));
  shape_ = std::make_unique<btBoxShape>(ToBt(spec_.half_extents_m));
  btTransform T;
  T.setIdentity();
  T.setOrigin(ToBt(X_WB.translation()));
  const Eigen::Quaterniond q(X_WB.rotation());
  T.setRotation(btQuaternion(static_cast<btScalar>(q.x()), static_cast<btScalar>(q.y()),
                             static_cast<btScalar>(q.z()), static_cast<btScalar>(q.w())));
  // No motion state on the body (nobody reads one; Bullet would interpolate and copy it every
  // step). The start transform is the one a btDefaultMotionState(T) would hand to the body.
  btTransform start;
  btDefaultMotionState(T).getWorldTransform(start);
  btRigidBody::btRigidBodyConstructionInfo info(static_cast<btScalar>(spec_.mass_kg), nullptr,
                                                shape_.get(), ToBt(spec_.inertia_kg_m2));
  info.m_startWorldTransform = start;
  info.m_linearDamping = 0;
  info.m_angularDamping = 0;
  info.m_friction = 0;
  body_ = std::make_unique<btRigidBody>(info);
  body_->setActivationState(DISABLE_DEACTIVATION);
  body_->setGravity(btVector3(0, 0, 0));  // gravity is applied in PreStep with the contacts
  body_->setCollisionFlags(body_->getCollisionFlags() | btCollisionObject::CF_NO_CONTACT_RESPONSE);

  state_.resize(spec_.wheels.size());
  truth_.resize(spec_.wheels.size());
  command_.assign(spec_.wheels.size(), 0.0);
  const Matrix3d R = X_WB.rotation();
  for (std::size_t i = 0; i < spec_.wheels.size(); ++i) {
    const WheelSpec& w = spec_.wheels[i];
    WheelState& st = state_[i];
    const double rotor =
        w.driven ? w.motor.gear_ratio * w.motor.gear_ratio * w.motor.rotor_inertia_kg_m2 : 0.0;
    st.inv_inertia = 1.0 / (w.inertia_kg_m2 + rotor);
    st.axle_B = Vector3d(-std::sin(w.heading_rad), std::cos(w.heading_rad), 0);
    st.roller_cos = std::cos(w.roller_angle_rad);
    st.roller_sin = std::sin(w.roller_angle_rad);
    if (w.rollers.count > 0) {
      st.rollers = MakeRollerGeometry(w, spec_.name);
      if (w.rollers.inertia_kg_m2 > 0) {
        st.roller_inv_inertia = 1.0 / w.rollers.inertia_kg_m2;
        st.roller_omega.assign(static_cast<std::size_t>(w.rollers.count * w.rollers.rows), 0.0);
      }
    }
    // Start with the hub on the floor (or hanging).
    st.length_m = w.suspension.max_length_m;
    const ContactGeometry geo = WheelGeometry(i, 0.0);
    const double r = geo.radius_m;
    const Vector3d dir = -R.col(2);
    const Vector3d axle = R * Vector3d(-std::sin(w.heading_rad), std::cos(w.heading_rad), 0);
    Vector3d from = X_WB * w.mount_B + axle * geo.lateral_m;
    if (geo.forward_m != 0) {
      from += R * Vector3d(std::cos(w.heading_rad), std::sin(w.heading_rad), 0) * geo.forward_m;
    }
    SurfaceHit hit;
    if (terrain_ != nullptr &&
        terrain_->Raycast(from, dir, w.suspension.max_length_m + r + kRayMargin_m, &hit)) {
      const double c = std::max(0.5, -dir.dot(hit.normal_W));
      st.length_m = std::clamp(hit.distance_m - r / c, 0.0, w.suspension.max_length_m);
    }
    truth_[i].suspension_length_m = st.length_m;
    truth_[i].effective_radius_m = r;
  }
  prev_v_W_.setZero();
  prev_w_W_.setZero();
  body_truth_.p_WB = X_WB.translation();
  body_truth_.q_WB = q;
  prev_yaw_wrapped_ = std::atan2(R(1, 0), R(0, 0));
  body_truth_.yaw_rad = prev_yaw_wrapped_;
}

RollerVehicle::~RollerVehicle() = default;

bool RollerVehicle::SetWheelSpeedCommand(std::size_t i, double omega) noexcept {
  if (i >= command_.size() || !std::isfinite(omega)) return false;
  command_[i] = omega;
  return true;
}

double RollerVehicle::wheel_speed_command(std::size_t i) const noexcept {
  return i < command_.size() ? command_[i] : 0.0;
}

bool RollerVehicle::SetWheelFriction(std::size_t i, double scale,
                                     const std::optional<Friction>& override_friction) noexcept {
  if (i >= state_.size() || !std::isfinite(scale) || scale < 0) return false;
  if (override_friction &&
      !(std::isfinite(override_friction->mu_peak) && std::isfinite(override_friction->mu_slide) &&
        override_friction->mu_slide >= 0 &&
        override_friction->mu_slide <= override_friction->mu_peak)) {
    return false;
  }
  state_[i].friction_scale = scale;
  state_[i].friction_override = override_friction;
  return true;
}

bool RollerVehicle::SetWheelDisturbanceTorque(std::size_t i, double torque_nm) noexcept {
  if (i >= state_.size() || !std::isfinite(torque_nm)) return false;
  state_[i].disturbance_nm = torque_nm;
  return true;
}

bool RollerVehicle::SetMotorTorqueLimit(std::size_t i, double limit_nm) noexcept {
  if (i >= state_.size() || !spec_.wheels[i].driven || std::isnan(limit_nm) || limit_nm < 0) {
    return false;
  }
  state_[i].drive_limit_nm = limit_nm;
  return true;
}

double RollerVehicle::wheel_spin_inertia(std::size_t i) const noexcept {
  if (i >= state_.size() || state_[i].inv_inertia <= 0) return 0.0;
  return 1.0 / state_[i].inv_inertia;
}

Eigen::Isometry3d RollerVehicle::pose() const noexcept {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = body_truth_.q_WB.toRotationMatrix();
  X.translation() = body_truth_.p_WB;
  return X;
}

RollerVehicle::ContactGeometry RollerVehicle::WheelGeometry(std::size_t i,
                                                            double angle) const noexcept {
  const WheelSpec& w = spec_.wheels[i];
  const WheelState& st = state_[i];
  ContactGeometry g{w.radius_m, 0.0, 0.0, st.roller_cos, st.roller_sin, -1, 0.0};
  if (st.rollers) {
    const RollerContact c = LowestRollerContact(*st.rollers, angle);
    g.radius_m = c.rolling_radius_m;
    g.lateral_m = c.lateral_offset_m;
    g.forward_m = c.forward_offset_m;
    g.roller_cos = c.roller_cos;
    g.roller_sin = c.roller_sin;
    g.roller = c.roller;
    g.roller_radius_m = c.roller_radius_m;
    return g;
  }
  if (w.kind != WheelKind::kOrthogonal) return g;
  g.radius_m = OrthogonalRadius(w, angle, &g.lateral_m);
  return g;
}

double RollerVehicle::OrthogonalRadius(const WheelSpec& w, double angle,
                                       double* lateral_offset) noexcept {
  const double seg = std::floor((angle + kPi / 4) / (kPi / 2));
  const double phi = angle - seg * (kPi / 2);  // [-pi/4, pi/4)
  const long long iseg = static_cast<long long>(seg);
  const bool first_half = ((iseg % 2) + 2) % 2 == 0;
  *lateral_offset = first_half ? w.half_offset_m : -w.half_offset_m;
  if (w.handover_zone_rad >= kPi / 2) {
    const double x = 4 * phi / kPi;
    return w.radius_m - w.handover_dip_m * x * x;
  }
  // Spherical halves: full radius except near the hand-over, where the halves are cut short.
  const double half_zone = 0.5 * w.handover_zone_rad;
  const double psi = kPi / 4 - std::abs(phi);
  if (psi >= half_zone) return w.radius_m;
  const double u = 1 - psi / half_zone;
  return w.radius_m - w.handover_dip_m * u * u;
}

void RollerVehicle::UpdateRollerSpins(std::size_t i, double contact_omega, double dt) noexcept {
  const RollerSpec& rs = spec_.wheels[i].rollers;
  WheelState& st = state_[i];
  WheelTruth& tr = truth_[i];
  const double viscous = 1.0 / (1.0 + dt * rs.bearing_viscous_nm_s * st.roller_inv_inertia);
  const double coulomb = rs.bearing_friction_nm * dt * st.roller_inv_inertia;
  for (std::size_t k = 0; k < st.roller_omega.size(); ++k) {
    double& wr = st.roller_omega[k];
    if (static_cast<int>(k) == tr.roller) {
      wr = contact_omega;  // its bearing decay is part of this step's solve
      if (tr.in_contact) continue;
    } else {
      wr *= viscous;
    }
    wr = wr > 0 ? std::max(0.0, wr - coulomb) : std::min(0.0, wr + coulomb);
  }
  tr.roller_omega_rad_s = tr.roller >= 0 ? st.roller_omega[static_cast<std::size_t>(tr.roller)] : 0;
}

void RollerVehicle::PreStep(double dt) noexcept {
  last_dt_s_ = dt;
  const btTransform& T = body_->getWorldTransform();
  Matrix3d R;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) R(r, c) = T.getBasis()[r][c];
  }
  const Vector3d p = ToEigen(T.getOrigin());
  Vector3d v = ToEigen(body_->getLinearVelocity());
  Vector3d w = ToEigen(body_->getAngularVelocity());
  const double inv_m = body_->getInvMass();
  const Vector3d inv_i_local = ToEigen(body_->getInvInertiaDiagLocal());
  const Matrix3d Iinv = R * inv_i_local.asDiagonal() * R.transpose();
  const Vector3d dir = -R.col(2);
  const double g_dir = gravity_W_.dot(dir);

  auto apply_at = [&](const Vector3d& impulse, const Vector3d& r) {
    v += impulse * inv_m;
    w += Iinv * r.cross(impulse);
  };
  v += gravity_W_ * dt;

  const std::size_t n = spec_.wheels.size();
  // Rows live on the stack for small vehicles; no allocation in the step.
  constexpr std::size_t kMaxRows = 4 * kMaxWheels;
  Row rows_buf[kMaxRows];
  std::size_t nrows = 0;
  double omega[kMaxWheels];
  double roller_omega[kMaxWheels];  // spin of each wheel's roller in contact (0: no spin state)
  const std::size_t nw = std::min<std::size_t>(n, kMaxWheels);

  // Geometry cache for the post-solve truth.
  struct Contact {
    Vector3d f, l, u, r_c;
    double r_eff;
  };
  Contact contact[kMaxWheels];

  for (std::size_t i = 0; i < nw; ++i) {
    const WheelSpec& ws = spec_.wheels[i];
    WheelState& st = state_[i];
    WheelTruth& tr = truth_[i];
    omega[i] = tr.omega_rad_s;
    // Implicit viscous bearing.
    if (ws.kind != WheelKind::kCaster && ws.bearing_viscous_nm_s > 0) {
      omega[i] /= 1.0 + dt * ws.bearing_viscous_nm_s * st.inv_inertia;
    }
    const ContactGeometry geo = WheelGeometry(i, tr.angle_rad);
    const double r_eff = geo.radius_m;
    tr.effective_radius_m = r_eff;
    const Vector3d axle = R * st.axle_B;
    const Vector3d mount = p + R * ws.mount_B;
    Vector3d from = mount + axle * geo.lateral_m;
    if (geo.forward_m != 0) from += R * Vector3d(st.axle_B.y(), -st.axle_B.x(), 0) * geo.forward_m;
    roller_omega[i] = 0;
    const bool roller_state = geo.roller >= 0 && st.roller_inv_inertia > 0;
    if (roller_state) {
      double& wr = st.roller_omega[static_cast<std::size_t>(geo.roller)];
      wr /= 1.0 + dt * ws.rollers.bearing_viscous_nm_s * st.roller_inv_inertia;
      roller_omega[i] = wr;
    }
    if (geo.roller >= 0) {
      // The contact geometry moves every step: warm start from the impulses' linear trend.
      for (int r = 0; r < 3; ++r) {
        double* lam = r == 0 ? &st.lambda_a : r == 1 ? &st.lambda_b : &st.lambda_motor;
        const double now = *lam;
        *lam = 2 * now - st.lambda_prev[r];
        st.lambda_prev[r] = now;
      }
    }
    tr.roller = geo.roller;
    tr.roller_angle_rad = geo.roller >= 0 ? std::atan2(geo.roller_sin, geo.roller_cos) : 0.0;
    const SuspensionSpec& q = ws.suspension;

    SurfaceHit hit;
    bool ground = terrain_ != nullptr &&
                  terrain_->Raycast(from, dir, q.max_length_m + r_eff + kRayMargin_m, &hit);
    double c = 1;
    double l_ground = 1e9;
    if (ground) {
      c = std::max(0.5, -dir.dot(hit.normal_W));
      l_ground = hit.distance_m - r_eff / c;
    }
    // Unsprung hub along the suspension axis: springs explicit in the length, suspension damper
    // and tyre spring-damper implicit in the hub's rate.
    const double L = st.length_m;
    const double f_spring = q.stiffness_n_m * (q.free_length_m - L);
    const double f_bump = L < q.min_length_m ? q.bump_stiffness_n_m * (q.min_length_m - L) : 0.0;
    const double mu_h = q.hub_mass_kg;
    const double f_ext = f_spring + f_bump + mu_h * g_dir;
    // The floor's rate from the ray distance alone: continuous over mesh edges, where the r/c
    // term of l_ground jumps with the facet normal.
    const double g_rate =
        (ground && st.ground_valid) ? (hit.distance_m - st.ground_length_m) / dt : 0.0;
    st.ground_valid = ground;
    st.ground_length_m = ground ? hit.distance_m : 0.0;
    double ldot = (mu_h * st.length_rate_m_s + dt * f_ext) / (mu_h + dt * q.damping_n_s_m);
    double f_tire = 0;
    if (ground && L + ldot * dt > l_ground) {
      const double kt = q.tire_stiffness_n_m, ct = q.tire_damping_n_s_m;
      const double ld =
          (mu_h * st.length_rate_m_s + dt * (f_ext - kt * (L - l_ground) + ct * g_rate)) /
          (mu_h + dt * (q.damping_n_s_m + ct + dt * kt));
      const double f = kt * (L + ld * dt - l_ground) + ct * (ld - g_rate);
      if (f > 0) {
        ldot = ld;
        f_tire = f;
      }
    }
    const double f_damp = -q.damping_n_s_m * ldot;
    double j_stop = 0;
    if (L + ldot * dt > q.max_length_m) {
      const double ld = (q.max_length_m - L) / dt;
      j_stop = mu_h * (ld - ldot);
      ldot = ld;
    } else if (L + ldot * dt < 0) {
      const double ld = -L / dt;
      j_stop = mu_h * (ld - ldot);
      ldot = ld;
    }
    st.length_m = L + ldot * dt;
    st.length_rate_m_s = ldot;
    tr.suspension_length_m = st.length_m;
    // Suspension reaction on the chassis at the mount (spring, damper, bump stop, droop stop).
    apply_at(-(dt * (f_spring + f_damp + f_bump) + j_stop) * dir, mount - p);

    const double n_axis = f_tire;
    tr.in_contact = ground && n_axis > 0;
    if (!tr.in_contact) {
      tr.normal_load_n = 0;
      tr.mu = 0;
      st.lambda_a = st.lambda_b = st.lambda_spin = 0;
      st.lambda_prev[0] = st.lambda_prev[1] = 0;  // no trend across a lift-off
      st.anchor_a_m = st.anchor_b_m = 0;
      st.last_slip_m_s = 0;
      contact[i] =
          Contact{Vector3d::Zero(), Vector3d::Zero(), Vector3d::Zero(), Vector3d::Zero(), r_eff};
    } else {
      const Vector3d nrm = hit.normal_W;
      const double n_load = n_axis / c;
      tr.normal_load_n = n_load;
      const Vector3d hub = from + dir * st.length_m;
      // A discrete roller rolls on its loaded radius (axle to floor): its compliance is contact
      // deformation, which shortens the lever the rim speed comes from.
      const double r_roll = geo.roller >= 0
                                ? std::clamp((hit.distance_m - st.length_m) * c, 0.5 * r_eff, r_eff)
                                : r_eff;
      const Vector3d cp = hub - nrm * r_roll;
      tr.contact_point_W = cp;
      const Vector3d r_c = cp - p;
      // Lateral part of the normal force (sloped floor): goes to the chassis directly.
      const Vector3d lateral = n_load * nrm + n_axis * dir;
      if (lateral.squaredNorm() > 1e-18) apply_at(dt * lateral, r_c);
      Vector3d f = axle.cross(nrm);
      const double fn = f.norm();
      f = fn > 1e-9 ? Vector3d(f / fn) : Vector3d(R.col(0));
      const Vector3d l = nrm.cross(f);
      const Friction fr = st.friction_override.value_or(hit.friction);
      // exp(-0) is exactly 1: no call for a contact that did not slip (e.g. every caster).
      const double decay =
          st.last_slip_m_s == 0
              ? 1.0
              : std::exp(-std::abs(st.last_slip_m_s) / spec_.stribeck_velocity_m_s);
      const double mu = st.friction_scale * (fr.mu_slide + (fr.mu_peak - fr.mu_slide) * decay);
      tr.mu = mu;
      const double lim = mu * n_load * dt;
      const double rr = ws.rolling_resistance * n_load * dt;
      Vector3d u = f;
      auto add_row = [&](const Vector3d& lin, double jw, double target, double lo, double hi,
                         double* lambda, double jr = 0.0) -> Row* {
        if (nrows >= kMaxRows) return nullptr;
        Row& row = rows_buf[nrows++];
        row.lin = lin;
        row.ang = r_c.cross(lin);
        row.iang = Iinv * row.ang;
        row.lin_m = lin * inv_m;
        row.jw = jw;
        row.jw_i = ws.kind == WheelKind::kCaster ? 0.0 : jw * st.inv_inertia;
        row.jr = jr;
        row.jr_i = jr * st.roller_inv_inertia;
        row.wheel = static_cast<int>(i);
        const double k =
            inv_m * lin.squaredNorm() + row.ang.dot(row.iang) + jw * row.jw_i + jr * row.jr_i;
        row.inv_k = k > 1e-12 ? 1.0 / k : 0.0;
        row.cfm = 0;
        row.target = target;
        row.lo = lo;
        row.hi = hi;
        row.lambda = lambda;
        row.partner = -1;
        row.radius = 0;
        row.lateral_scale = 1;
        return &row;
      };
      switch (ws.kind) {
        case WheelKind::kConventional: {
          Row* a = add_row(f, -r_eff, -kAnchorGain * st.anchor_a_m / dt, -lim, lim, &st.lambda_a);
          const std::size_t ia = nrows - 1;
          add_row(l, 0.0, -kAnchorGain * st.anchor_b_m / dt, -lim * ws.lateral_mu_scale,
                  lim * ws.lateral_mu_scale, &st.lambda_b);
          if (a != nullptr && nrows == ia + 2) {
            a->partner = static_cast<int>(ia + 1);
            a->radius = lim;
            a->lateral_scale = ws.lateral_mu_scale;
          }
          break;
        }
        case WheelKind::kMecanum:
        case WheelKind::kOmni:
        case WheelKind::kOrthogonal: {
          u = geo.roller_cos * l + geo.roller_sin * f;
          const Vector3d free_dir = nrm.cross(u);
          add_row(u, -r_roll * f.dot(u), -kAnchorGain * st.anchor_a_m / dt, -lim, lim,
                  &st.lambda_a);
          if (roller_state) {
            // The roller in contact rolls along free_dir on its own spin (inertia, bearing):
            // no slip there up to the friction bound; its bearing row below resists the spin.
            add_row(free_dir, -r_roll * f.dot(free_dir), 0.0, -lim, lim, &st.lambda_b,
                    geo.roller_radius_m);
            const double tau = ws.rollers.bearing_friction_nm +
                               ws.rolling_resistance * n_load * geo.roller_radius_m;
            add_row(Vector3d::Zero(), 0.0, 0.0, -tau * dt, tau * dt, &st.lambda_roller, 1.0);
          } else {
            // Free rollers: rolling resistance, plus the bearing friction seen at the contact.
            const double rb = geo.roller >= 0 && geo.roller_radius_m > 0
                                  ? rr + ws.rollers.bearing_friction_nm / geo.roller_radius_m * dt
                                  : rr;
            add_row(free_dir, -r_roll * f.dot(free_dir), 0.0, -rb, rb, &st.lambda_b);
          }
          break;
        }
        case WheelKind::kCaster: {
          // A swivel caster turns into its direction of travel: its rolling resistance c_rr*N
          // opposes the contact's velocity, whatever its direction (one circle, not a box per
          // axis). Two independent +-c_rr*N rows would hold the contact sideways with full
          // stiction while it rolls forward, i.e. resist yaw like a skid.
          Row* a = add_row(f, 0.0, 0.0, -rr, rr, &st.lambda_a);
          const std::size_t ia = nrows - 1;
          add_row(l, 0.0, 0.0, -rr, rr, &st.lambda_b);
          if (a != nullptr && nrows == ia + 2) {
            a->partner = static_cast<int>(ia + 1);
            a->radius = rr;
            a->lateral_scale = 1.0;
          }
          break;
        }
      }
      contact[i] = Contact{f, l, u, r_c, r_roll};
    }
    // Spin rows: motor (driven) or bearing friction (passive), no chassis coupling.
    if (ws.kind == WheelKind::kCaster) continue;
    // External disturbance torque (fault hook): explicit, like the motor's integral part.
    omega[i] += st.disturbance_nm * dt * st.inv_inertia;
    if (ws.driven && nrows < kMaxRows) {
      const MotorSpec& m = ws.motor;
      double cmd = command_[i];
      if (m.max_accel_rad_s2 > 0) {
        const double step = m.max_accel_rad_s2 * dt;
        cmd = std::clamp(cmd, st.omega_cmd_slewed - step, st.omega_cmd_slewed + step);
      }
      st.omega_cmd_slewed = cmd;
      const double kt = m.torque_constant_nm_a * m.gear_ratio;  // wheel torque per amp
      double hi = m.TorqueLimitNm();
      double lo = -hi;
      if (m.winding_resistance_ohm > 0) {
        const double emf = kt * omega[i];  // volts (k_e = k_t in SI)
        hi = std::min(hi, kt * (m.supply_voltage_v - emf) / m.winding_resistance_ohm);
        lo = std::max(lo, kt * (-m.supply_voltage_v - emf) / m.winding_resistance_ohm);
        if (lo > hi) lo = hi = 0.5 * (lo + hi);
      }
      // The drive's limit bounds whatever the motor could give (0: no torque at all).
      hi = std::clamp(hi, -st.drive_limit_nm, st.drive_limit_nm);
      lo = std::clamp(lo, -st.drive_limit_nm, st.drive_limit_nm);
      // Integral part: an explicit torque inside the same window; proportional part: a soft
      // row (cfm = 1/(gain*dt)) solved with the contacts.
      st.motor_integral_nm = std::clamp(st.motor_integral_nm, lo, hi);
      omega[i] += st.motor_integral_nm * dt * st.inv_inertia;
      Row& row = rows_buf[nrows++];
      row.partner = -1;
      row.radius = 0;
      row.lateral_scale = 1;
      row.lin.setZero();
      row.lin_m.setZero();
      row.ang.setZero();
      row.iang.setZero();
      row.jw = 1;
      row.jw_i = st.inv_inertia;
      row.jr = 0;
      row.jr_i = 0;
      row.wheel = static_cast<int>(i);
      row.cfm = 1.0 / (m.speed_gain_nm_s_rad * dt);
      row.inv_k = 1.0 / (st.inv_inertia + row.cfm);
      row.target = cmd;
      row.lo = (lo - st.motor_integral_nm) * dt;
      row.hi = (hi - st.motor_integral_nm) * dt;
      row.lambda = &st.lambda_motor;
    } else if (!ws.driven && nrows < kMaxRows) {
      double tau = ws.bearing_friction_nm;
      if (ws.kind == WheelKind::kConventional && tr.in_contact) {
        tau += ws.rolling_resistance * tr.normal_load_n * r_eff;
      }
      Row& row = rows_buf[nrows++];
      row.partner = -1;
      row.radius = 0;
      row.lateral_scale = 1;
      row.lin.setZero();
      row.lin_m.setZero();
      row.ang.setZero();
      row.iang.setZero();
      row.jw = 1;
      row.jw_i = st.inv_inertia;
      row.jr = 0;
      row.jr_i = 0;
      row.wheel = static_cast<int>(i);
      row.inv_k = 1.0 / st.inv_inertia;
      row.cfm = 0;
      row.target = 0;
      row.lo = -tau * dt;
      row.hi = tau * dt;
      row.lambda = &st.lambda_spin;
    }
  }

  auto apply_row = [&](const Row& row, double d) {
    v += row.lin_m * d;
    w += row.iang * d;
    omega[row.wheel] += row.jw_i * d;
    roller_omega[row.wheel] += row.jr_i * d;
  };
  auto row_velocity = [&](const Row& row) {
    return row.lin.dot(v) + row.ang.dot(w) + row.jw * omega[row.wheel] +
           row.jr * roller_omega[row.wheel];
  };
  // Warm start with last step's impulses, clamped to this step's bounds.
  for (std::size_t k = 0; k < nrows; ++k) {
    Row& row = rows_buf[k];
    double lam = std::clamp(*row.lambda, row.lo, row.hi);
    *row.lambda = lam;
    apply_row(row, lam);
  }
  // Projected Gauss-Seidel; stops early once no row changes its velocity by more than
  // kSolverTolerance (a deterministic test, so runs stay bit-identical).
  int sweeps = 0;
  for (int it = 0; it < spec_.solver_iterations; ++it) {
    ++sweeps;
    double max_change = 0;
    for (std::size_t k = 0; k < nrows; ++k) {
      Row& row = rows_buf[k];
      if (row.partner >= 0) {
        // Conventional pair: solve both, clamp the impulse to the friction ellipse.
        Row& lat = rows_buf[static_cast<std::size_t>(row.partner)];
        const double la0 = *row.lambda, lb0 = *lat.lambda;
        double la = la0 + (row.target - row_velocity(row)) * row.inv_k;
        double lb = lb0 + (lat.target - row_velocity(lat)) * lat.inv_k;
        const double ex = la / std::max(row.radius, 1e-300);
        const double ey = lb / std::max(row.radius * row.lateral_scale, 1e-300);
        // Inside the ellipse with a wide margin: hypot (< 1 ulp error) cannot exceed 1.
        if (!(ex * ex + ey * ey <= 0.999)) {
          const double e = std::hypot(ex, ey);
          if (e > 1.0) {
            la /= e;
            lb /= e;
          }
        }
        *row.lambda = la;
        *lat.lambda = lb;
        apply_row(row, la - la0);
        apply_row(lat, lb - lb0);
        if (row.inv_k > 0) max_change = std::max(max_change, std::abs(la - la0) / row.inv_k);
        if (lat.inv_k > 0) max_change = std::max(max_change, std::abs(lb - lb0) / lat.inv_k);
        ++k;  // the lateral row follows directly and was handled here
        continue;
      }
      const double old = *row.lambda;
      const double lam = std::clamp(
          old + (row.target - row_velocity(row) - row.cfm * old) * row.inv_k, row.lo, row.hi);
      *row.lambda = lam;
      apply_row(row, lam - old);
      if (row.inv_k > 0) max_change = std::max(max_change, std::abs(lam - old) / row.inv_k);
    }
    if (max_change < kSolverTolerance) break;
  }
  body_truth_.solver_sweeps = sweeps;

  body_->setLinearVelocity(ToBt(v));
  body_->setAngularVelocity(ToBt(w));

  // Post-solve ground truth, stiction anchors and wheel angles.
  for (std::size_t i = 0; i < nw; ++i) {
    const WheelSpec& ws = spec_.wheels[i];
    WheelState& st = state_[i];
    WheelTruth& tr = truth_[i];
    if (ws.kind == WheelKind::kCaster) omega[i] = 0;
    if (!st.roller_omega.empty()) UpdateRollerSpins(i, roller_omega[i], dt);
    tr.omega_rad_s = omega[i];
    tr.angle_rad += omega[i] * dt;
    const Contact& ct = contact[i];
    tr.rim_travel_m += omega[i] * ct.r_eff * dt;
    if (ws.driven) {
      tr.motor_torque_nm = st.lambda_motor / dt + st.motor_integral_nm;
      st.motor_integral_nm += ws.motor.integral_gain_nm_rad * (st.omega_cmd_slewed - omega[i]) * dt;
      tr.motor_current_a =
          tr.motor_torque_nm / (ws.motor.torque_constant_nm_a * ws.motor.gear_ratio);
    }
    if (!tr.in_contact) {
      tr.slip_velocity_m_s.setZero();
      tr.slip_speed_m_s = 0;
      tr.slipping = false;
      continue;
    }
    const Vector3d vc = v + w.cross(ct.r_c);
    double ground_speed = 0;
    if (ws.kind == WheelKind::kConventional) {
      const double sa = vc.dot(ct.f) - omega[i] * ct.r_eff;
      const double sb = vc.dot(ct.l);
      tr.slip_velocity_m_s = Eigen::Vector2d(sa, sb);
      ground_speed = vc.dot(ct.f);
      const bool sat = Saturated(st.lambda_a, st.lambda_b / ws.lateral_mu_scale,
                                 0.999 * tr.mu * tr.normal_load_n * dt);
      st.anchor_a_m = sat ? 0.0 : st.anchor_a_m + sa * dt;
      st.anchor_b_m = sat ? 0.0 : st.anchor_b_m + sb * dt;
    } else if (ws.kind == WheelKind::kCaster) {
      tr.slip_velocity_m_s.setZero();
      ground_speed = vc.dot(ct.f);
    } else {
      const double fu = ct.f.dot(ct.u);
      const double su = vc.dot(ct.u) - omega[i] * ct.r_eff * fu;
      tr.slip_velocity_m_s = su * Eigen::Vector2d(fu, ct.l.dot(ct.u));
      ground_speed = vc.dot(ct.u) / fu;
      const bool sat = std::abs(st.lambda_a) >= 0.999 * tr.mu * tr.normal_load_n * dt;
      st.anchor_a_m = sat ? 0.0 : st.anchor_a_m + su * dt;
    }
    tr.ground_travel_m += ground_speed * dt;
    tr.slip_speed_m_s = tr.slip_velocity_m_s.norm();
    st.last_slip_m_s = tr.slip_speed_m_s;
    tr.slipping = tr.slip_speed_m_s > spec_.slip_threshold_m_s;
  }
}

void RollerVehicle::updateAction(btCollisionWorld* /*world*/, btScalar /*dt*/) {
  const btTransform& T = body_->getWorldTransform();
  const btQuaternion q = T.getRotation();
  body_truth_.p_WB = ToEigen(T.getOrigin());
  body_truth_.q_WB = Eigen::Quaterniond(q.w(), q.x(), q.y(), q.z());
  const Vector3d v = ToEigen(body_->getLinearVelocity());
  const Vector3d w = ToEigen(body_->getAngularVelocity());
  body_truth_.a_WB_W = (v - prev_v_W_) / last_dt_s_;
  body_truth_.alpha_WB_W = (w - prev_w_W_) / last_dt_s_;
  body_truth_.v_WB_W = v;
  body_truth_.omega_WB_W = w;
  prev_v_W_ = v;
  prev_w_W_ = w;
  const Matrix3d R = body_truth_.q_WB.toRotationMatrix();
  const double yaw = std::atan2(R(1, 0), R(0, 0));
  body_truth_.yaw_rad += std::remainder(yaw - prev_yaw_wrapped_, 2 * kPi);
  prev_yaw_wrapped_ = yaw;
}

}  // namespace wheelhil::emulator::physics
