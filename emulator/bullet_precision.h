#pragma once
/// Guards against the classic Debian Bullet trap: the float (`bullet`) and double
/// (`bullet-float64`) builds share headers, link either way and then read garbage. wheelhil uses
/// the single-precision build; this reports what the linked library was built with.

namespace wheelhil::emulator {

/// True when the linked Bullet library was built with BT_USE_DOUBLE_PRECISION.
bool LinkedBulletIsDoublePrecision() noexcept;
/// True when our own translation units were compiled with BT_USE_DOUBLE_PRECISION.
bool CompiledWithDoublePrecision() noexcept;

}  // namespace wheelhil::emulator
