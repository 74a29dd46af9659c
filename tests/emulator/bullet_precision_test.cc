#include "emulator/bullet_precision.h"

#include <gtest/gtest.h>

namespace wheelhil::emulator {
namespace {

// Mixing Debian's float and double Bullet builds links cleanly and then reads garbage; this is
// the guard the build relies on.
TEST(BulletPrecision, LinkedLibraryMatchesOurHeaders) {
  EXPECT_EQ(LinkedBulletIsDoublePrecision(), CompiledWithDoublePrecision());
  EXPECT_FALSE(CompiledWithDoublePrecision()) << "wheelhil is built against `pkg-config bullet`";
}

}  // namespace
}  // namespace wheelhil::emulator
