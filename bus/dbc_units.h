#pragma once
/// The physical units DBC files write in their signals' unit strings, converted to SI. A DBC
/// says "mm", "deg/s" or "km/h" where wheelhil computes in m, rad/s and m/s; this is the one
/// table of those spellings, for decoding a firmware's frames and for encoding a device's. The
/// unit string is matched exactly after trimming spaces (case matters: "mm" is not "Mm"), with
/// the spellings real files use ("°/s", "dps", "m/s^2", "m/s²", "rpm", "1/min").
/// Stateless; thread-safe.

#include <optional>
#include <string_view>

namespace wheelhil::bus {

/// What a signal measures, for choosing the units that fit it.
enum class PhysicalQuantity {
  kLength,         ///< m, mm, cm, km.
  kAngle,          ///< rad, mrad, urad, deg, °.
  kSpeed,          ///< m/s, mm/s, cm/s, km/h.
  kAngularRate,    ///< rad/s, mrad/s, deg/s, °/s, dps, rpm, 1/min, rps.
  kAcceleration,   ///< m/s^2, m/s2, m/s², mm/s^2, g.
  kTime,           ///< s, ms, us, µs, ns.
  kTemperature,    ///< K; degC, °C, C (with an offset: UnitToSi).
  kDimensionless,  ///< "", "-", "1", counts, flags, %: taken as they are (% is not scaled).
  kCurrent,        ///< A, mA.
  kTorque,         ///< N*m, Nm, N.m, mNm.
};

/// "length", "angle", ...: for messages.
std::string_view PhysicalQuantityName(PhysicalQuantity q) noexcept;
/// The units accepted for `q`, as a list for messages ("m, mm, cm, km").
std::string_view AcceptedUnits(PhysicalQuantity q) noexcept;

/// SI value = value * scale + offset.
struct UnitToSi {
  double scale = 1.0;
  double offset = 0.0;
  double ToSi(double v) const noexcept { return v * scale + offset; }
  double FromSi(double si) const noexcept { return (si - offset) / scale; }
};

/// The conversion of `unit` to the SI unit of `q`; nullopt when `unit` does not measure `q`.
std::optional<UnitToSi> ConvertUnit(std::string_view unit, PhysicalQuantity q) noexcept;

}  // namespace wheelhil::bus
