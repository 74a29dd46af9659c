#include "emulator/scoring/artefacts.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <functional>
#include <limits>
#include <stdexcept>

#include <fmt/format.h>

#include "emulator/scoring/metric_format.h"
#include "emulator/xml_escape.h"

namespace wheelhil::emulator::scoring {

namespace {

std::ofstream Open(const std::string& path) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw std::runtime_error(fmt::format("{}: cannot be written", path));
  return out;
}

void Check(std::ofstream& out, const std::string& path) {
  out.flush();
  if (!out) throw std::runtime_error(fmt::format("{}: write failed", path));
}

}  // namespace

void WriteTruthCsv(const std::string& path, const std::vector<TruthRow>& rows) {
  auto out = Open(path);
  out << "t_s,x_m,y_m,z_m,theta_rad,vx_m_s,vy_m_s,omega_rad_s,slipping_wheels\n";
  for (const auto& r : rows) {
    out << fmt::format("{:.6f},{:.9f},{:.9f},{:.9f},{:.9f},{:.9f},{:.9f},{:.9f},{}\n", r.t_s, r.x_m,
                       r.y_m, r.z_m, r.theta_rad, r.vx_m_s, r.vy_m_s, r.omega_rad_s,
                       r.slipping_wheels);
  }
  Check(out, path);
}

void WriteEstimateCsv(const std::string& path, const std::vector<EstimateRow>& rows) {
  auto out = Open(path);
  out << "t_s,cycle,stream,x_m_or_vx_m_s,y_m_or_vy_m_s,theta_rad_or_omega_rad_s\n";
  for (const auto& r : rows) {
    out << fmt::format("{:.6f},{},{},{:.6f},{:.6f},{:.6f}\n", r.t_s, r.cycle, r.stream, r.a, r.b,
                       r.c);
  }
  Check(out, path);
}

void WriteTum(const std::string& path, const std::vector<PoseSample>& poses) {
  auto out = Open(path);
  for (const auto& p : poses) {
    out << fmt::format("{:.6f} {:.9f} {:.9f} 0 0 0 {:.9f} {:.9f}\n", p.t_s, p.x_m, p.y_m,
                       std::sin(p.theta_rad / 2), std::cos(p.theta_rad / 2));
  }
  Check(out, path);
}

void WriteJsonLines(const std::string& path, const std::vector<nlohmann::json>& events) {
  auto out = Open(path);
  for (const auto& e : events) out << e.dump() << '\n';
  Check(out, path);
}

void WriteText(const std::string& path, const std::string& text) {
  auto out = Open(path);
  out << text;
  Check(out, path);
}

