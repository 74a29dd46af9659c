#include "bus/dbc_units.h"

#include <numbers>

namespace wheelhil::bus {

namespace {

struct Spelling {
  std::string_view unit;
  double scale;
  double offset = 0.0;
};

constexpr double kDeg = std::numbers::pi / 180.0;
constexpr double kStandardGravity = 9.80665;  // m/s^2, ISO 80000-3

std::string_view Trim(std::string_view s) noexcept {
  while (!s.empty() && s.front() == ' ') s.remove_prefix(1);
  while (!s.empty() && s.back() == ' ') s.remove_suffix(1);
  return s;
}

template <std::size_t N>
std::optional<UnitToSi> Find(const Spelling (&table)[N], std::string_view unit) noexcept {
  for (const Spelling& s : table) {
    if (s.unit == unit) return UnitToSi{s.scale, s.offset};
  }
  return std::nullopt;
}

}  // namespace

std::string_view PhysicalQuantityName(PhysicalQuantity q) noexcept {
  switch (q) {
    case PhysicalQuantity::kLength: return "length";
    case PhysicalQuantity::kAngle: return "angle";
    case PhysicalQuantity::kSpeed: return "speed";
    case PhysicalQuantity::kAngularRate: return "angular rate";
    case PhysicalQuantity::kAcceleration: return "acceleration";
    case PhysicalQuantity::kTime: return "time";
    case PhysicalQuantity::kTemperature: return "temperature";
    case PhysicalQuantity::kDimensionless: return "dimensionless value";
    case PhysicalQuantity::kCurrent: return "current";
    case PhysicalQuantity::kTorque: return "torque";
  }
  return "?";
}

std::string_view AcceptedUnits(PhysicalQuantity q) noexcept {
  switch (q) {
    case PhysicalQuantity::kLength: return "m, mm, cm, km";
    case PhysicalQuantity::kAngle: return "rad, mrad, urad, deg";
    case PhysicalQuantity::kSpeed: return "m/s, mm/s, cm/s, km/h";
    case PhysicalQuantity::kAngularRate: return "rad/s, mrad/s, deg/s, dps, rpm, rps";
    case PhysicalQuantity::kAcceleration: return "m/s^2, mm/s^2, g";
    case PhysicalQuantity::kTime: return "s, ms, us, ns";
    case PhysicalQuantity::kTemperature: return "degC, K";
    case PhysicalQuantity::kDimensionless: return "none, -, 1, counts, %";
    case PhysicalQuantity::kCurrent: return "A, mA";
    case PhysicalQuantity::kTorque: return "N*m, Nm, mNm";
  }
  return "";
}

std::optional<UnitToSi> ConvertUnit(std::string_view unit, PhysicalQuantity q) noexcept {
  unit = Trim(unit);
  static constexpr Spelling kLength[] = {{"m", 1.0}, {"mm", 1e-3}, {"cm", 1e-2}, {"km", 1e3}};
  static constexpr Spelling kAngle[] = {{"rad", 1.0},          {"mrad", 1e-3}, {"urad", 1e-6},
                                        {"\xC2\xB5rad", 1e-6}, {"deg", kDeg},  {"\xC2\xB0", kDeg}};
  static constexpr Spelling kSpeed[] = {
      {"m/s", 1.0}, {"mm/s", 1e-3}, {"cm/s", 1e-2}, {"km/h", 1.0 / 3.6}, {"kph", 1.0 / 3.6}};
  static constexpr Spelling kRate[] = {{"rad/s", 1.0},
                                       {"mrad/s", 1e-3},
                                       {"deg/s", kDeg},
                                       {"\xC2\xB0/s", kDeg},
                                       {"dps", kDeg},
                                       {"rpm", 2.0 * std::numbers::pi / 60.0},
                                       {"1/min", 2.0 * std::numbers::pi / 60.0},
                                       {"rps", 2.0 * std::numbers::pi}};
  static constexpr Spelling kAccel[] = {{"m/s^2", 1.0},       {"m/s2", 1.0},
                                        {"m/s\xC2\xB2", 1.0}, {"mm/s^2", 1e-3},
                                        {"mm/s2", 1e-3},      {"g", kStandardGravity}};
  static constexpr Spelling kTime[] = {
      {"s", 1.0}, {"ms", 1e-3}, {"us", 1e-6}, {"\xC2\xB5s", 1e-6}, {"ns", 1e-9}};
  static constexpr Spelling kTemperature[] = {
      {"K", 1.0}, {"degC", 1.0, 273.15}, {"\xC2\xB0" "C", 1.0, 273.15}, {"C", 1.0, 273.15}};
  static constexpr Spelling kDimensionless[] = {{"", 1.0},       {"-", 1.0},      {"1", 1.0},
                                                {"counts", 1.0}, {"count", 1.0},  {"%", 1.0},
                                                {"bit", 1.0},    {"flags", 1.0}};
  static constexpr Spelling kCurrent[] = {{"A", 1.0}, {"mA", 1e-3}};
  static constexpr Spelling kTorque[] = {
      {"N*m", 1.0}, {"Nm", 1.0}, {"N.m", 1.0}, {"N m", 1.0}, {"mNm", 1e-3}, {"mN*m", 1e-3}};
  switch (q) {
    case PhysicalQuantity::kLength: return Find(kLength, unit);
    case PhysicalQuantity::kAngle: return Find(kAngle, unit);
    case PhysicalQuantity::kSpeed: return Find(kSpeed, unit);
    case PhysicalQuantity::kAngularRate: return Find(kRate, unit);
    case PhysicalQuantity::kAcceleration: return Find(kAccel, unit);
    case PhysicalQuantity::kTime: return Find(kTime, unit);
    case PhysicalQuantity::kTemperature: return Find(kTemperature, unit);
    case PhysicalQuantity::kDimensionless: return Find(kDimensionless, unit);
    case PhysicalQuantity::kCurrent: return Find(kCurrent, unit);
    case PhysicalQuantity::kTorque: return Find(kTorque, unit);
  }
  return std::nullopt;
}

}  // namespace wheelhil::bus
