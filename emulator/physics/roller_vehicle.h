#pragma once
/// A wheeled vehicle on Bullet: one btRigidBody chassis (no contact with anything - the wheels
/// carry it) and per wheel a raycast suspension with an unsprung hub, wheel spin with inertia,
/// a motor (driven) or bearing friction (passive), and roller contact friction:
///   conventional: along and across the rolling direction (friction circle/ellipse),
///   Mecanum:      only along the roller axis u = cos(a)*axle + sin(a)*rolling (a = +-45 deg),
///   omni/orthogonal: only along the rolling direction (a = 90 deg),
/// free directions carry only rolling resistance c_rr*N. A wheel with discrete rollers
/// (WheelSpec::rollers, geometry in roller_geometry.h) touches with the roller in contact: the
/// rolling radius, roller angle and contact offsets follow the wheel angle, the roller rolls on
/// its loaded radius and, with roller inertia, on its own spin against its bearing.
///
/// Contact and motor forces are solved at velocity level once per fixed step, in the world's
/// pre-tick callback (so they act in the same step): projected Gauss-Seidel over the rows
/// "contact slip = 0" (clamped to +-mu(s)*N*dt), "wheel speed = command" (clamped to the motor's
/// torque window * dt) and "free/rolling resistance", with warm starting and a stiction anchor
/// (accumulated creep is fed back, so a vehicle at rest does not drift). Slip curve:
///   mu(s) = mu_slide + (mu_peak - mu_slide) * exp(-|s| / v_stribeck)
/// with s the contact's slip speed of the previous step. The friction reaction acts on the wheel
/// spin: a wheel that loses traction spins up and its angle (the encoder truth) over-counts.
///
/// Frames: W world (z up), B body (x forward, y left, z up, origin at the chassis COM).
/// Thread-compatible; deterministic (no clocks, no randomness).

#include <memory>
#include <optional>
#include <vector>

#include <BulletDynamics/Dynamics/btActionInterface.h>
#include <Eigen/Core>
#include <Eigen/Geometry>

#include "emulator/physics/roller_geometry.h"
#include "emulator/physics/terrain.h"
#include "emulator/physics/vehicle_spec.h"

class btRigidBody;
class btCollisionShape;

namespace wheelhil::emulator::physics {

/// Per-wheel ground truth after a step.
struct WheelTruth {
  double angle_rad = 0;    ///< accumulated spin angle (double), the encoder's truth
  double omega_rad_s = 0;  ///< spin rate, positive rolls along the heading
  bool in_contact = false;
  double normal_load_n = 0;  ///< >= 0, zero off the floor
  Eigen::Vector2d slip_velocity_m_s =
      Eigen::Vector2d::Zero();  ///< (rolling, lateral) of the
                                ///< constrained slip: contact point against the rim
  double slip_speed_m_s = 0;    ///< |slip_velocity_m_s|
  bool slipping = false;        ///< slip_speed_m_s > VehicleSpec::slip_threshold_m_s
  double rim_travel_m = 0;      ///< integral of omega * effective radius
  double ground_travel_m = 0;   ///< integral of the rim speed the ground motion implies
  double suspension_length_m = 0;
  double effective_radius_m = 0;
  double motor_torque_nm = 0;  ///< wheel side (driven only)
  double motor_current_a = 0;
  Eigen::Vector3d contact_point_W = Eigen::Vector3d::Zero();
  double mu = 0;  ///< friction limit used in the step
  // Discrete rollers only (WheelSpec::rollers.count > 0):
  int roller = -1;                ///< the roller in contact (row * count + k), -1: none
  double roller_angle_rad = 0;    ///< its effective angle from the axle (floor plane)
  double roller_omega_rad_s = 0;  ///< its spin about its own axis (0 without roller inertia)
};

/// Body ground truth after a step.
struct BodyTruth {
  Eigen::Vector3d p_WB = Eigen::Vector3d::Zero();  ///< COM position
  Eigen::Quaterniond q_WB = Eigen::Quaterniond::Identity();
  double yaw_rad = 0;  ///< unwrapped heading (continuous, accumulates turns)
  Eigen::Vector3d v_WB_W = Eigen::Vector3d::Zero();
  Eigen::Vector3d omega_WB_W = Eigen::Vector3d::Zero();
  Eigen::Vector3d a_WB_W = Eigen::Vector3d::Zero();      ///< linear acceleration (no gravity)
  Eigen::Vector3d alpha_WB_W = Eigen::Vector3d::Zero();  ///< angular acceleration
  int solver_sweeps = 0;  ///< contact-solver sweeps used in the last step (diagnostics)
};

class RollerVehicle : public btActionInterface {
 public:
  /// Builds the chassis resting its wheels at the given pose (X_WB: COM pose). Validates the
  /// spec (throws std::invalid_argument "vehicle 'name': wheels[i].field: problem").
  RollerVehicle(const VehicleSpec& spec, const Terrain* terrain, const Eigen::Isometry3d& X_WB,
                const Eigen::Vector3d& gravity_W);
  ~RollerVehicle() override;
  RollerVehicle(const RollerVehicle&) = delete;
  RollerVehicle& operator=(const RollerVehicle&) = delete;

  [[nodiscard]] btRigidBody* chassis() noexcept { return body_.get(); }
  [[nodiscard]] const VehicleSpec& spec() const noexcept { return spec_; }

  /// Commanded wheel speed (rad/s) of driven wheel i; ignored for passive wheels. Returns false
  /// for a bad index or a non-finite value.
  bool SetWheelSpeedCommand(std::size_t i, double omega_rad_s) noexcept;
  [[nodiscard]] double wheel_speed_command(std::size_t i) const noexcept;

