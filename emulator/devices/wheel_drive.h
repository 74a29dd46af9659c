#pragma once
/// What a drive device (a CiA 402 servo drive, a DBC motor controller) makes a wheel's motor do:
/// the set point and torque limit its power stage applies. SI at the wheel. Value type.

#include <cstddef>
#include <cstdint>
#include <limits>

namespace wheelhil::emulator {

struct WheelDriveCommand {
  double omega_rad_s = 0;      ///< Speed set point at the wheel (the motor servo follows it).
  double torque_limit_nm = 0;  ///< Wheel side; 0 = power stage off (the wheel coasts).
};

/// A drive and the wheel it powers (index in the vehicle's wheels).
struct WheelDrive {
  std::size_t wheel = 0;
  WheelDriveCommand command;
};

/// A fault of a drive over [t0_ns, t1_ns) of virtual time (t1 = INT64_MAX: to the end).
struct DriveFault {
  enum class Kind : std::uint8_t {
    kOverCurrent,  ///< trips at t0 (fault 0x2310); a fault reset is refused until t1
    kStuck,        ///< the drive ignores its set point (the demand freezes)
    kTorqueLimit,  ///< the torque limit drops to torque_limit_nm (wheel side)
  };
  Kind kind = Kind::kOverCurrent;
  std::int64_t t0_ns = 0;
  std::int64_t t1_ns = std::numeric_limits<std::int64_t>::max();
  double torque_limit_nm = 0;
};

}  // namespace wheelhil::emulator
