#include "emulator/scoring/metrics.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace wheelhil::emulator::scoring {

double WrapAngle(double a_rad) {
  const double two_pi = 2.0 * std::numbers::pi;
  double a = std::fmod(a_rad + std::numbers::pi, two_pi);
  if (a <= 0) a += two_pi;
  return a - std::numbers::pi;
}

PoseSample InterpolatePose(const std::vector<PoseSample>& truth, double t_s) {
  if (t_s <= truth.front().t_s) return truth.front();
  if (t_s >= truth.back().t_s) return truth.back();
  const auto it = std::lower_bound(truth.begin(), truth.end(), t_s,
                                   [](const PoseSample& p, double t) { return p.t_s < t; });
  const PoseSample& b = *it;
  const PoseSample& a = *(it - 1);
  const double span = b.t_s - a.t_s;
  const double w = span > 0 ? (t_s - a.t_s) / span : 0.0;
  PoseSample p;
  p.t_s = t_s;
  p.x_m = a.x_m + w * (b.x_m - a.x_m);
  p.y_m = a.y_m + w * (b.y_m - a.y_m);
  p.theta_rad = a.theta_rad + w * WrapAngle(b.theta_rad - a.theta_rad);
  return p;
}

ErrorStats ComputeErrorStats(std::vector<double> e) {
  ErrorStats s;
  s.n = e.size();
  if (e.empty()) return s;
  double sum = 0, sq = 0;
  for (double v : e) sum += v, sq += v * v;
  const double n = static_cast<double>(e.size());
  s.mean = sum / n;
  s.rmse = std::sqrt(sq / n);
  double var = 0;
  for (double v : e) var += (v - s.mean) * (v - s.mean);
  s.std = std::sqrt(var / n);  // numpy's std, as evo uses it
  std::sort(e.begin(), e.end());
  s.min = e.front();
  s.max = e.back();
  const std::size_t mid = e.size() / 2;
  s.median = e.size() % 2 == 1 ? e[mid] : 0.5 * (e[mid - 1] + e[mid]);
  return s;
}

std::vector<std::pair<PoseSample, PoseSample>> AssociateNearest(
    const std::vector<PoseSample>& truth, const std::vector<PoseSample>& estimate,
    double max_diff_s) {
  std::vector<std::pair<PoseSample, PoseSample>> out;
  if (truth.empty()) return out;
  for (const PoseSample& e : estimate) {
    const auto it = std::lower_bound(truth.begin(), truth.end(), e.t_s,
                                     [](const PoseSample& p, double t) { return p.t_s < t; });
    const PoseSample* best = nullptr;
    if (it != truth.end()) best = &*it;
    if (it != truth.begin() && (best == nullptr || e.t_s - (it - 1)->t_s < best->t_s - e.t_s)) {
      best = &*(it - 1);
    }
    if (best != nullptr && std::abs(best->t_s - e.t_s) <= max_diff_s) out.emplace_back(*best, e);
  }
  return out;
}

ErrorStats AbsolutePositionError(const std::vector<std::pair<PoseSample, PoseSample>>& pairs) {
  std::vector<double> e;
  e.reserve(pairs.size());
  for (const auto& [t, est] : pairs) e.push_back(std::hypot(est.x_m - t.x_m, est.y_m - t.y_m));
  return ComputeErrorStats(std::move(e));
}

namespace {
// b expressed in a's frame (planar): a^-1 b.
PoseSample Relative(const PoseSample& a, const PoseSample& b) {
  const double c = std::cos(a.theta_rad), s = std::sin(a.theta_rad);
  const double dx = b.x_m - a.x_m, dy = b.y_m - a.y_m;
  return PoseSample{0, c * dx + s * dy, -s * dx + c * dy, WrapAngle(b.theta_rad - a.theta_rad)};
}
}  // namespace

RelativePoseError ComputeRelativePoseError(
    const std::vector<std::pair<PoseSample, PoseSample>>& pairs, double delta_m) {
  std::vector<std::size_t> ids;
  if (!pairs.empty()) ids.push_back(0);
  double path = 0;
  for (std::size_t i = 1; i < pairs.size(); ++i) {
    path += std::hypot(pairs[i].first.x_m - pairs[i - 1].first.x_m,
                       pairs[i].first.y_m - pairs[i - 1].first.y_m);
    if (path >= delta_m) {
      path = 0;
      ids.push_back(i);
    }
  }
  std::vector<double> trans, rot;
  for (std::size_t k = 1; k < ids.size(); ++k) {
    const auto& [ti, ei] = pairs[ids[k - 1]];
    const auto& [tj, ej] = pairs[ids[k]];
    const PoseSample dt = Relative(ti, tj), de = Relative(ei, ej);
    const PoseSample err = Relative(dt, de);
    trans.push_back(std::hypot(err.x_m, err.y_m));
    rot.push_back(std::abs(err.theta_rad));
  }
  return RelativePoseError{ComputeErrorStats(std::move(trans)), ComputeErrorStats(std::move(rot))};
}

double PathLength(const std::vector<PoseSample>& truth) {
  double d = 0;
  for (std::size_t i = 1; i < truth.size(); ++i) {
    d += std::hypot(truth[i].x_m - truth[i - 1].x_m, truth[i].y_m - truth[i - 1].y_m);
  }
  return d;
}

double TotalRotation(const std::vector<PoseSample>& truth) {
  double r = 0;
  for (std::size_t i = 1; i < truth.size(); ++i) {
    r += std::abs(WrapAngle(truth[i].theta_rad - truth[i - 1].theta_rad));
  }
  return r;
}

