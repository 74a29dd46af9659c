#include "bus/can_frame.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <stdexcept>
#include <vector>

namespace wheelhil::bus {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

TEST(CanFrame, ClassicFrameFormatsLikeCanUtils) {
  const std::vector<std::uint8_t> bytes{0xDE, 0xAD, 0xBE, 0xEF};
  EXPECT_EQ(ToCanUtilsString(CanFrame::Classic(0x123, bytes)), "123#DEADBEEF");
  EXPECT_EQ(ToCanUtilsString(CanFrame::Classic(0x1234567, bytes, true)), "01234567#DEADBEEF");
  EXPECT_EQ(ToCanUtilsString(CanFrame::Classic(0x7FF, {})), "7FF#");
}

TEST(CanFrame, RtrAndFdFormatting) {
  CanFrame rtr;
  rtr.id = 0x701;
  rtr.rtr = true;
  EXPECT_EQ(ToCanUtilsString(rtr), "701#R");
  rtr.len = 3;
  EXPECT_EQ(ToCanUtilsString(rtr), "701#R3");
  CanFrame fd;
  fd.id = 0x42;
  fd.fd = true;
  fd.fd_flags = 1;
  fd.len = 12;
  fd.data[11] = 0xAB;
  EXPECT_EQ(ToCanUtilsString(fd), "042##1" + std::string(22, '0') + "AB");
  EXPECT_TRUE(fd.IsValid());
  fd.len = 13;
  EXPECT_FALSE(fd.IsValid());
}

TEST(CanFrame, RejectsOversizeIdAndPayload) {
  const std::vector<std::uint8_t> nine(9, 0);
  EXPECT_THAT([&] { CanFrame::Classic(0x100, nine); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("at most 8")));
  EXPECT_THAT([&] { CanFrame::Classic(0x800, {}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("11-bit")));
  EXPECT_NO_THROW(CanFrame::Classic(0x800, {}, true));
}

TEST(CanFrame, DlcMapping) {
  EXPECT_EQ(LengthToDlc(8), 8);
  EXPECT_EQ(LengthToDlc(9), 9);  // rounds up to 12
  EXPECT_EQ(LengthToDlc(64), 15);
  EXPECT_EQ(DlcToLength(15, true), 64u);
  EXPECT_EQ(DlcToLength(15, false), 8u);
  EXPECT_TRUE(IsValidFdLength(48));
  EXPECT_FALSE(IsValidFdLength(9));
}

TEST(CanFrame, EqualityIgnoresBytesBeyondLength) {
  CanFrame a = CanFrame::Classic(0x10, std::vector<std::uint8_t>{1, 2});
  CanFrame b = a;
  b.data[5] = 0x55;
  EXPECT_EQ(a, b);
  b.data[1] = 3;
  EXPECT_FALSE(a == b);
}

}  // namespace
}  // namespace wheelhil::bus
