#pragma once
/// Paper 002: body velocity from four single-axis accelerometers and wheel odometry (see
/// docs/estimators.md and /work/shared/seeds/REFERENCE.md).
///
/// Frame: body frame B, x forward, y left, z up, omega counter-clockwise. The three task-space
/// axes are indexed kX (m), kY (m), kTheta (rad); "position" of an axis means the odometry's
/// accumulated body-frame displacement along it (its time derivative is the body velocity).
///
/// Accelerometer mounting that eq 3 implies (each sensor senses along a tangent, so the
/// centripetal term, which is radial, never enters a reading):
///   a1 at ( 0, +R) senses +x:  a1 =  ax - alpha R
///   a2 at (+R,  0) senses +y:  a2 =  ay + alpha R
///   a3 at (-R,  0) senses -y:  a3 = -ay + alpha R
///   a4 at ( 0, -R) senses -x:  a4 = -ax - alpha R

#include <array>
#include <cstdint>

namespace wheelhil::fw {

/// Body acceleration in B: translational [m/s^2] and angular [rad/s^2].
struct BodyAccel {
  double ax_m_s2 = 0.0;
  double ay_m_s2 = 0.0;
  double alpha_rad_s2 = 0.0;
};

/// Eq 3: the four readings a1..a4 [m/s^2] -> body acceleration. R = mount radius [m] > 0.
/// Any noise common to all four readings cancels exactly.
BodyAccel DecoupleAccelerometers(const std::array<double, 4>& a_m_s2,
                                 double mount_radius_m) noexcept;

/// The forward model of eq 3: body acceleration -> readings a1..a4 (tests, emulator checks).
std::array<double, 4> AccelerometerReadings(const BodyAccel& a, double mount_radius_m) noexcept;

/// Gains of the sliding-mode observer of eq 5, for one axis. Units: u = the axis unit (m or rad).
struct SlidingModeGains {
  double k11_1_s = 80.0;     ///< Linear position-error gain [1/s], > 0.
  double k12_u_s = 0.002;    ///< Switching position gain [u/s], >= 0.
  double k21_1_s2 = 1600.0;  ///< Linear velocity-error gain [1/s^2], > 0.
  double k22_u_s2 = 0.5;     ///< Switching velocity gain [u/s^2], >= 0.
  /// Boundary layer phi [u]: sgn(e) is replaced by clamp(e/phi, -1, 1); 0 = the paper's pure
  /// sgn. The default 0.1 mm removes the explicit-Euler chatter at 1 ms (docs/estimators.md).
  double boundary_layer_u = 1e-4;
};

/// Eq 5, one axis, explicit Euler at the step's dt:
///   e = xh1 - x1;  s = sgn(e) (or clamp(e/phi, -1, 1) with a boundary layer)
///   xh1 += dt * (xh2 - k11 e - k12 s)
///   xh2 += dt * (f  - k21 e - k22 s)
/// xh2 is the velocity estimate. Explicit Euler turns the state into a one-step prediction, so
/// position()/velocity() report the state at the time of the last measurement (before it is
/// advanced by dt), not the prediction for the next one; on a constant acceleration a the
/// prediction would read a*dt high. The first Step sets xh1 = x1, xh2 = 0.
/// Thread-compatible.
class SlidingModeObserver {
 public:
  SlidingModeObserver() = default;
  /// Throws std::invalid_argument naming the gain on bad values.
  explicit SlidingModeObserver(const SlidingModeGains& gains);

  /// One step with the measured position x1 [u], the model acceleration f [u/s^2] (commanded
  /// acceleration, or 0) and dt [s]. Returns false, changing nothing, on non-finite input or
  /// dt <= 0.
  [[nodiscard]] bool Step(double x1_u, double f_u_s2, double dt_s) noexcept;
  /// A period without a measurement: the state runs open loop on the model acceleration f
  /// [u/s^2] (xh1 += dt xh2, xh2 += dt f; position()/velocity() report the state before).
  /// Nothing before the first Step. Returns false, changing nothing, on non-finite input or
  /// dt <= 0.
  [[nodiscard]] bool Predict(double f_u_s2, double dt_s) noexcept;
  /// Limits the innovation the next Step(x1_u, ...) will see to |xh1 - x1| <= max_error_u by
  /// shifting the position state xh1 (velocity untouched). For a measurement that resumes
  /// after a gap: the displacement the prediction did not expect moves the position, it is not
  /// read as one period's velocity. Ignored on non-finite input or before the first Step.
  void LimitInnovation(double x1_u, double max_error_u) noexcept;
  void Reset() noexcept {
    started_ = false;
    xh1_ = xh2_ = position_ = velocity_ = 0.0;
  }

  /// Estimates at the time of the last measurement [u], [u/s].
  double position() const { return position_; }
  double velocity() const { return velocity_; }
  const SlidingModeGains& gains() const { return gains_; }

