#include "emulator/scoring/metric_format.h"

#include <cmath>
#include <string_view>

#include <fmt/format.h>

namespace wheelhil::emulator::scoring {

namespace {

bool EndsWith(std::string_view s, std::string_view suffix) {
  return s.size() >= suffix.size() && s.substr(s.size() - suffix.size()) == suffix;
}

// Three significant digits, but never a power-of-ten exponent for what a person reads.
std::string Sig3(double v) {
  const double a = std::fabs(v);
  if (a == 0) return "0";
  const int decimals = std::max(0, 2 - static_cast<int>(std::floor(std::log10(a))));
  return fmt::format("{:.{}f}", v, std::min(decimals, 9));
}

// v in the SI unit `si`; below 1 (0.1 for angles) shown in the milli unit.
std::string Scaled(double v, const char* si, const char* milli, double threshold = 1.0) {
  if (std::fabs(v) < threshold && v != 0) return Sig3(v * 1000) + " " + milli;
  return Sig3(v) + " " + si;
}

}  // namespace

std::string FormatMetricValue(const std::string& name, const nlohmann::json& value) {
  if (value.is_boolean()) return value.get<bool>() ? "yes" : "no";
  if (value.is_number_integer() || value.is_number_unsigned()) return value.dump();
  if (!value.is_number_float()) return value.dump();
  const double v = value.get<double>();
  if (!std::isfinite(v)) return value.dump();
  if (EndsWith(name, "_rad_s")) return Scaled(v, "rad/s", "mrad/s", 0.1);
  if (EndsWith(name, "_m_s")) return Scaled(v, "m/s", "mm/s", 0.1);
  if (EndsWith(name, "_m")) return Scaled(v, "m", "mm");
  if (EndsWith(name, "_rad")) return Scaled(v, "rad", "mrad", 0.1);
  if (EndsWith(name, "_s")) return Scaled(v, "s", "ms");
  if (name.find("pct") != std::string::npos) return Sig3(v) + " %";
  if (name == "load" || EndsWith(name, "_fraction") || EndsWith(name, "_rate")) {
    return Sig3(v * 100) + " %";
  }
  if (name.find("_over_") != std::string::npos) return Sig3(v) + "\u00d7";
  if (v == std::round(v) && std::fabs(v) < 1e15) return fmt::format("{:.0f}", v);
  return Sig3(v);
}

AxisTicks NiceTicks(double lo, double hi, int target) {
  AxisTicks t;
  if (!(hi > lo) || !std::isfinite(lo) || !std::isfinite(hi) || target < 1) {
    t.first = lo;
    t.count = 1;
    return t;
  }
  const double raw = (hi - lo) / target;
  const double p = std::pow(10.0, std::floor(std::log10(raw)));
  const double m = raw / p;
  t.step = (m < 1.5 ? 1 : m < 3.5 ? 2 : m < 7.5 ? 5 : 10) * p;
  t.first = std::ceil(lo / t.step - 1e-9) * t.step;
  t.count = static_cast<int>(std::floor((hi - t.first) / t.step + 1e-9)) + 1;
  t.decimals = std::max(0, -static_cast<int>(std::floor(std::log10(t.step) + 1e-9)));
  return t;
}

}  // namespace wheelhil::emulator::scoring
