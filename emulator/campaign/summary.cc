#include "emulator/campaign/summary.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <map>
#include <optional>
#include <set>
#include <stdexcept>

#include "emulator/scoring/metric_format.h"
#include "emulator/xml_escape.h"

namespace wheelhil::emulator::campaign {
namespace {

using nlohmann::json;

std::optional<double> MetricOf(const RunRecord& r, const std::string& name) {
  const auto it = r.metrics.find(name);
  if (it == r.metrics.end()) return std::nullopt;
  return it->second;
}

std::optional<double> NumericParam(const RunRecord& r, const std::string& path) {
  const auto it = r.params.find(path);
  if (it == r.params.end()) return std::nullopt;
  if (it->is_number()) return it->get<double>();
  if (it->is_boolean()) return it->get<bool>() ? 1.0 : 0.0;
  return std::nullopt;
}

std::string ParamText(const json& v) {
  if (v.is_number_float()) return fmt::format("{:.6g}", v.get<double>());
  if (v.is_string()) return v.get<std::string>();
  return v.dump();
}

std::string ParamsText(const RunRecord& r) {
  std::string out;
  for (const auto& [k, v] : r.params.items()) {
    if (!out.empty()) out += " ";
    out += k + "=" + ParamText(v);
  }
  return out;
}

// Groups of runs per parameter: exact values when few, else equal-count bins.
struct Group {
  std::string label;
  std::vector<std::size_t> runs;
  double x = 0;  // numeric centre (for ordering)
};

std::vector<Group> GroupBy(const std::vector<RunRecord>& runs, const std::string& path) {
  std::map<std::string, Group> exact;
  std::vector<std::pair<double, std::size_t>> numeric;
  bool all_numeric = true;
  for (std::size_t i = 0; i < runs.size(); ++i) {
    const auto it = runs[i].params.find(path);
    const std::string label = it == runs[i].params.end() ? "?" : ParamText(*it);
    auto& g = exact[label];
    g.label = label;
    g.runs.push_back(i);
    const auto num = NumericParam(runs[i], path);
    if (num) {
      g.x = *num;
      numeric.emplace_back(*num, i);
    } else {
      all_numeric = false;
    }
  }
  std::vector<Group> out;
  if (exact.size() <= 12 || !all_numeric) {
    for (auto& [_, g] : exact) out.push_back(std::move(g));
    if (all_numeric) {
      std::sort(out.begin(), out.end(), [](const Group& a, const Group& b) { return a.x < b.x; });
    }
    return out;
  }
  std::sort(numeric.begin(), numeric.end());
  constexpr std::size_t kBins = 6;
  for (std::size_t b = 0; b < kBins; ++b) {
    const std::size_t lo = numeric.size() * b / kBins, hi = numeric.size() * (b + 1) / kBins;
    if (lo == hi) continue;
    Group g;
    g.label = fmt::format("[{:.4g}, {:.4g}]", numeric[lo].first, numeric[hi - 1].first);
    g.x = numeric[lo].first;
    for (std::size_t i = lo; i < hi; ++i) g.runs.push_back(numeric[i].second);
    out.push_back(std::move(g));
  }
  return out;
}

struct Stats {
  std::size_t n = 0, passed = 0, with_metric = 0;
  double mean = 0, max = -std::numeric_limits<double>::infinity();
};

Stats StatsOf(const std::vector<RunRecord>& runs, const std::vector<std::size_t>& idx,
              const std::string& metric) {
  Stats s;
  double sum = 0;
  for (auto i : idx) {
    ++s.n;
    if (runs[i].passed) ++s.passed;
    if (const auto v = MetricOf(runs[i], metric)) {
      ++s.with_metric;
      sum += *v;
      s.max = std::max(s.max, *v);
    }
  }
  if (s.with_metric) s.mean = sum / s.with_metric;
  return s;
}

std::string Num(double v) { return std::isfinite(v) ? fmt::format("{:.4g}", v) : "-"; }

// A metric's value for the page: rounded with the unit its name says (scoring/metric_format.h).
std::string Shown(const std::string& metric, double v) {
  if (!std::isfinite(v)) return "-";
  return scoring::FormatMetricValue(metric.substr(metric.rfind('.') + 1), v);
}

// Scatter plot: parameter (x) against metric (y); passed runs green dots, failed red crosses,
// metric bounds of the criteria as dashed lines.
std::string SvgPlot(const CampaignSpec& spec, const std::vector<RunRecord>& runs,
                    const std::string& path, const std::string& metric) {
  constexpr double W = 440, H = 260, L = 60, R = 12, T = 14, B = 40;
  std::vector<std::string> categories;
  std::vector<std::tuple<double, double, bool>> pts;
  for (const auto& r : runs) {
    const auto y = MetricOf(r, metric);
    if (!y) continue;
    std::optional<double> x = NumericParam(r, path);
    if (!x) {
      const auto it = r.params.find(path);
      const std::string label = it == r.params.end() ? "?" : ParamText(*it);
      auto c = std::find(categories.begin(), categories.end(), label);
      if (c == categories.end()) c = categories.insert(categories.end(), label);
      x = static_cast<double>(c - categories.begin());
    }
    pts.emplace_back(*x, *y, r.passed);
  }
  if (pts.empty()) return "<p>(no runs with this metric)</p>";
  double x0 = INFINITY, x1 = -INFINITY, y0 = INFINITY, y1 = -INFINITY;
  for (const auto& [x, y, _] : pts) {
    x0 = std::min(x0, x), x1 = std::max(x1, x), y0 = std::min(y0, y), y1 = std::max(y1, y);
  }
  std::vector<double> bounds;
  for (const auto& c : spec.run_criteria) {
    if (c.metric != metric) continue;
    if (c.max) bounds.push_back(*c.max);
    if (c.min) bounds.push_back(*c.min);
  }
  for (const auto& c : spec.campaign_criteria) {
    if (!c.bound || c.bound->metric != metric) continue;
    if (c.bound->max) bounds.push_back(*c.bound->max);
    if (c.bound->min) bounds.push_back(*c.bound->min);
  }
  for (double b : bounds) y0 = std::min(y0, b), y1 = std::max(y1, b);
  if (x1 == x0) x0 -= 0.5, x1 += 0.5;
  if (y1 == y0) y0 -= 0.5, y1 += 0.5;
  // Round ticks (1-2-5 steps), the y range widened to whole ticks.
  const scoring::AxisTicks yt0 = scoring::NiceTicks(y0, y1);
  y0 = std::floor(y0 / yt0.step + 1e-9) * yt0.step;
  y1 = std::ceil(y1 / yt0.step - 1e-9) * yt0.step;
  if (categories.empty()) {
    const scoring::AxisTicks xt0 = scoring::NiceTicks(x0, x1);
    x0 = std::floor(x0 / xt0.step + 1e-9) * xt0.step;
    x1 = std::ceil(x1 / xt0.step - 1e-9) * xt0.step;
  } else {
    x0 -= 0.5, x1 += 0.5;  // categories sit between the frame's edges
  }
  auto sx = [&](double x) { return L + (x - x0) / (x1 - x0) * (W - L - R); };
  auto sy = [&](double y) { return H - B - (y - y0) / (y1 - y0) * (H - T - B); };
  std::string svg = fmt::format(
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{}\" height=\"{}\" "
      "viewBox=\"0 0 {} {}\" font-family=\"sans-serif\" font-size=\"11\">\n"
      "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"#fafafa\" stroke=\"#999\"/>\n",
      W, H, W, H, L, T, W - L - R, H - T - B);
  const scoring::AxisTicks yt = scoring::NiceTicks(y0, y1);
  for (int i = 0; i < yt.count; ++i) {
    const double yv = yt.first + i * yt.step;
    svg += fmt::format("<text x=\"{:.1f}\" y=\"{:.1f}\" text-anchor=\"end\">{:.{}f}</text>\n",
                       L - 4, sy(yv) + 4, std::fabs(yv) < yt.step * 1e-6 ? 0.0 : yv, yt.decimals);
  }
  if (categories.empty()) {
    const scoring::AxisTicks xt = scoring::NiceTicks(x0, x1);
    for (int i = 0; i < xt.count; ++i) {
      const double xv = xt.first + i * xt.step;
      svg += fmt::format("<text x=\"{:.1f}\" y=\"{:.1f}\" text-anchor=\"middle\">{:.{}f}</text>\n",
                         sx(xv), H - B + 14, std::fabs(xv) < xt.step * 1e-6 ? 0.0 : xv,
                         xt.decimals);
    }
  }
  for (std::size_t c = 0; c < categories.size(); ++c) {
    svg += fmt::format("<text x=\"{:.1f}\" y=\"{:.1f}\" text-anchor=\"middle\">{}</text>\n",
                       sx(static_cast<double>(c)), H - B + 14, EscapeXml(categories[c]));
  }
  svg += fmt::format("<text x=\"{:.1f}\" y=\"{:.1f}\" text-anchor=\"middle\">{}</text>\n",
                     L + (W - L - R) / 2, H - 6, EscapeXml(path));
  svg += fmt::format(
      "<text x=\"12\" y=\"{:.1f}\" transform=\"rotate(-90 12 {:.1f})\" "
      "text-anchor=\"middle\">{}</text>\n",
      T + (H - T - B) / 2, T + (H - T - B) / 2, EscapeXml(metric));
  const std::string leaf = metric.substr(metric.rfind('.') + 1);
  for (double b : bounds) {
    svg += fmt::format(
        "<line class=\"threshold\" x1=\"{}\" x2=\"{}\" y1=\"{:.1f}\" y2=\"{:.1f}\" "
        "stroke=\"#c60\" stroke-dasharray=\"5,4\"/>\n<text x=\"{}\" y=\"{:.1f}\" "
        "text-anchor=\"end\" fill=\"#c60\">pass limit {}</text>\n",
        L, W - R, sy(b), sy(b), W - R - 2, sy(b) - 3,
        EscapeXml(scoring::FormatMetricValue(leaf, b)));
  }
  for (const auto& [x, y, ok] : pts) {
    if (ok) {
      svg += fmt::format(
          "<circle cx=\"{:.1f}\" cy=\"{:.1f}\" r=\"3\" fill=\"#2a2\" fill-opacity=\"0.7\"/>\n",
          sx(x), sy(y));
    } else {
      const double cx = sx(x), cy = sy(y);
      svg += fmt::format(
          "<path d=\"M{:.1f} {:.1f}L{:.1f} {:.1f}M{:.1f} {:.1f}L{:.1f} {:.1f}\" stroke=\"#d22\" "
          "stroke-width=\"1.5\"/>\n",
          cx - 3, cy - 3, cx + 3, cy + 3, cx - 3, cy + 3, cx + 3, cy - 3);
    }
  }
  svg += "</svg>\n";
  return svg;
}

}  // namespace

CampaignSummary Summarize(const CampaignSpec& spec, const std::vector<RunRecord>& runs,
                          std::size_t expected) {
  CampaignSummary s;
  s.expected = expected;
  s.stored = runs.size();
  for (const auto& r : runs) s.passed += r.passed ? 1 : 0;
  s.pass_rate = runs.empty() ? 0 : static_cast<double>(s.passed) / runs.size();
  s.complete = s.stored == s.expected;
  bool all_hold = true;
  for (const auto& c : spec.campaign_criteria) {
    CriterionResult cr;
    cr.description = c.Describe();
    cr.required = c.fraction;
    std::size_t ok = 0;
    for (const auto& r : runs)
      ok += (c.bound ? c.bound->Holds(MetricOf(r, c.bound->metric)) : r.passed);
    cr.achieved = runs.empty() ? 0 : static_cast<double>(ok) / runs.size();
    cr.holds = !runs.empty() && cr.achieved + 1e-12 >= cr.required;
    all_hold = all_hold && cr.holds;
    s.criteria.push_back(cr);
  }
  s.campaign_passed = s.complete && all_hold;

  // Key metrics: criteria metrics, the rank metric, else the first few stored metrics.
  std::set<std::string> seen;
  auto add = [&](const std::string& m) {
    if (!m.empty() && seen.insert(m).second) s.key_metrics.push_back(m);
  };
  add(spec.rank_metric);
  for (const auto& c : spec.run_criteria) add(c.metric);
  for (const auto& c : spec.campaign_criteria) {
    if (c.bound) add(c.bound->metric);
  }
  if (s.key_metrics.empty()) {
    std::set<std::string> all;
    for (const auto& r : runs) {
      for (const auto& [k, _] : r.metrics) all.insert(k);
    }
    for (const auto& m : all) {
      if (s.key_metrics.size() >= 3) break;
      add(m);
    }
  }

  // Worst runs: failed before passed, then by the rank metric (largest first), then by index.
  std::vector<std::size_t> order(runs.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  const std::string rank = spec.rank_metric;
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    if (runs[a].passed != runs[b].passed) return !runs[a].passed;
    const double va = MetricOf(runs[a], rank).value_or(-INFINITY);
    const double vb = MetricOf(runs[b], rank).value_or(-INFINITY);
    if (va != vb) return va > vb;
    return runs[a].index < runs[b].index;
  });
  order.resize(std::min<std::size_t>(order.size(), 10));
  s.worst = order;
  return s;
}

