#include "emulator/scoring/metric_components.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <stdexcept>

#include <fmt/format.h>

#include "bus/normality.h"

namespace wheelhil::emulator::scoring {

namespace {

using nlohmann::json;

class PoseComponent final : public MetricComponent {
 public:
  std::string_view name() const override { return "pose"; }
  void Compute(const RecordedRun& run, json& metrics, std::vector<json>&) const override {
    for (const auto& [name, est] : run.estimates.pose_streams()) {
      const PoseMetrics m = ComputePoseMetrics(run.truth.poses(), est);
      json block{{"final_position_error_m", m.final_position_error_m},
                 {"ape_rmse_m", m.ape_rmse_m},
                 {"distance_m", m.distance_m},
                 {"rotation_rad", m.rotation_rad},
                 {"samples", m.samples}};
      if (!run.estimates.position_only().contains(name)) {
        block["final_heading_error_rad"] = m.final_heading_error_rad;
      }
      if (m.distance_m > 0) {
        block["final_position_error_pct_of_distance"] =
            100.0 * m.final_position_error_m / m.distance_m;
      }
      const bool heading = !run.estimates.position_only().contains(name);
      // evo's conventions: nearest truth sample within 10 ms, no alignment.
      const auto pairs = AssociateNearest(run.truth.poses(), est, 0.01);
      const ErrorStats ape = AbsolutePositionError(pairs);
      block["ape"] = json{{"pairs", ape.n},         {"rmse_m", ape.rmse}, {"mean_m", ape.mean},
                          {"median_m", ape.median}, {"std_m", ape.std},   {"min_m", ape.min},
                          {"max_m", ape.max}};
      const RelativePoseError rpe = ComputeRelativePoseError(pairs, 1.0);
      json rpe_block{{"segments", rpe.translation_m.n},
                     {"translation_rmse_m", rpe.translation_m.rmse},
                     {"translation_mean_m", rpe.translation_m.mean},
                     {"translation_max_m", rpe.translation_m.max}};
      if (heading) {
        rpe_block["rotation_rmse_rad"] = rpe.rotation_rad.rmse;
        rpe_block["rotation_max_rad"] = rpe.rotation_rad.max;
      }
      block["rpe_1m"] = std::move(rpe_block);
      metrics[name] = std::move(block);
    }
  }
};

// Paper 000, Table 2: the corrected stream ("pose") against the uncorrected one ("pose_raw").
class CorrectionRatioComponent final : public MetricComponent {
 public:
  std::string_view name() const override { return "correction_ratio"; }
  void Compute(const RecordedRun& run, json& metrics, std::vector<json>&) const override {
    const auto& streams = run.estimates.pose_streams();
    const auto corrected = streams.find("pose");
    const auto uncorrected = streams.find("pose_raw");
    if (corrected == streams.end() || uncorrected == streams.end()) return;
    const double c = FinalPositionError(run.truth.poses(), corrected->second);
    const double u = FinalPositionError(run.truth.poses(), uncorrected->second);
    metrics["correction"] = json{{"uncorrected_over_corrected", c > 0 ? u / c : 0.0},
                                 {"corrected_below_uncorrected", c < u}};
  }
};

class VelocityComponent final : public MetricComponent {
 public:
  std::string_view name() const override { return "velocity"; }
  void Compute(const RecordedRun& run, json& metrics, std::vector<json>&) const override {
    for (const auto& [name, est] : run.estimates.velocity_streams()) {
      metrics[name]["velocity_rmse_m_s"] = VelocityRmse(run.truth.velocities(), est);
      metrics[name]["samples"] = est.size();
    }
  }
};

class TruthComponent final : public MetricComponent {
 public:
  std::string_view name() const override { return "truth"; }
  void Compute(const RecordedRun& run, json& metrics, std::vector<json>& events) const override {
    double slip_time = 0;
    for (const auto& iv : run.slip_intervals) {
      events.push_back(json{
          {"t_s", iv.start_s}, {"event", "slip"}, {"start_s", iv.start_s}, {"end_s", iv.end_s}});
      slip_time += iv.end_s - iv.start_s;
    }
    // The slip block counts the truth intervals; slip_detection, when selected and the firmware
    // flags slips, replaces it with its scores (which count them too).
    if (!run.slip_intervals.empty()) {
      metrics["slip"] = json{{"truth_intervals", run.slip_intervals.size()}};
    }
    metrics["truth"] = json{{"slip_intervals", run.slip_intervals.size()},
                            {"slip_time_s", slip_time},
                            {"distance_m", PathLength(run.truth.poses())},
                            {"rotation_rad", TotalRotation(run.truth.poses())}};
  }
};

// Episodes are merged over regained contact shorter than 10 ms, so a wheel chattering over a
// bump is one episode; the time is the steps off the floor.
class ContactComponent final : public MetricComponent {
 public:
  std::string_view name() const override { return "contact"; }
  void Compute(const RecordedRun& run, json& metrics, std::vector<json>& events) const override {
    json contact = json::object();
    int wheels_losing_contact = 0;
    std::size_t all_episodes = 0;
    const double step_s = run.truth.step_s();
    const auto& airborne = run.truth.airborne();
    for (std::size_t w = 0; w < airborne.size(); ++w) {
      const auto episodes = FlagsToIntervals(run.truth.step_t_s(), airborne[w], step_s, 0.01, 0.0);
      if (episodes.empty()) continue;
      const std::string& wheel = run.wheel_names[w];
      double longest = 0;
      for (const auto& iv : episodes) {
        longest = std::max(longest, iv.end_s - iv.start_s);
        events.push_back(json{{"t_s", iv.start_s},
                              {"event", "contact_lost"},
                              {"wheel", wheel},
                              {"start_s", iv.start_s},
                              {"end_s", iv.end_s}});
      }
      const auto steps = std::count(airborne[w].begin(), airborne[w].end(), true);
      ++wheels_losing_contact;
      all_episodes += episodes.size();
      contact[wheel + "_episodes"] = episodes.size();
      contact[wheel + "_time_s"] = static_cast<double>(steps) * step_s;
      contact[wheel + "_longest_s"] = longest;
    }
    contact["wheels_losing_contact"] = wheels_losing_contact;
    contact["episodes"] = all_episodes;
    metrics["contact"] = contact;
  }
};

// Paper 000: the firmware's per-cycle slip flags against the ground-truth intervals, one block
// per slip stream (a stream named "slip" replaces the truth component's block of that name).
class SlipDetectionComponent final : public MetricComponent {
 public:
  std::string_view name() const override { return "slip_detection"; }
  void Compute(const RecordedRun& run, json& metrics, std::vector<json>&) const override {
    for (const auto& [stream, detections] : run.estimates.detections()) {
      if (detections.empty()) continue;
      const SlipMetrics sm = ComputeSlipMetrics(run.slip_intervals, detections, run.sync_period_s);
      json j{{"precision", sm.precision},
             {"recall", sm.recall},
             {"true_positive", sm.true_positive},
             {"false_positive", sm.false_positive},
             {"false_negative", sm.false_negative},
             {"true_negative", sm.true_negative},
             {"truth_intervals", sm.intervals},
             {"intervals_detected", sm.intervals_detected},
             {"detections", std::count_if(detections.begin(), detections.end(),
                                          [](const DetectionSample& d) { return d.detected; })}};
      if (sm.mean_latency_s) j["mean_latency_s"] = *sm.mean_latency_s;
      if (sm.max_latency_s) j["max_latency_s"] = *sm.max_latency_s;
      metrics[stream] = j;
    }
  }
};

// Paper 000: is the firmware's calibrated residual normal (its band assumes it is)? The block
// of the stream named "slip" is "residual", of another one "<stream>_residual".
class ResidualNormalityComponent final : public MetricComponent {
 public:
  std::string_view name() const override { return "residual_normality"; }
  void Compute(const RecordedRun& run, json& metrics, std::vector<json>&) const override {
    for (const auto& [stream, trace] : run.estimates.residuals()) {
      const auto& residual = trace.residual_rad;
      if (residual.empty()) continue;
      // Paper 000 states no minimum n; below 8 samples the skewness test is not defined.
      const bus::NormalityResult n = bus::SkewnessKurtosisTest(residual, 1.96, 8);
      metrics[stream == "slip" ? std::string("residual") : stream + "_residual"] =
          json{{"samples", n.n},
               {"mean_rad", n.mean},
               {"sigma_rad", n.sigma},
               {"skewness_g1", n.g1},
               {"excess_kurtosis_g2", n.g2},
               {"u1", n.u1},
               {"u2", n.u2},
               {"normality_accepted", n.accepted}};
    }
  }
};

// CANoe-style checks of the firmware's frames of each bound stream, added to the stream's block
// (after the other components, which may have written it).
class FramesComponent final : public MetricComponent {
 public:
  std::string_view name() const override { return "frames"; }
  void Compute(const RecordedRun& run, json& metrics, std::vector<json>&) const override {
    const auto& checks = run.estimates.frame_checks();
    for (const ResolvedStream& s : run.estimates.binding().streams()) {
      const FrameChecks& c = checks.at(s.spec->name);
      if (c.frames == 0) continue;  // not sent in this run: no block (an expectation on it fails)
      json& block = metrics[s.spec->name];
      block["frames"] = c.frames;
      block["dlc_errors"] = c.dlc_errors;
      if (c.intervals > 0) {
        block["cycle_time_min_s"] = c.min_interval_s;
        block["cycle_time_max_s"] = c.max_interval_s;
        block["cycle_time_mean_s"] = c.sum_interval_s / static_cast<double>(c.intervals);
      }
      if (s.expected_cycle_s) {
        block["cycle_time_expected_s"] = *s.expected_cycle_s;
        block["cycle_time_violations"] = c.cycle_violations;
      }
      if (s.counter.signal != nullptr) block["counter_errors"] = c.counter_errors;
      if (s.checksum.signal != nullptr) block["checksum_errors"] = c.checksum_errors;
    }
  }
};

/// A truth pose stands still below these speeds.
constexpr double kStandstillSpeedMs = 0.01;
constexpr double kStandstillYawRads = 0.01;

class ClosedLoopComponent final : public MetricComponent {
 public:
  std::string_view name() const override { return "closed_loop"; }
  void Compute(const RecordedRun& run, json& metrics, std::vector<json>& events) const override {
    const auto& poses = run.truth.poses();
    const auto& vel = run.truth.velocities();
    std::vector<const json*> drive_states, faults;
    for (const json& e : run.run_events) {
      const std::string ev = e.value("event", "");
      if (ev == "drive_state") drive_states.push_back(&e);
      if (ev == "fault_start") faults.push_back(&e);
    }
    if (poses.empty() || (!run.goal && drive_states.empty())) return;
    json block = json::object();
    const PoseSample& end = poses.back();
    block["final_x_m"] = end.x_m;
    block["final_y_m"] = end.y_m;
    block["final_theta_rad"] = end.theta_rad;
    if (run.goal) {
      block["goal_x_m"] = run.goal->x_m;
      block["goal_y_m"] = run.goal->y_m;
      block["goal_error_m"] = std::hypot(end.x_m - run.goal->x_m, end.y_m - run.goal->y_m);
      if (run.goal_has_heading) {
        block["goal_heading_error_rad"] = std::abs(WrapAngle(end.theta_rad - run.goal->theta_rad));
      }
    }
    // Drives by name, from their state events and the faults that name them.
    auto drive_of = [&](const json& f) -> std::string {
      if (f.contains("drive")) return f["drive"].get<std::string>();
      const std::string target = f.value("target", "");
      for (const json* d : drive_states) {
        const std::string name = (*d)["drive"].get<std::string>();
        if (target.rfind(name + " ", 0) == 0 || target == name) return name;
      }
      return "";
    };
    json reactions = json::array();
    for (const json* f : faults) {
      const std::string faulted = drive_of(*f);
      if (faulted.empty()) continue;
      const double t0 = (*f)["t_s"].get<double>();
      json r{{"drive", faulted}, {"fault", f->value("fault", "")}, {"start_s", t0}};
      // Detected: the firmware stops another drive (the faulted one may fail on its own).
      std::optional<double> detected;
      for (const json* d : drive_states) {
        const double t = (*d)["t_s"].get<double>();
        const std::string state = (*d)["state"].get<std::string>();
        if (t < t0 || (*d)["drive"].get<std::string>() == faulted) continue;
        if (state != "operation_enabled" && state != "fault" && state != "fault_reaction_active") {
          detected = t;
          break;
        }
      }
      r["detected"] = detected.has_value();
      if (detected) r["time_to_detect_s"] = *detected - t0;
      // Distance the truth covered after the fault started, and when it stood still for good.
      double distance = 0;
      for (std::size_t i = 1; i < poses.size(); ++i) {
        if (poses[i].t_s <= t0) continue;
        distance += std::hypot(poses[i].x_m - poses[i - 1].x_m, poses[i].y_m - poses[i - 1].y_m);
      }
      r["distance_after_m"] = distance;
      std::optional<double> still;
      for (std::size_t i = vel.size(); i-- > 0;) {
        const bool moving = std::hypot(vel[i].vx_m_s, vel[i].vy_m_s) >= kStandstillSpeedMs ||
                            std::abs(vel[i].omega_rad_s) >= kStandstillYawRads;
        if (moving || vel[i].t_s < t0) break;
        still = vel[i].t_s;
      }
      r["stopped"] = still.has_value();
      if (still) r["time_to_standstill_s"] = *still - t0;
      events.push_back(json{{"t_s", t0},
                            {"event", "drive_fault_reaction"},
                            {"drive", faulted},
                            {"detected", detected.has_value()},
                            {"time_to_detect_s", detected ? *detected - t0 : -1.0},
                            {"distance_after_m", distance}});
      if (reactions.empty()) {  // The first fault's figures, for expectations.
        block["fault_detected"] = detected.has_value();
        if (detected) block["fault_time_to_detect_s"] = *detected - t0;
        block["fault_distance_after_m"] = distance;
        if (still) block["fault_time_to_standstill_s"] = *still - t0;
      }
      reactions.push_back(std::move(r));
    }
    if (!reactions.empty()) block["drive_faults"] = std::move(reactions);
    metrics["closed_loop"] = std::move(block);
  }
};

}  // namespace

const std::vector<std::string>& MetricComponentNames() {
  // The canonical order: the events of "truth" (slip) come before those of "contact" at one
  // instant.
  static const std::vector<std::string> names{
      "pose",           "correction_ratio",   "velocity", "truth",      "contact",
      "slip_detection", "residual_normality", "frames",   "closed_loop"};
  return names;
}

std::unique_ptr<MetricComponent> MakeMetricComponent(std::string_view name) {
  if (name == "pose") return std::make_unique<PoseComponent>();
  if (name == "correction_ratio") return std::make_unique<CorrectionRatioComponent>();
  if (name == "velocity") return std::make_unique<VelocityComponent>();
  if (name == "truth") return std::make_unique<TruthComponent>();
  if (name == "contact") return std::make_unique<ContactComponent>();
  if (name == "slip_detection") return std::make_unique<SlipDetectionComponent>();
  if (name == "residual_normality") return std::make_unique<ResidualNormalityComponent>();
  if (name == "frames") return std::make_unique<FramesComponent>();
  if (name == "closed_loop") return std::make_unique<ClosedLoopComponent>();
  throw std::invalid_argument(fmt::format("unknown metric component '{}' (known: {})", name,
                                          fmt::join(MetricComponentNames(), ", ")));
}

std::vector<std::string> DefaultMetricComponents() {
  return {"pose", "velocity", "truth", "contact", "frames", "closed_loop"};
}

std::vector<Interval> SlipIntervals(const TruthRecorder& truth) {
  return FlagsToIntervals(truth.step_t_s(), truth.slipping(), truth.step_s(), 0.02, 0.0);
}

void ScoreRun(const RecordedRun& run, const std::vector<std::string>& selected, json& metrics,
              std::vector<json>& events) {
  for (const std::string& name : MetricComponentNames()) {
    if (std::find(selected.begin(), selected.end(), name) == selected.end()) {
      continue;
    }
    MakeMetricComponent(name)->Compute(run, metrics, events);
  }
  std::stable_sort(events.begin(), events.end(), [](const json& a, const json& b) {
    return a["t_s"].get<double>() < b["t_s"].get<double>();
  });
}

}  // namespace wheelhil::emulator::scoring