  /// Fault hooks (scenario faults; deterministic, take effect from the next step):
  /// wheel i's contact friction becomes `override` (or the floor's when nullopt) with both
  /// mu_peak and mu_slide multiplied by scale (>= 0; 0: no traction at all). Returns false for a
  /// bad index, a negative/non-finite scale or an invalid override.
  bool SetWheelFriction(std::size_t i, double scale,
                        const std::optional<Friction>& override_friction = std::nullopt) noexcept;
  /// An external torque (N*m, about the axle, positive spins the wheel forward: +omega) added to
  /// wheel i's spin every step until changed (0: none), e.g. a brake drag or a kick. The motor
  /// servo of a driven wheel reacts to it as to any load. Returns false for a bad index or a
  /// non-finite value.
  bool SetWheelDisturbanceTorque(std::size_t i, double torque_nm) noexcept;
  /// A limit (N*m, wheel side, >= 0) on driven wheel i's motor torque on top of the motor's own
  /// window, set by the drive that powers it: 0 = the power stage is off and the wheel coasts
  /// (only its contacts, bearing and rotor inertia act on it); infinity = none. Returns false
  /// for a bad index, a passive wheel or a negative/NaN value.
  bool SetMotorTorqueLimit(std::size_t i, double limit_nm) noexcept;
  /// Spin inertia of wheel i about its axle (wheel + reflected rotor), kg*m^2; 0 for a bad index.
  [[nodiscard]] double wheel_spin_inertia(std::size_t i) const noexcept;

  /// Called by PhysicsWorld before Bullet integrates the step (pre-tick).
  void PreStep(double dt_s) noexcept;
  /// btActionInterface: called after Bullet integrated the step; records the body truth.
  void updateAction(btCollisionWorld* world, btScalar dt) override;
  void debugDraw(btIDebugDraw*) override {}

  [[nodiscard]] const BodyTruth& body_truth() const noexcept { return body_truth_; }
  [[nodiscard]] const std::vector<WheelTruth>& wheel_truth() const noexcept { return truth_; }
  [[nodiscard]] Eigen::Isometry3d pose() const noexcept;

 private:
  struct WheelState {
    double length_m = 0;
    double length_rate_m_s = 0;
    double ground_length_m = 0;  // last step's ray distance to the floor, for its rate
    bool ground_valid = false;
    double omega_cmd_slewed = 0;
    double lambda_motor = 0;       // warm start, impulses
    double motor_integral_nm = 0;  // PI servo integral torque
    double lambda_spin = 0;
    double lambda_a = 0;    // constrained row 1 (rolling or roller axis)
    double lambda_b = 0;    // row 2 (lateral for conventional, free for rollers)
    double anchor_a_m = 0;  // stiction anchors: accumulated creep while stuck
    double anchor_b_m = 0;
    double last_slip_m_s = 0;
    double inv_inertia = 0;                             // 1 / (wheel + reflected rotor inertia)
    Eigen::Vector3d axle_B = Eigen::Vector3d::UnitY();  // left of the rolling direction
    double roller_cos = 0, roller_sin = 1;
    double friction_scale = 1;                  // fault hook: multiplies mu_peak and mu_slide
    std::optional<Friction> friction_override;  // fault hook: replaces the floor's friction
    double disturbance_nm = 0;                  // fault hook: external spin torque
    double drive_limit_nm = 1e300;              // the drive's torque limit (0: power stage off)
    std::optional<RollerGeometry> rollers;      // discrete rollers
    std::vector<double> roller_omega;           // every roller's spin (with roller inertia)
    double roller_inv_inertia = 0;              // 0: rollers turn freely (no spin state)
    double lambda_roller = 0;                   // warm start of the roller bearing row
    double lambda_prev[3] = {0, 0, 0};          // last step's lambda_a, lambda_b, lambda_motor
  };
  // Where wheel i touches the floor at spin angle `angle`.
  struct ContactGeometry {
    double radius_m;
    double lateral_m;  // along the axle
    double forward_m;  // along the rolling direction
    double roller_cos, roller_sin;
    int roller;              // -1: no discrete rollers
    double roller_radius_m;  // contact to the roller's axis
  };
  ContactGeometry WheelGeometry(std::size_t i, double angle) const noexcept;
  // After the solve: the roller in contact takes its solved spin, the others coast down on
  // their bearings.
  void UpdateRollerSpins(std::size_t i, double contact_omega, double dt) noexcept;
  // Orthogonal wheel: rolling radius and the active half's offset along the axle.
  static double OrthogonalRadius(const WheelSpec& w, double angle, double* lateral_offset) noexcept;

  VehicleSpec spec_;
  const Terrain* terrain_;
  Eigen::Vector3d gravity_W_;
  std::unique_ptr<btCollisionShape> shape_;
  std::unique_ptr<btRigidBody> body_;
  std::vector<WheelState> state_;
  std::vector<WheelTruth> truth_;
  std::vector<double> command_;
  BodyTruth body_truth_;
  Eigen::Vector3d prev_v_W_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d prev_w_W_ = Eigen::Vector3d::Zero();
  double prev_yaw_wrapped_ = 0;
  double last_dt_s_ = 1e-3;
};

/// Validates a vehicle spec; throws std::invalid_argument naming the field.
void ValidateVehicleSpec(const VehicleSpec& spec, const std::string& where);

}  // namespace wheelhil::emulator::physics