std::string FormatSummary(const CampaignSpec& spec, const CampaignSummary& s,
                          const std::vector<RunRecord>& runs) {
  std::string out = fmt::format("campaign {}: {}/{} runs stored, {} passed, pass rate {:.1f} %\n",
                                spec.name, s.stored, s.expected, s.passed, s.pass_rate * 100);
  for (const auto& c : s.criteria) {
    out += fmt::format("  criterion {}: {:.1f} % -> {}\n", c.description, c.achieved * 100,
                       c.holds ? "holds" : "FAILS");
  }
  if (!s.complete) out += "  (incomplete: criteria judge only the stored runs)\n";
  out += fmt::format("  campaign verdict: {}\n",
                     !s.complete ? "incomplete" : (s.campaign_passed ? "pass" : "FAIL"));
  if (!s.worst.empty()) {
    out += fmt::format("worst runs{}:\n",
                       spec.rank_metric.empty() ? "" : " (by " + spec.rank_metric + ")");
    for (const auto i : s.worst) {
      const auto& r = runs[i];
      out += fmt::format(
          "  {} seed {} {} {}{}{}\n", r.key, r.seed, r.passed ? "pass" : "FAIL", ParamsText(r),
          spec.rank_metric.empty()
              ? ""
              : " " + spec.rank_metric + "=" + Num(MetricOf(r, spec.rank_metric).value_or(NAN)),
          r.passed ? "" : "  [" + r.failure.substr(0, 160) + "]");
    }
  }
  for (const auto& p : spec.parameters) {
    const auto groups = GroupBy(runs, p.path);
    out += fmt::format("\n{}:\n  {:<22} {:>5} {:>7}", p.path, "value", "runs", "pass%");
    for (const auto& m : s.key_metrics) out += fmt::format("  {:>24}", m + " mean/max");
    out += "\n";
    for (const auto& g : groups) {
      const Stats any = StatsOf(runs, g.runs, s.key_metrics.empty() ? "" : s.key_metrics[0]);
      out += fmt::format("  {:<22} {:>5} {:>7.1f}", g.label, any.n,
                         any.n ? 100.0 * any.passed / any.n : 0.0);
      for (const auto& m : s.key_metrics) {
        const Stats st = StatsOf(runs, g.runs, m);
        out += fmt::format("  {:>24}", Num(st.with_metric ? st.mean : NAN) + " / " +
                                           Num(st.with_metric ? st.max : NAN));
      }
      out += "\n";
    }
  }
  return out;
}

