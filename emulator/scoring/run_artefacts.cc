#include "emulator/scoring/run_artefacts.h"

#include <cmath>
#include <fstream>
#include <map>

#include <fmt/format.h>

#include "bus/candump_log.h"
#include "emulator/devices/can_bus_model.h"
#include "emulator/scoring/artefacts.h"
#include "emulator/scoring/metrics.h"

namespace wheelhil::emulator::scoring {

namespace {

// Rounded for the page (0.1 mm, 0.1 mrad, 1 ms): a replay needs no more, and the page stays small.
double R4(double v) { return std::isfinite(v) ? std::round(v * 1e4) / 1e4 : 0.0; }

// The replay's data: truth at <= 1500 instants, each pose stream at <= 1500, the robot.
nlohmann::json ReplayData(const TruthRecorder& truth, const EstimateDecoder& estimates,
                          const ReplayRobot& robot) {
  using nlohmann::json;
  json d;
  const auto& rows = truth.rows();
  const std::size_t stride = std::max<std::size_t>(1, rows.size() / 1500);
  json t = json::array(), x = json::array(), y = json::array(), th = json::array(),
       slip = json::array();
  for (std::size_t i = 0; i < rows.size(); i += stride) {
    int mask = 0;  // a slip anywhere inside the stride shows
    for (std::size_t k = i; k < std::min(rows.size(), i + stride); ++k) {
      mask |= rows[k].slipping_wheels;
    }
    t.push_back(R4(rows[i].t_s));
    x.push_back(R4(rows[i].x_m));
    y.push_back(R4(rows[i].y_m));
    th.push_back(R4(rows[i].theta_rad));
    slip.push_back(mask);
  }
  d["truth"] = {{"t", t}, {"x", x}, {"y", y}, {"theta", th}, {"slip", slip}};
  json est = json::object();
  for (const auto& [name, poses] : estimates.pose_streams()) {
    const std::size_t s = std::max<std::size_t>(1, poses.size() / 1500);
    json et = json::array(), ex = json::array(), ey = json::array();
    for (std::size_t i = 0; i < poses.size(); i += s) {
      et.push_back(R4(poses[i].t_s));
      ex.push_back(R4(poses[i].x_m));
      ey.push_back(R4(poses[i].y_m));
    }
    est[name] = {{"t", et}, {"x", ex}, {"y", ey}};
  }
  d["estimates"] = est;
  json wheels = json::array();
  for (const auto& w : robot.wheels) {
    wheels.push_back({{"name", w.name}, {"x", R4(w.x_m)}, {"y", R4(w.y_m)}, {"r", R4(w.radius_m)},
                      {"bit", w.slip_bit}});
  }
  d["robot"] = {{"half_length", R4(robot.half_length_m)},
                {"half_width", R4(robot.half_width_m)},
                {"wheels", wheels}};
  return d;
}

// Bus load in 100 ms bins from the can.log just written: the bits of each frame on the wire
// (stuffing as the bus model's Tindell bound) over the bits the bin has. The log's clock is
// the bus's; `bus_at_motion_s` (the motion_start event) shifts it to the plots' time.
Series BusLoadSeries(const std::string& can_log, double bitrate_bps, double bus_at_motion_s) {
  Series s{"bus load", "#1f77b4", {}, {}};
  std::ifstream in(can_log);
  if (!in || bitrate_bps <= 0) return s;
  constexpr double kBin = 0.1;
  std::vector<double> bits;
  std::string line;
  std::size_t n = 0;
  bus::CandumpRecord rec;
  while (std::getline(in, line)) {
    if (bus::ParseCandumpLine(line, ++n, rec) != bus::CandumpLineStatus::kRecord) continue;
    const auto bin = static_cast<std::size_t>(static_cast<double>(rec.timestamp_ns) * 1e-9 / kBin);
    if (bin > 10'000'000) break;  // a log that is not ours; the plot is only an aid
    if (bits.size() <= bin) bits.resize(bin + 1, 0.0);
    bits[bin] += CanFrameBits(rec.frame, StuffingMode::kTindell);
  }
  for (std::size_t i = 0; i < bits.size(); ++i) {
    s.x.push_back((static_cast<double>(i) + 0.5) * kBin - bus_at_motion_s);
    s.y.push_back(100.0 * bits[i] / (bitrate_bps * kBin));
  }
  return s;
}

}  // namespace

void WriteRunArtefacts(const std::string& out, const nlohmann::json& report,
                       const TruthRecorder& truth, const EstimateDecoder& estimates,
                       const std::vector<nlohmann::json>& events, const ReplayRobot& robot) {
  const auto& truth_pose = truth.poses();
  const auto& truth_vel = truth.velocities();
  const auto& pose_streams = estimates.pose_streams();
  const auto& vel_streams = estimates.velocity_streams();
  WriteTruthCsv(out + "/truth.csv", truth.rows());
  WriteEstimateCsv(out + "/estimate.csv", estimates.rows());
  WriteTum(out + "/truth.tum", truth_pose);
  for (const auto& [name, est] : pose_streams) {
    // A stream named "pose" (the reference firmware's corrected one) also as estimate.tum,
    // "pose_raw" as estimate_raw.tum: the names evo recipes in docs/ use.
    WriteTum(out + "/estimate_" + name + ".tum", est);
    if (name == "pose") WriteTum(out + "/estimate.tum", est);
    if (name == "pose_raw") WriteTum(out + "/estimate_raw.tum", est);
  }
  WriteJsonLines(out + "/events.jsonl", events);
  WriteText(out + "/report.json", report.dump(2) + "\n");

  const char* colors[] = {"#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b"};
  // Shaded on every time plot: the ground truth's slip intervals and the injected faults.
  std::vector<Band> time_bands;
  std::map<std::string, double> fault_started;
  for (const auto& e : events) {
    const std::string kind = e.value("event", std::string());
    if (kind == "slip" && e.contains("start_s") && e.contains("end_s")) {
      time_bands.push_back({e.value("start_s", 0.0), e.value("end_s", 0.0), "slip", "#ff7f0e"});
    } else if (kind == "fault_start" || kind == "fault_end") {
      const std::string key =
          e.value("fault", std::string()) + "/" + e.value("node_id", nlohmann::json()).dump();
      if (kind == "fault_start") {
        fault_started[key] = e.value("t_s", 0.0);
      } else if (auto it = fault_started.find(key); it != fault_started.end()) {
        time_bands.push_back({it->second, e.value("t_s", 0.0), "fault", "#7f7f7f"});
        fault_started.erase(it);
      }
    }
  }
  std::vector<std::string> plots;
  {
    std::vector<Series> ss;
    Series t{"truth", "#1f77b4", {}, {}};
    for (const auto& p : truth_pose) t.x.push_back(p.x_m), t.y.push_back(p.y_m);
    ss.push_back(t);
    int c = 0;
    for (const auto& [name, est] : pose_streams) {
      Series e{name, colors[c++ % 5], {}, {}, true};
      for (const auto& p : est) e.x.push_back(p.x_m), e.y.push_back(p.y_m);
      ss.push_back(e);
    }
    plots.push_back(SvgPlot("Trajectory: truth vs estimates (equal axes)", "x [m]", "y [m]", ss, {}, true));
  }
  for (const auto& [stream, residual] : estimates.residuals()) {
    std::vector<Series> ss{{"residual r", "#1f77b4", residual.t_s, residual.residual_rad}};
    if (!residual.band_lower_rad.empty()) {
      ss.push_back({"band lower", "#d62728", residual.t_s, residual.band_lower_rad, true});
      ss.push_back({"band upper", "#d62728", residual.t_s, residual.band_upper_rad, true});
    }
    plots.push_back(SvgPlot(fmt::format("{}: residual against its band (cf. paper 000 fig 8)",
                                        stream),
                            "t [s]", "r [rad]", ss, time_bands));
  }
  if (!vel_streams.empty()) {
    std::vector<Series> ss;
    Series t{"truth vx", "#1f77b4", {}, {}};
    for (const auto& v : truth_vel) t.x.push_back(v.t_s), t.y.push_back(v.vx_m_s);
    ss.push_back(t);
    int c = 0;
    for (const auto& [name, est] : vel_streams) {
      Series e{name + " vx", colors[c++ % 5], {}, {}, true};
      for (const auto& v : est) e.x.push_back(v.t_s), e.y.push_back(v.vx_m_s);
      ss.push_back(e);
    }
    plots.push_back(SvgPlot("Forward velocity (cf. paper 002 figs 2-4)", "t [s]", "vx [m/s]", ss,
                            time_bands));
  }
  if (!pose_streams.empty() && !truth_pose.empty()) {
    std::vector<Series> ss;
    int c = 0;
    for (const auto& [name, est] : pose_streams) {
      Series e{name, colors[c++ % 5], {}, {}};
      // Distance travelled (truth) at each estimate sample vs the position error there.
      std::size_t j = 0;
      double dist = 0;
      for (const auto& p : est) {
        while (j + 1 < truth_pose.size() && truth_pose[j + 1].t_s <= p.t_s) {
          dist += std::hypot(truth_pose[j + 1].x_m - truth_pose[j].x_m,
                             truth_pose[j + 1].y_m - truth_pose[j].y_m);
          ++j;
        }
        const PoseSample t = InterpolatePose(truth_pose, p.t_s);
        e.x.push_back(dist);
        e.y.push_back(std::hypot(p.x_m - t.x_m, p.y_m - t.y_m));
      }
      ss.push_back(e);
    }
    plots.push_back(
        SvgPlot("Position error over distance travelled", "distance [m]", "error [m]", ss));
  }
  if (robot.bus_bitrate_bps > 0) {
    double bus_at_motion_s = 0;
    for (const auto& e : events) {
      if (e.value("event", std::string()) == "motion_start") {
        bus_at_motion_s = e.value("bus_time_s", 0.0);
      }
    }
    const Series load = BusLoadSeries(out + "/can.log", robot.bus_bitrate_bps, bus_at_motion_s);
    if (!load.x.empty()) {
      plots.push_back(SvgPlot(fmt::format("Bus load (100 ms bins, {:.0f} kbit/s)",
                                          robot.bus_bitrate_bps / 1000),
                              "t [s]", "load [%]", {load}, time_bands));
    }
  }
  WriteText(out + "/report.html",
            HtmlReport(report, plots, ReplayData(truth, estimates, robot)));
}

}  // namespace wheelhil::emulator::scoring
