#pragma once
/// Writers of a run's artefacts: truth.csv / estimate.csv (one row per sample, SI units, header
/// line), TUM trajectories (`t x y z qx qy qz qw`, for evo), events.jsonl (one JSON object per
/// line) and report.html (self-contained: inline SVG plots, no external assets). Throw
/// std::runtime_error naming the path when a file cannot be written. Thread-compatible.

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "emulator/scoring/metrics.h"

namespace wheelhil::emulator::scoring {

/// One ground-truth row (world frame W relative to the start pose; body velocity in B).
struct TruthRow {
  double t_s = 0;
  double x_m = 0, y_m = 0, z_m = 0, theta_rad = 0;
  double vx_m_s = 0, vy_m_s = 0, omega_rad_s = 0;
  int slipping_wheels = 0;  ///< Bit i: drive wheel i slips (ground truth).
};

/// One estimate row: a pose stream (x, y, theta) or a velocity stream (vx, vy, omega).
struct EstimateRow {
  double t_s = 0;
  int cycle = 0;
  std::string stream;  ///< "pose", "pose_raw", "fused", "odometry", "accel".
  double a = 0, b = 0, c = 0;
};

void WriteTruthCsv(const std::string& path, const std::vector<TruthRow>& rows);
void WriteEstimateCsv(const std::string& path, const std::vector<EstimateRow>& rows);
/// TUM format; planar poses get z = 0 and a yaw-only quaternion.
void WriteTum(const std::string& path, const std::vector<PoseSample>& poses);
void WriteJsonLines(const std::string& path, const std::vector<nlohmann::json>& events);
void WriteText(const std::string& path, const std::string& text);

/// A named curve for an SVG plot.
struct Series {
  std::string name;
  std::string color;  ///< CSS colour.
  std::vector<double> x, y;
  bool dashed = false;
};

/// An interval of the x axis shaded behind the lines (a slip interval, a fault window).
struct Band {
  double x0 = 0, x1 = 0;
  std::string label;  ///< One legend entry per distinct label.
  std::string color;  ///< CSS colour (drawn translucent).
};

/// A line plot as an <svg> element: round ticks (1, 2, 5 x 10^k) on both axes, the bands
/// shaded, a legend; equal_axes keeps 1:1 (a trajectory, where a drift must look its size).
std::string SvgPlot(const std::string& title, const std::string& x_label,
                    const std::string& y_label, const std::vector<Series>& series,
                    const std::vector<Band>& bands = {}, bool equal_axes = false,
                    int width = 640, int height = 360);

/// The HTML report: title, the report's summary table (from report.json) and the plots.
/// `replay` (run_artefacts.cc's ReplayData; null: none) adds a top-down replay of the run that
/// plays in the page: the robot's outline and wheels (orange while the truth says a wheel
/// slips), the truth's and the estimates' traces so far. Self-contained: no network. The page
/// sets data-replay-ready on <body> once drawn, data-script-errors if any script failed.
std::string HtmlReport(const nlohmann::json& report, const std::vector<std::string>& svg_plots,
                       const nlohmann::json& replay = nullptr);

}  // namespace wheelhil::emulator::scoring