void WriteCampaignHtml(const std::filesystem::path& file, const CampaignSpec& spec,
                       const CampaignSummary& s, const std::vector<RunRecord>& runs) {
  std::string h = fmt::format(
      "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>campaign {0}</title>\n"
      "<style>body{{font-family:sans-serif;margin:1.5em}}table{{border-collapse:collapse}}"
      "td,th{{border:1px solid #ccc;padding:2px 6px;text-align:right}}"
      "td.l,th.l{{text-align:left}}.fail{{color:#c00}}.pass{{color:#080}}"
      "figure{{display:inline-block;margin:0.5em}}</style></head><body>\n"
      "<h1>Campaign {0}</h1>\n<p>Base scenario <code>{1}</code>; {2} of {3} runs stored; "
      "{4} passed; pass rate <b>{5:.1f} %</b>; verdict <b class=\"{6}\">{7}</b>.</p>\n",
      EscapeXml(spec.name), EscapeXml(spec.base_scenario.string()), s.stored, s.expected, s.passed,
      s.pass_rate * 100, s.campaign_passed ? "pass" : "fail",
      !s.complete ? "incomplete" : (s.campaign_passed ? "pass" : "FAIL"));
  if (!s.criteria.empty()) {
    h += "<h2>Campaign criteria</h2><table><tr><th class=\"l\">criterion</th><th>achieved</th>"
         "<th>result</th></tr>\n";
    for (const auto& c : s.criteria) {
      h +=
          fmt::format("<tr><td class=\"l\">{}</td><td>{:.1f} %</td><td class=\"{}\">{}</td></tr>\n",
                      EscapeXml(c.description), c.achieved * 100, c.holds ? "pass" : "fail",
                      c.holds ? "holds" : "fails");
    }
    h += "</table>\n";
  }
  h += "<h2>Worst runs</h2><table><tr><th class=\"l\">run</th><th>seed</th><th>result</th>"
       "<th class=\"l\">parameters</th>";
  for (const auto& m : s.key_metrics) h += fmt::format("<th>{}</th>", EscapeXml(m));
  h += "<th class=\"l\">failure</th></tr>\n";
  for (const auto i : s.worst) {
    const auto& r = runs[i];
    h += fmt::format(
        "<tr><td class=\"l\"><a href=\"{}\">{}</a></td><td>{}</td>"
        "<td class=\"{}\">{}</td><td class=\"l\">{}</td>",
        EscapeXml(r.run_dir), EscapeXml(r.key), r.seed, r.passed ? "pass" : "fail",
        r.passed ? "pass" : "FAIL", EscapeXml(ParamsText(r)));
    for (const auto& m : s.key_metrics)
      h += fmt::format("<td>{}</td>", EscapeXml(Shown(m, MetricOf(r, m).value_or(NAN))));
    h += fmt::format("<td class=\"l\">{}</td></tr>\n", EscapeXml(r.failure));
  }
  h += "</table>\n";
  for (const auto& p : spec.parameters) {
    h += fmt::format(
        "<h2>{}</h2>\n<table><tr><th class=\"l\">value</th><th>runs</th>"
        "<th>pass %</th>",
        EscapeXml(p.path));
    for (const auto& m : s.key_metrics) {
      h += fmt::format("<th>{} mean</th><th>{} max</th>", EscapeXml(m), EscapeXml(m));
    }
    h += "</tr>\n";
    for (const auto& g : GroupBy(runs, p.path)) {
      const Stats any = StatsOf(runs, g.runs, "");
      h += fmt::format("<tr><td class=\"l\">{}</td><td>{}</td><td>{:.1f}</td>", EscapeXml(g.label),
                       any.n, any.n ? 100.0 * any.passed / any.n : 0.0);
      for (const auto& m : s.key_metrics) {
        const Stats st = StatsOf(runs, g.runs, m);
        h += fmt::format("<td>{}</td><td>{}</td>",
                         EscapeXml(Shown(m, st.with_metric ? st.mean : NAN)),
                         EscapeXml(Shown(m, st.with_metric ? st.max : NAN)));
      }
      h += "</tr>\n";
    }
    h += "</table>\n";
    for (const auto& m : s.key_metrics) {
      h += "<figure>" + SvgPlot(spec, runs, p.path, m) + "</figure>\n";
    }
  }
  h += "</body></html>\n";
  if (file.has_parent_path()) std::filesystem::create_directories(file.parent_path());
  const auto tmp = file.string() + ".tmp";
  {
    std::ofstream out(tmp, std::ios::trunc);
    out << h;
    if (!out) throw std::runtime_error(fmt::format("cannot write {}", tmp));
  }
  std::filesystem::rename(tmp, file);
}