std::string SvgPlot(const std::string& title, const std::string& x_label,
                    const std::string& y_label, const std::vector<Series>& series,
                    const std::vector<Band>& bands, bool equal_axes, int width, int height) {
  double x0 = std::numeric_limits<double>::infinity(), x1 = -x0, y0 = x0, y1 = -x0;
  for (const auto& s : series) {
    for (std::size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
      if (!std::isfinite(s.x[i]) || !std::isfinite(s.y[i])) continue;
      x0 = std::min(x0, s.x[i]);
      x1 = std::max(x1, s.x[i]);
      y0 = std::min(y0, s.y[i]);
      y1 = std::max(y1, s.y[i]);
    }
  }
  if (!std::isfinite(x0)) x0 = 0, x1 = 1, y0 = 0, y1 = 1;
  if (x1 - x0 < 1e-12) x1 = x0 + 1;
  if (y1 - y0 < 1e-12) y0 -= 0.5, y1 += 0.5;
  // Round the ranges out to whole ticks (a 1-2-5 step), so the frame starts and ends on labels.
  const auto widen = [](double& lo, double& hi) {
    const AxisTicks t = NiceTicks(lo, hi);
    lo = std::floor(lo / t.step + 1e-9) * t.step;
    hi = std::ceil(hi / t.step - 1e-9) * t.step;
  };
  widen(x0, x1);
  widen(y0, y1);
  const double ml = 70, mr = 20, mt = 30, mb = 45;
  const double pw = width - ml - mr, ph = height - mt - mb;
  if (equal_axes) {
    const double sx = (x1 - x0) / pw, sy = (y1 - y0) / ph;
    if (sx > sy) {
      const double c = (y0 + y1) / 2, h = sx * ph / 2;
      y0 = c - h, y1 = c + h;
    } else {
      const double c = (x0 + x1) / 2, h = sy * pw / 2;
      x0 = c - h, x1 = c + h;
    }
  }
  auto X = [&](double x) { return ml + (x - x0) / (x1 - x0) * pw; };
  auto Y = [&](double y) { return mt + ph - (y - y0) / (y1 - y0) * ph; };
  std::string svg = fmt::format(
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{}\" height=\"{}\" "
      "font-family=\"sans-serif\" font-size=\"11\">\n<rect width=\"100%\" height=\"100%\" "
      "fill=\"white\"/>\n<text x=\"{}\" y=\"18\" font-size=\"13\" font-weight=\"bold\">{}</text>\n"
      "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"#888\"/>\n",
      width, height, ml, EscapeXml(title), ml, mt, pw, ph);
  svg += fmt::format(
      "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{}</text>\n<text x=\"14\" y=\"{}\" "
      "transform=\"rotate(-90 14 {})\" text-anchor=\"middle\">{}</text>\n",
      ml + pw / 2, height - 8, EscapeXml(x_label), mt + ph / 2, mt + ph / 2, EscapeXml(y_label));
  std::vector<std::pair<std::string, std::string>> band_legend;
  for (const auto& b : bands) {
    const double a = std::max(x0, std::min(b.x0, b.x1)), z = std::min(x1, std::max(b.x0, b.x1));
    if (!(z > a)) continue;
    svg += fmt::format(
        "<rect class=\"band\" x=\"{:.1f}\" y=\"{}\" width=\"{:.1f}\" height=\"{}\" "
        "fill=\"{}\" fill-opacity=\"0.18\"><title>{}: {:.3f}-{:.3f}</title></rect>\n",
        X(a), mt, std::max(0.5, X(z) - X(a)), ph, b.color, EscapeXml(b.label), b.x0, b.x1);
    if (std::find_if(band_legend.begin(), band_legend.end(),
                     [&](const auto& l) { return l.first == b.label; }) == band_legend.end()) {
      band_legend.emplace_back(b.label, b.color);
    }
  }
  const AxisTicks tx = NiceTicks(x0, x1), ty = NiceTicks(y0, y1);
  for (int i = 0; i < tx.count; ++i) {
    const double xv = tx.first + i * tx.step;
    svg += fmt::format(
        "<text x=\"{:.1f}\" y=\"{}\" text-anchor=\"middle\">{:.{}f}</text>\n<line x1=\"{:.1f}\" "
        "y1=\"{}\" x2=\"{:.1f}\" y2=\"{}\" stroke=\"#eee\"/>\n",
        X(xv), mt + ph + 15, std::fabs(xv) < tx.step * 1e-6 ? 0.0 : xv, tx.decimals, X(xv), mt,
        X(xv), mt + ph);
  }
  for (int i = 0; i < ty.count; ++i) {
    const double yv = ty.first + i * ty.step;
    svg += fmt::format(
        "<text x=\"{}\" y=\"{:.1f}\" text-anchor=\"end\">{:.{}f}</text>\n<line x1=\"{}\" "
        "y1=\"{:.1f}\" x2=\"{}\" y2=\"{:.1f}\" stroke=\"#eee\"/>\n",
        ml - 4, Y(yv) + 4, std::fabs(yv) < ty.step * 1e-6 ? 0.0 : yv, ty.decimals, ml, Y(yv),
        ml + pw, Y(yv));
  }
  int legend = 0;
  for (const auto& s : series) {
    std::string pts;
    const std::size_t n = std::min(s.x.size(), s.y.size());
    const std::size_t stride = std::max<std::size_t>(1, n / 4000);
    for (std::size_t i = 0; i < n; i += stride) {
      if (!std::isfinite(s.x[i]) || !std::isfinite(s.y[i])) continue;
      pts += fmt::format("{:.1f},{:.1f} ", X(s.x[i]), Y(s.y[i]));
    }
    svg += fmt::format(
        "<polyline fill=\"none\" stroke=\"{}\" stroke-width=\"1.5\"{} points=\"{}\"/>\n", s.color,
        s.dashed ? " stroke-dasharray=\"5,3\"" : "", pts);
    svg += fmt::format(
        "<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"{}\" stroke-width=\"2\"/><text "
        "x=\"{}\" y=\"{}\">{}</text>\n",
        ml + 8, mt + 12 + 14 * legend, ml + 28, mt + 12 + 14 * legend, s.color, ml + 32,
        mt + 16 + 14 * legend, EscapeXml(s.name));
    ++legend;
  }
  for (const auto& [label, color] : band_legend) {
    svg += fmt::format(
        "<rect x=\"{}\" y=\"{}\" width=\"20\" height=\"8\" fill=\"{}\" fill-opacity=\"0.3\"/>"
        "<text x=\"{}\" y=\"{}\">{}</text>\n",
        ml + 8, mt + 8 + 14 * legend, color, ml + 32, mt + 16 + 14 * legend, EscapeXml(label));
    ++legend;
  }
  svg += "</svg>\n";
  return svg;
}

