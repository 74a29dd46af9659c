#pragma once
/// How a report shows a metric to a person: rounded to what it means, with a unit read from the
/// metric's name (wheelhil's names end in their SI unit: _m, _rad, _m_s, _rad_s, _s, _pct).
/// Small lengths go to mm, small angles to mrad, short times to ms; `load` and other fractions
/// to %, `a_over_b` to a ratio. The report.json keeps the full values; this is display only.
/// Pure functions; thread-safe.

#include <string>

#include <nlohmann/json.hpp>

namespace wheelhil::emulator::scoring {

/// e.g. ("final_position_error_m", 0.0072318) -> "7.23 mm"; ("load", 0.0336) -> "3.36 %";
/// ("distance_m", 1.97295) -> "1.973 m"; ("samples", 39) -> "39"; booleans -> "yes"/"no".
std::string FormatMetricValue(const std::string& name, const nlohmann::json& value);

/// Axis ticks: a step of 1, 2 or 5 times a power of ten giving about `target` intervals over
/// [lo, hi], and how many decimals its labels need.
struct AxisTicks {
  double first = 0;  ///< First tick >= lo (a multiple of step).
  double step = 1;
  int count = 0;     ///< Ticks first, first + step, ... <= hi.
  int decimals = 0;
};
AxisTicks NiceTicks(double lo, double hi, int target = 5);

}  // namespace wheelhil::emulator::scoring