JUnitSuite CampaignJUnitSuite(const CampaignSpec& spec, const CampaignSummary& s,
                              const std::vector<RunRecord>& runs) {
  JUnitSuite suite;
  suite.name = "campaign." + spec.name;
  for (const auto& r : runs) {
    JUnitCase c;
    c.classname = suite.name;
    c.name = r.key + " " + ParamsText(r) + " seed=" + std::to_string(r.seed);
    c.time_s = r.wall_s;
    if (r.verdict == "error" || r.verdict == "timeout") {
      c.error = r.failure.empty() ? r.verdict : r.failure;
    } else if (!r.passed) {
      c.failure = r.failure.empty() ? "verdict " + r.verdict : r.failure;
    }
    c.system_out = "run dir: " + r.run_dir;
    suite.cases.push_back(std::move(c));
  }
  for (const auto& cr : s.criteria) {
    JUnitCase c;
    c.classname = suite.name + ".criteria";
    c.name = cr.description;
    if (!cr.holds) {
      c.failure = fmt::format("campaign criterion {} fails: {:.2f} % of {} runs (need {:.2f} %)",
                              cr.description, cr.achieved * 100, s.stored, cr.required * 100);
    }
    suite.cases.push_back(std::move(c));
  }
  if (!s.complete) {
    JUnitCase c;
    c.classname = suite.name + ".criteria";
    c.name = "complete";
    c.failure = fmt::format("only {} of {} runs stored", s.stored, s.expected);
    suite.cases.push_back(std::move(c));
  }
  return suite;
}

}  // namespace wheelhil::emulator::campaign
