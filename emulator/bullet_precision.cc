#include "emulator/bullet_precision.h"

#include <LinearMath/btScalar.h>

namespace wheelhil::emulator {

bool LinkedBulletIsDoublePrecision() noexcept { return btIsDoublePrecision(); }

bool CompiledWithDoublePrecision() noexcept {
#ifdef BT_USE_DOUBLE_PRECISION
  return true;
#else
  return false;
#endif
}

}  // namespace wheelhil::emulator
