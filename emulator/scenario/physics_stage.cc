#include "emulator/scenario/physics_stage.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <random>

#include <fmt/format.h>

namespace wheelhil::emulator::scenario {

namespace {

using nlohmann::json;

}  // namespace

PhysicsStage::PhysicsStage(const Scenario& scenario, std::uint64_t seed, sim::RunContext& run)
    : s_(scenario), run_(run) {
  BuildWorld(seed);
}

PhysicsStage::~PhysicsStage() = default;

void PhysicsStage::BuildWorld(std::uint64_t seed) {
  physics::WorldOptions wo;
  wo.step_s = 1.0 / s_.timing.physics_rate_hz;
  step_ns_ = std::llround(1e9 / s_.timing.physics_rate_hz);
  world_ = std::make_unique<physics::PhysicsWorld>(wo);
  Terrain& terrain = world_->terrain();
  terrain.AddPlane(Eigen::Vector3d::UnitZ(), Eigen::Vector3d::Zero(), s_.terrain.friction);
  for (const auto& m : s_.terrain.meshes) {
    MeshOptions mo;
    mo.friction = s_.terrain.friction;
    terrain.AddMesh(m, mo);
  }
  for (const auto& p : s_.terrain.patches) {
    terrain.AddPatch(FrictionPatch{p.name, p.polygon_m, p.friction});
  }
  const auto& rp = s_.terrain.random_patches;
  if (rp.count > 0) {
    std::mt19937_64 rng(seed ^ 0x5157AB1Eull);
    std::uniform_real_distribution<double> ux(rp.x_min_m, rp.x_max_m);
    std::uniform_real_distribution<double> ul(rp.length_min_m, rp.length_max_m);
    std::uniform_int_distribution<std::size_t> ut(0, rp.track_y_m.size() - 1);
    const bool stratified = rp.placement == RandomPatchesSpec::Placement::kStratified;
    const double section = (rp.x_max_m - rp.x_min_m) / rp.count;
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    for (int i = 0; i < rp.count; ++i) {
      double x = 0;
      double len = 0;
      if (stratified) {
        len = ul(rng);
        x = rp.x_min_m + i * section + u01(rng) * (section - len);
      } else {
        x = ux(rng);
        len = ul(rng);
      }
      const double y = rp.track_y_m[ut(rng)];
      const double hw = rp.width_m / 2;
      FrictionPatch p{fmt::format("random{}", i),
                      {{x, y - hw}, {x + len, y - hw}, {x + len, y + hw}, {x, y + hw}},
                      rp.friction};
      terrain.AddPatch(p);
      run_.events.push_back(json{{"t_s", 0.0},
                                 {"event", "patch"},
                                 {"name", p.name},
                                 {"x_m", x},
                                 {"y_m", y},
                                 {"length_m", len},
                                 {"mu_peak", rp.friction.mu_peak}});
    }
  }
  AddBumps(terrain);
  if (s_.sample_tolerances && s_.platform.tolerances.any()) {
    // The robot as built: every wheel off its nominal geometry within the file's tolerances.
    const auto deviations = platforms::DrawWheelDeviations(s_.platform, seed);
    for (std::size_t i = 0; i < deviations.size(); ++i) {
      const auto& d = deviations[i];
      run_.events.push_back(json{{"t_s", 0.0},
                                 {"event", "wheel_as_built"},
                                 {"wheel", s_.platform.vehicle.wheels[i].name},
                                 {"radius_dev_m", d.radius_m},
                                 {"mount_x_dev_m", d.mount_x_m},
                                 {"mount_y_dev_m", d.mount_y_m},
                                 {"heading_dev_rad", d.heading_rad},
                                 {"roller_angle_dev_rad", d.roller_angle_rad}});
    }
    vehicle_ =
        &world_->AddVehicle(platforms::AsBuilt(s_.platform.vehicle, deviations), 0.0, 0.0, 0.0);
  } else {
    vehicle_ = &world_->AddVehicle(s_.platform.vehicle, 0.0, 0.0, 0.0);
  }
  body_ = &vehicle_->body_truth();
  wheels_ = &vehicle_->wheel_truth();
}

void PhysicsStage::AddBumps(Terrain& terrain) {
  int n = 0;
  for (const auto& f : s_.faults) {
    if (f.kind != FaultSpec::Kind::kBump) continue;
    // A ridge across x: foot, top start, top end, foot; two rows of vertices at y -/+ width/2.
    const double xs[4] = {f.x_m, f.x_m + f.ramp_length_m, f.x_m + f.ramp_length_m + f.top_length_m,
                          f.x_m + 2 * f.ramp_length_m + f.top_length_m};
    const double zs[4] = {0.0, f.height_m, f.height_m, 0.0};
    std::vector<Eigen::Vector3d> v;
    for (int side = 0; side < 2; ++side) {
      const double y = f.y_m + (side == 0 ? -0.5 : 0.5) * f.width_m;
      for (int j = 0; j < 4; ++j) v.emplace_back(xs[j], y, zs[j]);
    }
    std::vector<std::array<int, 3>> tris;
    for (int j = 0; j < 3; ++j) {
      if (j == 1 && f.top_length_m <= 0) continue;
      tris.push_back({j, j + 1, 4 + j + 1});
      tris.push_back({j, 4 + j + 1, 4 + j});
    }
    terrain.AddTriangles(v, tris, f.bump_friction.value_or(s_.terrain.friction),
                         fmt::format("bump{}", n));
    run_.events.push_back(json{{"t_s", 0.0},
                               {"event", "fault_applied"},
                               {"category", "physics"},
                               {"fault", "bump"},
                               {"name", fmt::format("bump{}", n)},
                               {"x_m", f.x_m},
                               {"y_m", f.y_m},
                               {"width_m", f.width_m},
                               {"height_m", f.height_m},
                               {"ramp_length_m", f.ramp_length_m},
                               {"top_length_m", f.top_length_m}});
    ++n;
  }
}

void PhysicsStage::StartMotion(std::int64_t t0_ns) {
  t_motion0_s_ = static_cast<double>(t0_ns) * 1e-9;
  motion0_ns_ = t0_ns;
}

void PhysicsStage::SetDrives(const std::vector<WheelDrive>& drives) {
  for (const WheelDrive& d : drives) {
    (void)vehicle_->SetWheelSpeedCommand(d.wheel, d.command.omega_rad_s);
    (void)vehicle_->SetMotorTorqueLimit(d.wheel, d.command.torque_limit_nm);
  }
}

void PhysicsStage::Command(std::int64_t t_ns, bool motion) {
  if (s_.firmware_motion) return;  // the drives command the wheels (SetDrives)
  if (!motion) {
    platforms::CommandTwist(*vehicle_, s_.platform, platforms::BodyTwist{});
    return;
  }
  const double tm = static_cast<double>(t_ns) * 1e-9 - t_motion0_s_;
  double t0 = 0;
  bool wheels = false;
  for (const auto& m : s_.motion) {
    if (tm >= t0 && tm < t0 + m.duration_s && m.kind == MotionSegment::Kind::kWheels) {
      for (std::size_t i = 0; i < m.wheel_speeds_rad_s.size(); ++i) {
        (void)vehicle_->SetWheelSpeedCommand(i, m.wheel_speeds_rad_s[i]);
      }
      wheels = true;
    }
    t0 += m.duration_s;
  }
  if (!wheels) platforms::CommandTwist(*vehicle_, s_.platform, TwistAt(s_.motion, tm));
}

void PhysicsStage::ApplyPhysicalFaults(double tm_s, std::vector<json>& events) {
  if (physical_on_.size() != s_.faults.size()) {
    physical_on_.assign(s_.faults.size(), 0);
    has_physical_faults_ = std::any_of(s_.faults.begin(), s_.faults.end(), [](const FaultSpec& f) {
      return f.kind == FaultSpec::Kind::kWheelFriction ||
             f.kind == FaultSpec::Kind::kTorqueDisturbance;
    });
  }
  // Called every step: nothing to do (and nothing to allocate) without a physical fault.
  if (!has_physical_faults_) return;
  const std::size_t nw = s_.platform.vehicle.wheels.size();
  // Per-wheel scratch, sized once (assign does not reallocate after the first step).
  phys_scale_.assign(nw, 1.0);
  phys_torque_.assign(nw, 0.0);
  phys_over_.assign(nw, std::nullopt);
  phys_touched_.assign(nw, 0);
  for (std::size_t i = 0; i < s_.faults.size(); ++i) {
    const FaultSpec& f = s_.faults[i];
    if (f.kind != FaultSpec::Kind::kWheelFriction &&
        f.kind != FaultSpec::Kind::kTorqueDisturbance) {
      continue;
    }
    phys_touched_[f.wheel_index] = 1;
    const bool on = tm_s >= f.start_s && tm_s < f.end_s;
    if (on) {
      if (f.kind == FaultSpec::Kind::kWheelFriction) {
        phys_scale_[f.wheel_index] *= f.mu_scale;
        if (f.mu_override) phys_over_[f.wheel_index] = f.mu_override;
      } else {
        phys_torque_[f.wheel_index] += f.torque_nm;
      }
    }
    if (static_cast<bool>(physical_on_[i]) == on) continue;
    physical_on_[i] = on;
    const bool friction = f.kind == FaultSpec::Kind::kWheelFriction;
    json ev{{"t_s", tm_s},
            {"event", on ? "fault_start" : "fault_end"},
            {"category", "physics"},
            {"fault", friction ? "wheel_friction" : "torque_disturbance"},
            {"wheel", f.wheel}};
    if (friction) {
      ev["mu_scale"] = f.mu_scale;
      if (f.mu_override) {
        ev["mu_peak"] = f.mu_override->mu_peak;
        ev["mu_slide"] = f.mu_override->mu_slide;
      }
    } else {
      ev["torque_nm"] = f.torque_nm;
    }
    events.push_back(ev);
  }
  for (std::size_t w = 0; w < nw; ++w) {
    if (!phys_touched_[w]) continue;
    (void)vehicle_->SetWheelFriction(w, phys_scale_[w], phys_over_[w]);
    (void)vehicle_->SetWheelDisturbanceTorque(w, phys_torque_[w]);
  }
}

void PhysicsStage::StepWorld(std::int64_t t_ns, bool motion, std::vector<json>& events) {
  Command(t_ns, motion);
  if (motion) ApplyPhysicalFaults(static_cast<double>(t_ns - motion0_ns_) * 1e-9, events);
  world_->Step();
}

bool PhysicsStage::Step(std::int64_t t_ns, bool motion) {
  if (motion && pipeline_) {
    try {
      slot_ = &pipeline_->Next();
    } catch (const std::exception& e) {
      run_.Fail(e.what());
      return false;
    }
    for (const json& e : slot_->events) run_.events.push_back(e);
    body_ = &slot_->body;
    wheels_ = &slot_->wheels;
    return true;
  }
  StepWorld(t_ns, motion, run_.events);
  body_ = &vehicle_->body_truth();
  wheels_ = &vehicle_->wheel_truth();
  return true;
}

std::optional<PhysicsStage::StepAhead> PhysicsStage::PeekMotionStep(std::int64_t ahead) {
  if (!pipeline_) return std::nullopt;
  const StepResult* r = pipeline_->Peek(ahead);
  if (r == nullptr) return std::nullopt;
  return StepAhead{&r->body, &r->wheels, &r->readings};
}

std::span<const double> PhysicsStage::readings(std::size_t device) const {
  if (slot_ == nullptr || device >= slot_->readings.size()) return {};
  return slot_->readings[device];
}

void PhysicsStage::StartWorker(std::int64_t steps, const cpu_set_t* cpus,
                               std::vector<std::unique_ptr<Device>>& devices, bool fall_back) {
  if (steps <= 0) return;
  // From here the worker owns the vehicle: what the run reads before the first motion step
  // (the truth row of the motion start) is a copy.
  start_state_.body = vehicle_->body_truth();
  start_state_.wheels = vehicle_->wheel_truth();
  body_ = &start_state_.body;
  wheels_ = &start_state_.wheels;
  // The worker also owns the sensor models of the devices that read ahead (their noise
  // streams); the run's thread still encodes every sample.
  std::vector<Device*> ahead(devices.size(), nullptr);
  bool any_ahead = false;
  for (std::size_t d = 0; d < devices.size(); ++d) {
    if (!devices[d]->ReadsAhead()) continue;
    devices[d]->StartReadingsAhead();
    ahead[d] = devices[d].get();
    any_ahead = true;
  }
  if (!any_ahead) ahead.clear();
  const std::int64_t t0_ns = run_.now_ns;
  worker_t0_ns_ = t0_ns;
  // 2048 steps of look-ahead (~2 s of motion at 1 kHz, ~1.5 MB): either side may lose its CPU
  // to another process for a time slice (a few ms) without the other running dry or blocking.
  pipeline_ = std::make_unique<sim::StepPipeline<StepResult>>(
      2048, steps,
      [this, t0_ns, ahead](std::int64_t step, StepResult& out) {
        out.events.clear();
        StepWorld(t0_ns + step * step_ns_, true, out.events);
        out.body = vehicle_->body_truth();
        out.wheels = vehicle_->wheel_truth();
        out.readings.resize(ahead.size());
        // The instants the run's thread samples after this step: those up to its end.
        const std::int64_t t_after = t0_ns + (step + 1) * step_ns_;
        for (std::size_t d = 0; d < ahead.size(); ++d) {
          out.readings[d].clear();
          if (ahead[d] != nullptr) ahead[d]->TakeReadingsAhead(t_after, out.body, out.readings[d]);
        }
      },
      cpus, fall_back);
  worker_used_ = true;
}

void PhysicsStage::StopWorker() { pipeline_.reset(); }

std::int64_t PhysicsStage::inline_from_ns() const {
  if (!pipeline_ || pipeline_->inline_from_step() < 0) return -1;
  return worker_t0_ns_ + pipeline_->inline_from_step() * step_ns_;
}

}  // namespace wheelhil::emulator::scenario