 private:
  SlidingModeGains gains_;
  bool started_ = false;
  double xh1_ = 0.0;  // State predicted for the next measurement.
  double xh2_ = 0.0;
  double position_ = 0.0;  // State at the last measurement.
  double velocity_ = 0.0;
};

enum FusionAxis : int { kX = 0, kY = 1, kTheta = 2 };

struct FusionAxisConfig {
  SlidingModeGains observer;
  /// d_i: disturbance threshold on |commanded - measured acceleration| [u/s^2], > 0.
  double disturbance_threshold_u_s2 = 0.1;
  /// tau_i: recovery time constant of the weight k [s], > 0.
  double recovery_time_s = 0.1;
};

struct VelocityFusionConfig {
  double period_s = 0.001;            ///< dt between Steps [s], > 0 (paper: 1 ms).
  double accel_mount_radius_m = 0.0;  ///< R of eq 3 [m], > 0 (used by StepRaw).
  /// Per axis x, y, theta. Defaults: tau = 100, 150, 200 ms; d = 0.1 m/s^2 (x, y), 0.5 rad/s^2.
  std::array<FusionAxisConfig, 3> axes = {
      FusionAxisConfig{{}, 0.1, 0.100}, FusionAxisConfig{{}, 0.1, 0.150},
      FusionAxisConfig{{80.0, 0.002, 1600.0, 0.5, 1e-4}, 0.5, 0.200}};
  /// Weight floor k_min in (0, 1]: k right after a disturbance.
  double k_min = 0.01;
  /// Feed the commanded acceleration to the observer as f (else f = 0).
  bool observer_uses_commanded_accel = true;
  /// Subtract the rotation term omega x v when integrating body-frame accelerations (the paper
  /// moves in a straight line and does not need it).
  bool compensate_rotation = true;
};

/// What one axis produced in one Step. Units u/s (m/s or rad/s) unless stated.
struct FusionAxisOutput {
  double fused = 0.0;             ///< Disturbance-weighted fusion.
  double odometry = 0.0;          ///< Observer velocity xh2 (odometry only).
  double accel_integrated = 0.0;  ///< Pure accelerometer integration from the start (drifts).
  double weight_k = 1.0;          ///< k in [k_min, 1): weight of the odometry velocity.
  double disturbance_u_s2 = 0.0;  ///< commanded - measured acceleration.
  bool disturbed = false;         ///< |disturbance| > d_i in this step.
  double time_since_disturbance_s = 0.0;
  /// False in a period stepped without odometry (StepUnobserved): the weight applied was 0
  /// (fused = inertial propagation, whatever weight_k says) and `odometry` is the value of the
  /// last observed period, held.
  bool odometry_observed = true;
};

struct FusionOutput {
  std::array<FusionAxisOutput, 3> axes;
};

/// Section 5 fusion, per axis i, every period dt (see docs/estimators.md for the exact law):
///   disturbance D_i = f_i - a_i, a_i = measured d/dt of the body velocity;
///   t_i = time since |D_i| last exceeded d_i;
///   k_i = 1 - (1 - k_min) / (1 + (t_i/tau_i)^2)          (k_min at t=0, -> 1)
///   w_i = 1 - (1 - k_i)^(dt/1 ms)                        (k is the paper's per-1-ms weight)
///   v_i = w_i * xh2_i + (1 - w_i) * (v_i + a_i dt)       (odometry vs inertial propagation)
/// Odometry gap (StepUnobserved, e.g. an encoder missing: the wheel kinematics needs every
/// wheel): every axis propagates on the accelerometers alone, v_i = v_i + a_i dt (w_i = 0, the
/// paper's mechanism for disturbed odometry; D_i, t_i, k_i keep running), and each observer
/// predicts open loop with f = a_i (SlidingModeObserver::Predict). The first observed Step
/// after a gap first shifts each observer's position so that the innovation is at most its
/// boundary layer phi (SlidingModeObserver::LimitInnovation), then fuses as usual: the
/// displacement gathered over the gap moves the position but never enters the observer as one
/// period's velocity, and a gap short enough for the prediction to stay within phi goes
/// unnoticed.
/// Starts at rest (all velocities 0). Thread-compatible; no allocation.
class VelocityFusion {
 public:
  /// Throws std::invalid_argument naming the field on bad values.
  explicit VelocityFusion(const VelocityFusionConfig& config);

  /// One period. odometry_position: accumulated body-frame displacement (x_m, y_m, theta_rad);
  /// measured: body acceleration (e.g. from DecoupleAccelerometers); commanded: commanded
  /// acceleration per axis (zeros if none). Returns false, changing nothing, on non-finite input.
  [[nodiscard]] bool Step(const std::array<double, 3>& odometry_position, const BodyAccel& measured,
                          const std::array<double, 3>& commanded) noexcept;
  /// The same with the four raw accelerometer readings a1..a4 [m/s^2].
  [[nodiscard]] bool StepRaw(const std::array<double, 3>& odometry_position,
                             const std::array<double, 4>& accelerometers_m_s2,
                             const std::array<double, 3>& commanded) noexcept;

  /// One period without odometry (see the class comment); measured and commanded as in Step.
  /// Returns false, changing nothing, on non-finite input.
  [[nodiscard]] bool StepUnobserved(const BodyAccel& measured,
                                    const std::array<double, 3>& commanded) noexcept;
  [[nodiscard]] bool StepRawUnobserved(const std::array<double, 4>& accelerometers_m_s2,
                                       const std::array<double, 3>& commanded) noexcept;

  const FusionOutput& last() const { return out_; }
  /// True after StepUnobserved until the next observed Step.
  bool in_odometry_gap() const { return odometry_gap_; }
  void Reset() noexcept;

  const VelocityFusionConfig& config() const { return config_; }

 private:
  VelocityFusionConfig config_;
  std::array<SlidingModeObserver, 3> observers_;
  std::array<double, 3> fused_{};
  std::array<double, 3> integrated_{};
  std::array<double, 3> since_disturbance_s_{};
  bool odometry_gap_ = false;
  std::array<double, 3> odometry_velocity_{};  // Observer velocity of the last observed period.
  FusionOutput out_;

  // The common step; odometry_position == nullptr: a period without odometry.
  bool DoStep(const std::array<double, 3>* odometry_position, const BodyAccel& measured,
              const std::array<double, 3>& commanded) noexcept;
};

}  // namespace wheelhil::fw