double FinalPositionError(const std::vector<PoseSample>& truth,
                          const std::vector<PoseSample>& estimate) {
  if (truth.empty() || estimate.empty()) return 0;
  const PoseSample& e = estimate.back();
  const PoseSample t = InterpolatePose(truth, e.t_s);
  return std::hypot(e.x_m - t.x_m, e.y_m - t.y_m);
}

PoseMetrics ComputePoseMetrics(const std::vector<PoseSample>& truth,
                               const std::vector<PoseSample>& estimate) {
  PoseMetrics m;
  m.distance_m = PathLength(truth);
  m.rotation_rad = TotalRotation(truth);
  if (truth.empty() || estimate.empty()) return m;
  double sum_sq = 0;
  for (const auto& e : estimate) {
    const PoseSample t = InterpolatePose(truth, e.t_s);
    sum_sq += (e.x_m - t.x_m) * (e.x_m - t.x_m) + (e.y_m - t.y_m) * (e.y_m - t.y_m);
  }
  m.samples = estimate.size();
  m.ape_rmse_m = std::sqrt(sum_sq / static_cast<double>(estimate.size()));
  const PoseSample& e = estimate.back();
  const PoseSample t = InterpolatePose(truth, e.t_s);
  m.final_position_error_m = FinalPositionError(truth, estimate);
  m.final_heading_error_rad = std::abs(WrapAngle(e.theta_rad - t.theta_rad));
  return m;
}

double VelocityRmse(const std::vector<VelocitySample>& truth,
                    const std::vector<VelocitySample>& estimate) {
  if (truth.empty() || estimate.empty()) return 0;
  double sum_sq = 0;
  for (const auto& e : estimate) {
    VelocitySample t = truth.front();
    if (e.t_s >= truth.back().t_s) {
      t = truth.back();
    } else if (e.t_s > truth.front().t_s) {
      const auto it = std::lower_bound(truth.begin(), truth.end(), e.t_s,
                                       [](const VelocitySample& v, double x) { return v.t_s < x; });
      const auto& b = *it;
      const auto& a = *(it - 1);
      const double span = b.t_s - a.t_s;
      const double w = span > 0 ? (e.t_s - a.t_s) / span : 0.0;
      t.vx_m_s = a.vx_m_s + w * (b.vx_m_s - a.vx_m_s);
      t.vy_m_s = a.vy_m_s + w * (b.vy_m_s - a.vy_m_s);
    }
    sum_sq += (e.vx_m_s - t.vx_m_s) * (e.vx_m_s - t.vx_m_s) +
              (e.vy_m_s - t.vy_m_s) * (e.vy_m_s - t.vy_m_s);
  }
  return std::sqrt(sum_sq / static_cast<double>(estimate.size()));
}

std::vector<Interval> FlagsToIntervals(const std::vector<double>& t_s,
                                       const std::vector<bool>& flags, double step_s,
                                       double merge_gap_s, double min_length_s) {
  std::vector<Interval> raw;
  for (std::size_t i = 0; i < flags.size() && i < t_s.size(); ++i) {
    if (!flags[i]) continue;
    if (!raw.empty() && t_s[i] - raw.back().end_s <= merge_gap_s + 1e-12) {
      raw.back().end_s = t_s[i] + step_s;
    } else {
      raw.push_back({t_s[i], t_s[i] + step_s});
    }
  }
  std::vector<Interval> out;
  for (const auto& iv : raw) {
    if (iv.end_s - iv.start_s >= min_length_s - 1e-12) out.push_back(iv);
  }
  return out;
}

SlipMetrics ComputeSlipMetrics(const std::vector<Interval>& truth,
                               const std::vector<DetectionSample>& detections, double period_s,
                               double min_overlap_s) {
  SlipMetrics m;
  m.intervals = truth.size();
  auto overlap = [&](double a, double b) {
    double best = 0;
    for (const auto& iv : truth) {
      best = std::max(best, std::min(b, iv.end_s) - std::max(a, iv.start_s));
    }
    return best;
  };
  for (const auto& d : detections) {
    const double o = overlap(d.t_s - period_s, d.t_s);
    const bool positive = !truth.empty() && o > 0 && o >= min_overlap_s;
    if (d.detected && positive) ++m.true_positive;
    if (d.detected && !positive) ++m.false_positive;
    if (!d.detected && positive) ++m.false_negative;
    if (!d.detected && !positive) ++m.true_negative;
  }
  const double tp = static_cast<double>(m.true_positive);
  m.precision = (m.true_positive + m.false_positive) == 0
                    ? 1.0
                    : tp / static_cast<double>(m.true_positive + m.false_positive);
  m.recall = (m.true_positive + m.false_negative) == 0
                 ? 1.0
                 : tp / static_cast<double>(m.true_positive + m.false_negative);
  double sum = 0, worst = 0;
  for (const auto& iv : truth) {
    for (const auto& d : detections) {
      if (!d.detected) continue;
      if (d.t_s <= iv.start_s) continue;  // The cycle ended before the slip began.
      if (d.t_s > iv.end_s + period_s) break;
      const double lat = d.t_s - iv.start_s;
      sum += lat;
      worst = std::max(worst, lat);
      ++m.intervals_detected;
      break;
    }
  }
  if (m.intervals_detected > 0) {
    m.mean_latency_s = sum / static_cast<double>(m.intervals_detected);
    m.max_latency_s = worst;
  }
  return m;
}

}  // namespace wheelhil::emulator::scoring