namespace {

// The replay's player: equal axes, the traces up to the current instant, the robot at its true
// pose. Plain ES2017, no libraries.
constexpr const char* kReplayScript = R"js(
(function () {
  const d = JSON.parse(document.getElementById('replay-data').textContent);
  const cv = document.getElementById('replay'), g = cv.getContext('2d');
  const slider = document.getElementById('replay-t'), label = document.getElementById('replay-label');
  const play = document.getElementById('replay-play'), speed = document.getElementById('replay-speed');
  const T = d.truth, R = d.robot, n = T.t.length;
  const colors = ['#d62728', '#2ca02c', '#9467bd', '#ff7f0e', '#8c564b'];
  let x0 = Infinity, x1 = -Infinity, y0 = Infinity, y1 = -Infinity;
  const grow = (xs, ys) => { for (let i = 0; i < xs.length; ++i) {
    x0 = Math.min(x0, xs[i]); x1 = Math.max(x1, xs[i]); y0 = Math.min(y0, ys[i]); y1 = Math.max(y1, ys[i]); } };
  grow(T.x, T.y);
  for (const k in d.estimates) grow(d.estimates[k].x, d.estimates[k].y);
  const pad = 1.5 * Math.hypot(R.half_length, R.half_width);
  if (!isFinite(x0)) { x0 = y0 = -1; x1 = y1 = 1; }
  x0 -= pad; x1 += pad; y0 -= pad; y1 += pad;
  const s = Math.min((cv.width - 20) / (x1 - x0), (cv.height - 20) / (y1 - y0));
  const ox = (cv.width - s * (x1 - x0)) / 2, oy = (cv.height - s * (y1 - y0)) / 2;
  const X = x => ox + (x - x0) * s, Y = y => cv.height - oy - (y - y0) * s;
  const tEnd = n ? T.t[n - 1] : 0, tStart = n ? T.t[0] : 0;
  let t = tStart, playing = false, last = null;
  slider.min = tStart; slider.max = tEnd; slider.step = (tEnd - tStart) / 1000 || 0.001;
  const upTo = (ts, t) => { let lo = 0, hi = ts.length; while (lo < hi) { const m = (lo + hi) >> 1;
    if (ts[m] <= t) lo = m + 1; else hi = m; } return lo; };
  function trace(xs, ys, k, color, dash) {
    g.strokeStyle = color; g.setLineDash(dash); g.lineWidth = 1.5; g.beginPath();
    for (let i = 0; i < k; ++i) { if (i) g.lineTo(X(xs[i]), Y(ys[i])); else g.moveTo(X(xs[i]), Y(ys[i])); }
    g.stroke(); g.setLineDash([]);
  }
  function draw() {
    g.fillStyle = '#fff'; g.fillRect(0, 0, cv.width, cv.height);
    // a 1 m grid (0.1 m when the run is small)
    const step = (x1 - x0) > 4 ? 1 : 0.1;
    g.strokeStyle = '#eee'; g.lineWidth = 1; g.beginPath();
    for (let gx = Math.ceil(x0 / step) * step; gx <= x1; gx += step) { g.moveTo(X(gx), 0); g.lineTo(X(gx), cv.height); }
    for (let gy = Math.ceil(y0 / step) * step; gy <= y1; gy += step) { g.moveTo(0, Y(gy)); g.lineTo(cv.width, Y(gy)); }
    g.stroke();
    const k = upTo(T.t, t);
    trace(T.x, T.y, k, '#1f77b4', []);
    let c = 0;
    for (const name in d.estimates) { const e = d.estimates[name];
      trace(e.x, e.y, upTo(e.t, t), colors[c++ % colors.length], [5, 3]); }
    if (k > 0) {
      const i = k - 1, th = T.theta[i], slip = T.slip[i];
      g.save(); g.translate(X(T.x[i]), Y(T.y[i])); g.rotate(-th); g.scale(s, s);
      g.lineWidth = 2 / s; g.strokeStyle = '#333'; g.fillStyle = 'rgba(31,119,180,0.15)';
      g.fillRect(-R.half_length, -R.half_width, 2 * R.half_length, 2 * R.half_width);
      g.strokeRect(-R.half_length, -R.half_width, 2 * R.half_length, 2 * R.half_width);
      g.beginPath(); g.moveTo(R.half_length, 0); g.lineTo(R.half_length * 0.6, 0); g.stroke();
      for (const w of R.wheels) {
        const slipping = w.bit >= 0 && (slip >> w.bit) & 1;
        g.fillStyle = slipping ? '#ff7f0e' : '#444';
        g.fillRect(w.x - w.r, -w.y - w.r * 0.35, 2 * w.r, 0.7 * w.r);
      }
      g.restore();
      label.textContent = 't = ' + t.toFixed(2) + ' s' + (slip ? '  (wheel slip)' : '');
    }
  }
  function frame(now) {
    if (!playing) return;
    if (last !== null) t = Math.min(tEnd, t + (now - last) / 1000 * Number(speed.value));
    last = now; slider.value = t; draw();
    if (t >= tEnd) { playing = false; play.textContent = 'play'; return; }
    requestAnimationFrame(frame);
  }
  play.onclick = () => { playing = !playing; play.textContent = playing ? 'pause' : 'play';
    if (playing) { if (t >= tEnd) t = tStart; last = null; requestAnimationFrame(frame); } };
  slider.oninput = () => { t = Number(slider.value); draw(); };
  t = tEnd; slider.value = t; draw();
  document.body.dataset.replayReady = '1';
})();
)js";

}  // namespace

