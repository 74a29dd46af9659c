// bus/socketcan_transport.h runs unchanged on a ucan bus: it only uses the plain SocketCAN API,
// which this binary's linked libwheelhil_ucan.so routes to an in-process UcanBroker.

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <system_error>

#include "bus/socketcan_transport.h"
#include "bus/ucan_broker.h"
#include "tests/bus/ucan_test_util.h"

namespace wheelhil::bus {
namespace {

class UcanTransportTest : public ::testing::Test {
 protected:
  UcanTransportTest() : broker_(Options(dir_.path())) { broker_.AddBus("ucan0"); }
  static UcanBrokerOptions Options(const std::string& dir) {
    UcanBrokerOptions o;
    o.runtime_dir = dir;
    return o;
  }
  testing::TempRuntimeDir dir_;
  UcanBroker broker_;
};

TEST_F(UcanTransportTest, SendReceiveWithFiltersFdAndTimestamps) {
  CanTransportOptions fd_options;
  fd_options.fd_frames = true;
  auto tx = SocketCanTransport::Open("ucan0", fd_options);
  CanTransportOptions filtered;
  filtered.fd_frames = true;
  filtered.filters = {CanFilter{0x100, 0x700, false, false}};
  auto rx = SocketCanTransport::Open("ucan0", filtered);
  EXPECT_EQ(rx.ifindex(), 1000);

  const std::uint8_t bytes[] = {1, 2, 3};
  ASSERT_FALSE(tx.Send(CanFrame::Classic(0x200, bytes)));  // filtered out at rx
  ASSERT_FALSE(tx.Send(CanFrame::Classic(0x123, bytes)));
  CanFrame fd;
  fd.id = 0x1AB;
  fd.fd = true;
  fd.len = 64;
  fd.data[63] = 0x5A;
  ASSERT_FALSE(tx.Send(fd));

  ReceivedFrame got;
  ASSERT_FALSE(rx.Receive(got, 2000));
  EXPECT_EQ(got.frame, CanFrame::Classic(0x123, bytes));
  EXPECT_TRUE(got.kernel_timestamp);
  EXPECT_GT(got.timestamp_ns, 1600000000LL * 1000000000LL);
  EXPECT_EQ(got.ifindex, 1000);
  EXPECT_EQ(rx.InterfaceName(got.ifindex), "ucan0");
  ASSERT_FALSE(rx.Receive(got, 2000));
  EXPECT_TRUE(got.frame.fd);
  EXPECT_EQ(got.frame.len, 64);
  EXPECT_EQ(got.frame.data[63], 0x5A);
  EXPECT_EQ(rx.Receive(got, 0), std::errc::resource_unavailable_try_again);
  EXPECT_EQ(tx.stats().sent, 3u);
  EXPECT_EQ(rx.stats().received, 2u);
}

TEST_F(UcanTransportTest, ReceiveOwnAndErrorFrames) {
  CanTransportOptions own;
  own.receive_own = true;
  own.error_mask = 0x40;  // CAN_ERR_BUSOFF
  auto a = SocketCanTransport::Open("ucan0", own);
  auto b = SocketCanTransport::Open("ucan0");
  const std::uint8_t one[] = {1};
  ASSERT_FALSE(a.Send(CanFrame::Classic(0x10, one)));
  ReceivedFrame got;
  ASSERT_FALSE(a.Receive(got, 2000));
  EXPECT_EQ(got.frame.id, 0x10u);
  ASSERT_FALSE(b.Receive(got, 2000));
  EXPECT_EQ(got.frame.id, 0x10u);
  CanFrame busoff;
  busoff.error = true;
  busoff.id = 0x40;
  busoff.len = 8;
  ASSERT_FALSE(b.Send(busoff));
  ASSERT_FALSE(a.Receive(got, 2000));
  EXPECT_TRUE(got.frame.error);
  EXPECT_EQ(got.frame.id, 0x40u);
}

TEST_F(UcanTransportTest, UnknownInterfaceThrows) {
  EXPECT_THROW(SocketCanTransport::Open("vcan0"), std::system_error);
}

}  // namespace
}  // namespace wheelhil::bus