std::string HtmlReport(const nlohmann::json& report, const std::vector<std::string>& svg_plots,
                       const nlohmann::json& replay) {
  std::string h =
      "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>wheelhil run: " +
      EscapeXml(report.value("scenario", std::string())) +
      "</title><style>body{font-family:sans-serif;margin:2em}table{border-collapse:collapse}"
      "td,th{border:1px solid #ccc;padding:2px 8px;text-align:right}table.metrics td:first-child{text-align:left;font-family:monospace}h3{margin:1em 0 .3em}.pass{color:#070}"
      ".fail{color:#b00}</style>"
      "<script>window.onerror=function(m){document.body.dataset.scriptErrors="
      "(document.body.dataset.scriptErrors||'')+m+';';};</script></head><body>\n";
  const std::string verdict = report.value("verdict", std::string());
  h += fmt::format(
      "<h1>{}</h1>\n<p>seed {} &middot; {:.3f} s simulated &middot; verdict <b "
      "class=\"{}\">{}</b></p>\n",
      EscapeXml(report.value("scenario", std::string())), report.value("seed", std::uint64_t{0}),
      report.value("sim_time_s", 0.0), verdict == "pass" ? "pass" : "fail", EscapeXml(verdict));
  if (report.contains("failure")) {
    h += "<p class=\"fail\">" + EscapeXml(report["failure"].get<std::string>()) + "</p>\n";
  }
  h += "<h2>Expectations</h2>\n<table><tr><th>expectation</th><th>value</th><th>result</th></tr>\n";
  for (const auto& e : report.value("expectations", nlohmann::json::array())) {
    const bool ok = e.value("passed", false);
    // The metric is the expectation's first word ("pose.final_position_error_m < 0.25"); its
    // last name part says the unit.
    const std::string text = e.value("text", std::string());
    const std::string metric = text.substr(0, text.find(' '));
    const std::string leaf = metric.substr(metric.rfind('.') + 1);
    h += fmt::format("<tr><td>{}</td><td title=\"{}\">{}</td><td class=\"{}\">{}</td></tr>\n",
                     EscapeXml(text), EscapeXml(e.contains("value") ? e["value"].dump() : ""),
                     EscapeXml(e.contains("value") ? FormatMetricValue(leaf, e["value"]) : "-"),
                     ok ? "pass" : "fail", ok ? "pass" : "FAIL");
  }
  h += "</table>\n<h2>Metrics</h2>\n";
  // Named: items() only refers to the object it is called on, so iterating the items() of the
  // temporary that value() returns would read a destroyed map (crashed `wheelhil run`).
  const nlohmann::json metrics = report.value("metrics", nlohmann::json::object());
  // One table per stream; nested groups (ape, rpe_1m) as dotted names; each value rounded to
  // its meaning with its unit, the exact one in the cell's title (and in report.json).
  for (const auto& [stream, m] : metrics.items()) {
    if (!m.is_object()) continue;
    h += "<h3>" + EscapeXml(stream) + "</h3>\n<table class=\"metrics\">\n";
    const std::function<void(const std::string&, const nlohmann::json&)> rows =
        [&](const std::string& prefix, const nlohmann::json& obj) {
          for (const auto& [k, v] : obj.items()) {
            const std::string name = prefix.empty() ? k : prefix + "." + k;
            if (v.is_object()) {
              rows(name, v);
              continue;
            }
            h += fmt::format("<tr><td>{}</td><td title=\"{}\">{}</td></tr>\n", EscapeXml(name),
                             EscapeXml(v.dump()), EscapeXml(FormatMetricValue(k, v)));
          }
        };
    rows("", m);
    h += "</table>\n";
  }
  if (!replay.is_null()) {
    std::string data = replay.dump();
    // Inside <script>, "</" would end the element: JSON allows "<\/" for it.
    for (std::size_t at = data.find("</"); at != std::string::npos; at = data.find("</", at + 3)) {
      data.replace(at, 2, "<\\/");
    }
    h += "<h2>Replay</h2>\n<p><button id=\"replay-play\">play</button> <select "
         "id=\"replay-speed\"><option value=\"1\">1x</option><option value=\"5\" "
         "selected>5x</option><option value=\"20\">20x</option></select> <input "
         "id=\"replay-t\" type=\"range\" style=\"width:420px\"> <span "
         "id=\"replay-label\"></span></p>\n<canvas id=\"replay\" width=\"720\" height=\"440\" "
         "style=\"border:1px solid #ccc\"></canvas>\n<p>Top down, equal axes: truth (blue), the "
         "estimates (dashed), the robot at its true pose, a wheel orange while it slips.</p>\n"
         "<script type=\"application/json\" id=\"replay-data\">" +
         data + "</script>\n<script>" + kReplayScript + "</script>\n";
  }
  h += "<h2>Plots</h2>\n";
  for (const auto& s : svg_plots) h += "<div>" + s + "</div>\n";
  h += "</body></html>\n";
  return h;
}

}  // namespace wheelhil::emulator::scoring
