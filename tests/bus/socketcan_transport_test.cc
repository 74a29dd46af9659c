#include "bus/socketcan_transport.h"

#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/net_tstamp.h>
#include <net/if.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include "bus/internal/socketcan_convert.h"
#include "tests/bus/timestamping_expectations.h"

namespace wheelhil::bus {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::ThrowsMessage;
using ::testing::UnorderedElementsAre;

CanFrame Fd(std::uint32_t id, std::uint8_t len, std::uint8_t flags, bool extended = false) {
  CanFrame f;
  f.id = id;
  f.fd = true;
  f.fd_flags = flags;
  f.extended = extended;
  f.len = len;
  for (std::uint8_t i = 0; i < len; ++i) f.data[i] = static_cast<std::uint8_t>(0xA0 + i);
  return f;
}

CanFrame Remote(std::uint32_t id, std::uint8_t dlc, bool extended = false) {
  CanFrame f;
  f.id = id;
  f.rtr = true;
  f.len = dlc;
  f.extended = extended;
  return f;
}

CanFrame ErrorFrame(std::uint32_t classes) {
  CanFrame f;
  f.error = true;
  f.id = classes;
  f.len = CAN_ERR_DLC;
  f.data[1] = CAN_ERR_CRTL_RX_WARNING;
  return f;
}

// ---------------------------------------------------------------------------------------------
// Conversion and messages: no AF_CAN needed.

TEST(SocketCanConvert, ClassicStandardFrame) {
  const std::vector<std::uint8_t> bytes{0xDE, 0xAD, 0xBE, 0xEF};
  canfd_frame buf;
  ASSERT_EQ(internal::EncodeFrame(CanFrame::Classic(0x123, bytes), buf), CAN_MTU);
  can_frame cf;
  std::memcpy(&cf, &buf, sizeof(cf));
  EXPECT_EQ(cf.can_id, 0x123u);
  EXPECT_EQ(cf.len, 4);
  EXPECT_EQ(cf.data[0], 0xDE);
  EXPECT_EQ(cf.data[3], 0xEF);
  EXPECT_EQ(cf.data[4], 0);
}

TEST(SocketCanConvert, FlagsForExtendedRemoteAndErrorFrames) {
  canfd_frame buf;
  const std::vector<std::uint8_t> one{0x01};
  ASSERT_EQ(internal::EncodeFrame(CanFrame::Classic(0x1ABCDEF0, one, true), buf), CAN_MTU);
  EXPECT_EQ(buf.can_id, 0x1ABCDEF0u | CAN_EFF_FLAG);

  ASSERT_EQ(internal::EncodeFrame(Remote(0x701, 3), buf), CAN_MTU);
  EXPECT_EQ(buf.can_id, 0x701u | CAN_RTR_FLAG);
  EXPECT_EQ(buf.len, 3);
  EXPECT_EQ(buf.data[0], 0);

  ASSERT_EQ(internal::EncodeFrame(ErrorFrame(CAN_ERR_BUSOFF), buf), CAN_MTU);
  EXPECT_EQ(buf.can_id, CAN_ERR_BUSOFF | CAN_ERR_FLAG);
  EXPECT_EQ(buf.len, CAN_ERR_DLC);
}

TEST(SocketCanConvert, FdFrameUsesCanfdMtuAndFlags) {
  canfd_frame buf;
  ASSERT_EQ(internal::EncodeFrame(Fd(0x42, 64, CANFD_BRS | CANFD_ESI), buf), CANFD_MTU);
  EXPECT_EQ(buf.can_id, 0x42u);
  EXPECT_EQ(buf.len, 64);
  EXPECT_EQ(buf.flags & (CANFD_BRS | CANFD_ESI), CANFD_BRS | CANFD_ESI);
  EXPECT_EQ(buf.data[63], 0xA0 + 63);
}

TEST(SocketCanConvert, InvalidFramesAreNotEncoded) {
  canfd_frame buf;
  CanFrame too_long = CanFrame::Classic(0x10, {});
  too_long.len = 9;
  EXPECT_EQ(internal::EncodeFrame(too_long, buf), 0u);
  EXPECT_EQ(internal::EncodeFrame(Fd(0x10, 13, 0), buf), 0u);
  CanFrame big_id = CanFrame::Classic(0x10, {});
  big_id.id = 0x800;
  EXPECT_EQ(internal::EncodeFrame(big_id, buf), 0u);
  CanFrame fd_remote = Fd(0x10, 8, 0);
  fd_remote.rtr = true;
  EXPECT_EQ(internal::EncodeFrame(fd_remote, buf), 0u);
}

TEST(SocketCanConvert, RoundTripsEveryKind) {
  const std::vector<std::uint8_t> eight{1, 2, 3, 4, 5, 6, 7, 8};
  const std::vector<CanFrame> frames = {CanFrame::Classic(0x000, {}),
                                        CanFrame::Classic(0x7FF, eight),
                                        CanFrame::Classic(0x1FFFFFFF, eight, true),
                                        Remote(0x123, 8),
                                        Remote(0x12345, 0, true),
                                        ErrorFrame(CAN_ERR_CRTL | CAN_ERR_BUSERROR),
                                        Fd(0x1, 0, 0),
                                        Fd(0x7FF, 12, CANFD_BRS),
                                        Fd(0x1FFFFFFF, 64, CANFD_ESI, true)};
  for (const CanFrame& f : frames) {
    canfd_frame buf;
    const std::size_t size = internal::EncodeFrame(f, buf);
    ASSERT_NE(size, 0u) << ToCanUtilsString(f);
    CanFrame back;
    ASSERT_FALSE(internal::DecodeFrame(&buf, size, back)) << ToCanUtilsString(f);
    EXPECT_EQ(back, f) << ToCanUtilsString(f) << " came back as " << ToCanUtilsString(back);
    EXPECT_EQ(back.fd_flags, f.fd_flags);
  }
}

TEST(SocketCanConvert, DecodeDropsTheFdfMarker) {
  canfd_frame buf{};
  buf.can_id = 0x55;
  buf.len = 8;
  buf.flags = CANFD_BRS | 0x04;  // CANFD_FDF, set by kernels >= 6.2 on every FD frame.
  CanFrame out;
  ASSERT_FALSE(internal::DecodeFrame(&buf, CANFD_MTU, out));
  EXPECT_TRUE(out.fd);
  EXPECT_EQ(out.fd_flags, CANFD_BRS);
}

TEST(SocketCanConvert, DecodeRejectsMalformedDatagrams) {
  const auto bad = std::make_error_code(std::errc::bad_message);
  canfd_frame buf{};
  CanFrame out;
  EXPECT_EQ(internal::DecodeFrame(&buf, 0, out), bad);
  EXPECT_EQ(internal::DecodeFrame(&buf, CAN_MTU - 1, out), bad);
  EXPECT_EQ(internal::DecodeFrame(&buf, CAN_MTU + 1, out), bad);

  buf.len = 9;  // Classic frame claiming 9 bytes.
  EXPECT_EQ(internal::DecodeFrame(&buf, CAN_MTU, out), bad);
  buf.len = 13;  // Not an FD length.
  EXPECT_EQ(internal::DecodeFrame(&buf, CANFD_MTU, out), bad);
  buf.len = 8;
  buf.can_id = 0x800;  // 12-bit id without CAN_EFF_FLAG.
  EXPECT_EQ(internal::DecodeFrame(&buf, CAN_MTU, out), bad);
  buf.can_id = 0x10 | CAN_RTR_FLAG;  // Remote FD frames do not exist.
  EXPECT_EQ(internal::DecodeFrame(&buf, CANFD_MTU, out), bad);
  buf.can_id = CAN_ERR_FLAG | CAN_ERR_BUSOFF;  // Error frames are classic frames.
  EXPECT_EQ(internal::DecodeFrame(&buf, CANFD_MTU, out), bad);
  EXPECT_FALSE(internal::DecodeFrame(&buf, CAN_MTU, out));
  EXPECT_TRUE(out.error);
  EXPECT_EQ(out.id, CAN_ERR_BUSOFF);
}

TEST(SocketCanConvert, FiltersCompareFormatBitAndInvert) {
  const std::vector<can_filter> k = internal::ToKernelFilters({
      {.id = 0x105, .mask = 0x7F0},
      {.id = 0x18DAF100, .mask = 0x1FFFFF00, .extended = true},
      {.id = 0x100, .mask = 0x7FF, .inverse = true},
  });
  ASSERT_EQ(k.size(), 3u);
  EXPECT_EQ(k[0].can_id, 0x105u);
  EXPECT_EQ(k[0].can_mask, 0x7F0u | CAN_EFF_FLAG);
  EXPECT_EQ(k[1].can_id, 0x18DAF100u | CAN_EFF_FLAG);
  EXPECT_EQ(k[1].can_mask, 0x1FFFFF00u | CAN_EFF_FLAG);
  EXPECT_EQ(k[2].can_id, 0x100u | CAN_INV_FILTER);
  EXPECT_EQ(k[2].can_mask, 0x7FFu | CAN_EFF_FLAG);
}

TEST(SocketCanMessages, SayWhatIsWrongAndHowToFixIt) {
  EXPECT_THAT(internal::InterfaceNotFoundMessage("can7"),
              HasSubstr("CAN interface 'can7' not found (ENODEV)"));
  EXPECT_THAT(internal::InterfaceDownMessage("can7"),
              HasSubstr("CAN interface 'can7' is down: ip link set can7 up"));
  EXPECT_THAT(internal::NotCanInterfaceMessage("eth0"), HasSubstr("'eth0' is not a CAN"));
  EXPECT_THAT(
      internal::NoSocketCanMessage("can0", EAFNOSUPPORT),
      AllOf(HasSubstr("'can0'"), HasSubstr("no SocketCAN support"), HasSubstr("AF_CAN"),
            HasSubstr("wheelhil exec"), HasSubstr("ucan"), HasSubstr(std::strerror(EAFNOSUPPORT))));
}

TEST(SocketCanTransport, RejectsBadNamesAndOptionsBeforeTouchingTheKernel) {
  EXPECT_THAT([] { (void)SocketCanTransport::Open(""); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("name '' is invalid")));
  EXPECT_THAT([] { (void)SocketCanTransport::Open("a_name_far_too_long0"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("is invalid")));
  CanTransportOptions many;
  many.filters.resize(513);
  EXPECT_THAT([&] { (void)SocketCanTransport::Open("vcan0", many); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("513 filters")));
}

bool KernelHasSocketCan() {
  const int fd = ::socket(PF_CAN, SOCK_RAW, CAN_RAW);
  if (fd < 0) return false;
  ::close(fd);
  return true;
}

TEST(SocketCanTransport, WithoutAfCanTheErrorPointsAtTheUserspaceBus) {
  if (KernelHasSocketCan()) GTEST_SKIP() << "this kernel has AF_CAN";
  EXPECT_THAT([] { (void)SocketCanTransport::Open("vcan0"); },
              ThrowsMessage<std::system_error>(
                  AllOf(HasSubstr("'vcan0'"), HasSubstr("AF_CAN"), HasSubstr("wheelhil exec"))));
}

// ---------------------------------------------------------------------------------------------
// Over a real kernel vcan: run under tests/vcan/uml_run.sh (CTest: Vcan.SocketCanTransport),
// which sets WHEELHIL_VCAN=vcan0 and WHEELHIL_VCAN2=vcan1.

class VcanTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const char* a = std::getenv("WHEELHIL_VCAN");
    const char* b = std::getenv("WHEELHIL_VCAN2");
    if (a == nullptr || *a == '\0') {
      GTEST_SKIP() << "needs a kernel vcan: set WHEELHIL_VCAN=vcan0 (and WHEELHIL_VCAN2=vcan1), "
                      "or run `ctest -L vcan`, which boots one in user-mode-linux";
    }
    iface_ = a;
    iface2_ = b != nullptr && *b != '\0' ? b : "";
  }

  static std::vector<ReceivedFrame> Drain(SocketCanTransport& t, int first_timeout_ms = 200) {
    std::vector<ReceivedFrame> out;
    ReceivedFrame rf;
    int timeout = first_timeout_ms;
    while (!t.Receive(rf, timeout)) {
      out.push_back(rf);
      timeout = 100;
    }
    return out;
  }

  static std::vector<std::uint32_t> Ids(const std::vector<ReceivedFrame>& frames) {
    std::vector<std::uint32_t> ids;
    for (const ReceivedFrame& f : frames) ids.push_back(f.frame.id);
    return ids;
  }

  // Sets IFF_UP on an interface; returns errno (0 on success).
  static int SetLinkUp(const std::string& iface, bool up) {
    const int fd = ::socket(PF_CAN, SOCK_RAW, CAN_RAW);
    if (fd < 0) return errno;
    ifreq ifr{};
    std::strncpy(ifr.ifr_name, iface.c_str(), IFNAMSIZ - 1);
    int err = 0;
    if (::ioctl(fd, SIOCGIFFLAGS, &ifr) != 0) {
      err = errno;
    } else {
      ifr.ifr_flags = static_cast<short>(up ? (ifr.ifr_flags | IFF_UP) : (ifr.ifr_flags & ~IFF_UP));
      if (::ioctl(fd, SIOCSIFFLAGS, &ifr) != 0) err = errno;
    }
    ::close(fd);
    return err;
  }

  std::string iface_;
  std::string iface2_;
};

TEST_F(VcanTest, SendsAndReceivesClassicFrames) {
  SocketCanTransport tx = SocketCanTransport::Open(iface_);
  SocketCanTransport rx = SocketCanTransport::Open(iface_);
  EXPECT_EQ(rx.name(), iface_);
  EXPECT_GT(rx.ifindex(), 0);
  const std::vector<std::uint8_t> bytes{0xDE, 0xAD, 0xBE, 0xEF};
  const std::vector<CanFrame> sent = {CanFrame::Classic(0x123, bytes),
                                      CanFrame::Classic(0x1234567, bytes, true), Remote(0x321, 2),
                                      CanFrame::Classic(0x7FF, {})};
  for (const CanFrame& f : sent) ASSERT_FALSE(tx.Send(f)) << ToCanUtilsString(f);

  const std::vector<ReceivedFrame> got = Drain(rx);
  ASSERT_EQ(got.size(), sent.size());
  for (std::size_t i = 0; i < sent.size(); ++i) {
    EXPECT_EQ(got[i].frame, sent[i]) << ToCanUtilsString(got[i].frame);
    EXPECT_EQ(got[i].ifindex, rx.ifindex());
    EXPECT_EQ(rx.InterfaceName(got[i].ifindex), iface_);
  }
  EXPECT_EQ(tx.stats().sent, sent.size());
  EXPECT_EQ(tx.stats().send_failures, 0u);
  EXPECT_EQ(rx.stats().received, sent.size());
  EXPECT_EQ(rx.stats().rx_invalid, 0u);
}

TEST_F(VcanTest, ReceiveReportsNothingThereWithoutBlockingForever) {
  SocketCanTransport rx = SocketCanTransport::Open(iface_);
  ReceivedFrame rf;
  EXPECT_EQ(rx.Receive(rf, 0), std::make_error_code(std::errc::resource_unavailable_try_again));
  EXPECT_EQ(rx.Receive(rf, 10), std::make_error_code(std::errc::timed_out));
}

TEST_F(VcanTest, FiltersSelectByIdFormatAndInverse) {
  CanTransportOptions opt;
  opt.filters = {{.id = 0x100, .mask = 0x7F0},
                 {.id = 0x18DAF100, .mask = 0x1FFFFF00, .extended = true}};
  SocketCanTransport rx = SocketCanTransport::Open(iface_, opt);
  CanTransportOptions inv;
  inv.filters = {{.id = 0x105, .mask = 0x7FF, .inverse = true}};
  SocketCanTransport rx_inverse = SocketCanTransport::Open(iface_, inv);
  SocketCanTransport tx = SocketCanTransport::Open(iface_);

  const std::vector<std::uint8_t> b{1};
  ASSERT_FALSE(tx.Send(CanFrame::Classic(0x105, b)));             // passes filter 1
  ASSERT_FALSE(tx.Send(CanFrame::Classic(0x205, b)));             // id differs
  ASSERT_FALSE(tx.Send(CanFrame::Classic(0x105, b, true)));       // 29-bit, filter 1 is 11-bit
  ASSERT_FALSE(tx.Send(CanFrame::Classic(0x18DAF1AA, b, true)));  // passes filter 2
  ASSERT_FALSE(tx.Send(CanFrame::Classic(0x18DAF2AA, b, true)));  // id differs

  EXPECT_EQ(Ids(Drain(rx)), (std::vector<std::uint32_t>{0x105, 0x18DAF1AA}));
  // The inverse filter drops only the 11-bit 0x105.
  EXPECT_EQ(Ids(Drain(rx_inverse)),
            (std::vector<std::uint32_t>{0x205, 0x105, 0x18DAF1AA, 0x18DAF2AA}));
}

TEST_F(VcanTest, FdFramesNeedTheFdOption) {
  CanTransportOptions fd;
  fd.fd_frames = true;
  SocketCanTransport tx = SocketCanTransport::Open(iface_, fd);
  SocketCanTransport rx = SocketCanTransport::Open(iface_, fd);
  SocketCanTransport rx_classic = SocketCanTransport::Open(iface_);
  SocketCanTransport tx_classic = SocketCanTransport::Open(iface_);

  const CanFrame big = Fd(0x42, 64, CANFD_BRS);
  const CanFrame small = Fd(0x1ABCDE, 8, 0, true);
  ASSERT_FALSE(tx.Send(big));
  ASSERT_FALSE(tx.Send(small));
  ASSERT_FALSE(tx.Send(CanFrame::Classic(0x43, std::vector<std::uint8_t>{7})));
  const std::vector<ReceivedFrame> got = Drain(rx);
  ASSERT_EQ(got.size(), 3u);
  EXPECT_EQ(got[0].frame, big);
  EXPECT_EQ(got[0].frame.fd_flags, CANFD_BRS);
  EXPECT_EQ(got[1].frame, small);
  EXPECT_FALSE(got[2].frame.fd);
  // A socket without CAN_RAW_FD_FRAMES sees only the classic frame and cannot send FD.
  EXPECT_EQ(Ids(Drain(rx_classic)), (std::vector<std::uint32_t>{0x43}));
  EXPECT_EQ(tx_classic.Send(big), std::make_error_code(std::errc::operation_not_supported));
  EXPECT_EQ(tx_classic.stats().send_failures, 1u);
}

TEST_F(VcanTest, OwnMessagesOnlyWhenAskedFor) {
  CanTransportOptions own;
  own.receive_own = true;
  SocketCanTransport self = SocketCanTransport::Open(iface_, own);
  SocketCanTransport plain = SocketCanTransport::Open(iface_);
  ASSERT_FALSE(self.Send(CanFrame::Classic(0x11, std::vector<std::uint8_t>{1})));
  ASSERT_FALSE(plain.Send(CanFrame::Classic(0x22, std::vector<std::uint8_t>{2})));
  // Order-insensitive: this is about who sees what (the kernel also keeps the two in order).
  EXPECT_THAT(Ids(Drain(self)), UnorderedElementsAre(0x11u, 0x22u));
  EXPECT_EQ(Ids(Drain(plain)), (std::vector<std::uint32_t>{0x11}));
}

TEST_F(VcanTest, LoopbackOffHidesFramesFromLocalSockets) {
  CanTransportOptions quiet;
  quiet.loopback = false;
  SocketCanTransport tx = SocketCanTransport::Open(iface_, quiet);
  SocketCanTransport rx = SocketCanTransport::Open(iface_);
  ASSERT_FALSE(tx.Send(CanFrame::Classic(0x33, std::vector<std::uint8_t>{3})));
  EXPECT_TRUE(Drain(rx, 50).empty());
  EXPECT_EQ(tx.stats().sent, 1u);
}

TEST_F(VcanTest, ErrorFramesReachOnlySocketsWithAnErrorMask) {
  CanTransportOptions errs;
  errs.error_mask = CAN_ERR_MASK;
  SocketCanTransport rx_errors = SocketCanTransport::Open(iface_, errs);
  SocketCanTransport rx_plain = SocketCanTransport::Open(iface_);
  SocketCanTransport tx = SocketCanTransport::Open(iface_);
  // vcan has no controller to raise errors; an error frame written to it loops back like one.
  const CanFrame err = ErrorFrame(CAN_ERR_CRTL);
  ASSERT_FALSE(tx.Send(err));
  const std::vector<ReceivedFrame> got = Drain(rx_errors);
  ASSERT_EQ(got.size(), 1u);
  EXPECT_TRUE(got[0].frame.error);
  EXPECT_EQ(got[0].frame.id, CAN_ERR_CRTL);
  EXPECT_EQ(got[0].frame.data[1], CAN_ERR_CRTL_RX_WARNING);
  EXPECT_TRUE(Drain(rx_plain, 50).empty());
}

TEST_F(VcanTest, KernelTimestampsArePresentAndNonDecreasing) {
  SocketCanTransport tx = SocketCanTransport::Open(iface_);
  SocketCanTransport rx = SocketCanTransport::Open(iface_);
  constexpr int kFrames = 50;
  for (int i = 0; i < kFrames; ++i) {
    ASSERT_FALSE(tx.Send(CanFrame::Classic(0x100 + i, std::vector<std::uint8_t>{1})));
  }
  const std::vector<ReceivedFrame> got = Drain(rx);
  ASSERT_EQ(got.size(), static_cast<std::size_t>(kFrames));
  for (int i = 0; i < kFrames; ++i) {
    EXPECT_TRUE(got[i].kernel_timestamp) << i;
    EXPECT_GT(got[i].timestamp_ns, 1'000'000'000LL * 1'000'000'000LL) << i;  // after 2001
    if (i > 0) {
      EXPECT_GE(got[i].timestamp_ns, got[i - 1].timestamp_ns) << i;
    }
    EXPECT_EQ(got[i].frame.id, 0x100u + i);
  }
}

// The kernel's SO_TIMESTAMPING on a CAN socket, which the userspace bus copies (its twin is
// UcanBusTest.SoTimestampingDeliversTheSoftwareStampOfSoTimestampns): with the reporting flag,
// an SCM_TIMESTAMPING after the SCM_TIMESTAMPNS, software stamp equal to it, the others zero;
// generation alone reports nothing; SO_PEEK_OFF is not for CAN sockets.
TEST_F(VcanTest, SoTimestampingReportsTheSoftwareStampAfterSoTimestampns) {
  auto open = [&] {
    const int s = ::socket(PF_CAN, SOCK_RAW, CAN_RAW);
    EXPECT_GE(s, 0);
    sockaddr_can addr{};
    addr.can_family = AF_CAN;
    addr.can_ifindex = static_cast<int>(::if_nametoindex(iface_.c_str()));
    EXPECT_EQ(::bind(s, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)), 0);
    return s;
  };
  auto set = [](int s, int opt, int v) {
    return ::setsockopt(s, SOL_SOCKET, opt, &v, sizeof(v)) == 0;
  };
  const int tx = open(), rx = open(), quiet = open();
  ASSERT_TRUE(set(rx, SO_TIMESTAMPNS, 1));
  ASSERT_TRUE(set(rx, SO_TIMESTAMPING, testing::kSoftwareRxStamps));
  ASSERT_TRUE(set(quiet, SO_TIMESTAMPING, SOF_TIMESTAMPING_RX_SOFTWARE));
  EXPECT_FALSE(set(rx, SO_PEEK_OFF, 0));
  EXPECT_EQ(errno, EOPNOTSUPP);
  can_frame out{};
  out.can_id = 0x123;
  out.len = 1;
  ASSERT_EQ(::write(tx, &out, sizeof(out)), static_cast<ssize_t>(sizeof(out)));
  EXPECT_GT(testing::ExpectSoftwareTimestamping(rx, quiet), 0);
  for (int s : {tx, rx, quiet}) ::close(s);
}

TEST_F(VcanTest, MissingInterfaceIsNamed) {
  EXPECT_THAT(
      [] { (void)SocketCanTransport::Open("vcan9"); },
      ThrowsMessage<std::system_error>(HasSubstr("CAN interface 'vcan9' not found (ENODEV)")));
}

TEST_F(VcanTest, NonCanInterfaceIsNamed) {
  EXPECT_THAT([] { (void)SocketCanTransport::Open("lo"); },
              ThrowsMessage<std::system_error>(HasSubstr("'lo' is not a CAN interface")));
}

TEST_F(VcanTest, DownInterfaceSaysHowToBringItUp) {
  if (iface2_.empty()) GTEST_SKIP() << "set WHEELHIL_VCAN2 to a second vcan this test may down";
  const int err = SetLinkUp(iface2_, false);
  if (err != 0) {
    GTEST_SKIP() << "cannot set " << iface2_ << " down (" << std::strerror(err)
                 << "): needs root and a kernel interface";
  }
  const std::string expected =
      "CAN interface '" + iface2_ + "' is down: ip link set " + iface2_ + " up";
  EXPECT_THAT([&] { (void)SocketCanTransport::Open(iface2_); },
              ThrowsMessage<std::system_error>(HasSubstr(expected)));
  ASSERT_EQ(SetLinkUp(iface2_, true), 0);
  EXPECT_NO_THROW((void)SocketCanTransport::Open(iface2_));
}

TEST_F(VcanTest, MovedFromTransportIsInert) {
  SocketCanTransport a = SocketCanTransport::Open(iface_);
  const int fd = a.fd();
  SocketCanTransport b = std::move(a);
  EXPECT_EQ(b.fd(), fd);
  EXPECT_EQ(a.fd(), -1);  // NOLINT(bugprone-use-after-move): documented moved-from state.
  EXPECT_EQ(a.Send(CanFrame::Classic(1, {})), std::make_error_code(std::errc::bad_file_descriptor));
  EXPECT_FALSE(b.Send(CanFrame::Classic(1, {})));
}

TEST_F(VcanTest, KernelReceiveQueueOverflowIsCounted) {
  SocketCanTransport tx = SocketCanTransport::Open(iface_);
  SocketCanTransport rx = SocketCanTransport::Open(iface_);
  const int tiny = 1;  // The kernel rounds it up to its minimum, a few frames' worth.
  ASSERT_EQ(::setsockopt(rx.fd(), SOL_SOCKET, SO_RCVBUF, &tiny, sizeof(tiny)), 0);
  constexpr std::size_t kFrames = 200;
  for (std::size_t i = 0; i < kFrames; ++i) ASSERT_FALSE(tx.Send(CanFrame::Classic(0x200, {})));
  const std::vector<ReceivedFrame> got = Drain(rx);
  ASSERT_FALSE(got.empty());
  if (got.size() == kFrames && std::getenv("WHEELHIL_UML") == nullptr) {
    GTEST_SKIP() << "SO_RCVBUF did not limit the receive queue (not a kernel CAN socket?)";
  }
  EXPECT_LT(got.size(), kFrames);
  // The kernel reports the drop count with the next frame that does get queued.
  ASSERT_FALSE(tx.Send(CanFrame::Classic(0x201, {})));
  ReceivedFrame next;
  ASSERT_FALSE(rx.Receive(next, 1000));
  EXPECT_EQ(next.frame.id, 0x201u);
  EXPECT_EQ(rx.stats().received, got.size() + 1);
  EXPECT_EQ(rx.stats().rx_kernel_drops, kFrames - got.size());
}

TEST_F(VcanTest, OneThreadSendsWhileAnotherReceives) {
  CanTransportOptions own;
  own.receive_own = true;
  SocketCanTransport bus = SocketCanTransport::Open(iface_, own);
  constexpr std::uint32_t kFrames = 100;
  std::vector<std::uint32_t> ids;
  std::thread reader([&] {
    ReceivedFrame rf;
    while (ids.size() < kFrames && !bus.Receive(rf, 2000)) ids.push_back(rf.frame.id);
  });
  std::uint32_t send_errors = 0;
  for (std::uint32_t i = 0; i < kFrames; ++i) {
    send_errors += bus.Send(CanFrame::Classic(0x300 + i, {})) ? 1 : 0;
  }
  reader.join();
  EXPECT_EQ(send_errors, 0u);
  ASSERT_EQ(ids.size(), kFrames);
  for (std::uint32_t i = 0; i < kFrames; ++i) EXPECT_EQ(ids[i], 0x300 + i);
  EXPECT_EQ(bus.stats().sent, kFrames);
  EXPECT_EQ(bus.stats().received, kFrames);
}

// A netem queue of one frame that holds each frame a while makes the second of two back-to-back
// writes fail with ENOBUFS: without retries Send() reports it, with retries every frame gets out.
class VcanQueueFullTest : public VcanTest {
 protected:
  void SetUp() override {
    VcanTest::SetUp();
    if (IsSkipped()) return;
    if (iface2_.empty()) GTEST_SKIP() << "set WHEELHIL_VCAN2 to a second vcan";
  }
  void TearDown() override {
    if (qdisc_) (void)std::system(("tc qdisc del dev " + iface2_ + " root 2>/dev/null").c_str());
  }
  // Returns false (and the test should skip) when the qdisc cannot be installed.
  bool InstallQdisc(const std::string& spec) {
    const std::string cmd = "tc qdisc replace dev " + iface2_ + " root " + spec;
    if (std::system((cmd + " 2>/dev/null").c_str()) != 0) return false;
    qdisc_ = true;
    return true;
  }
  bool InstallNetem(int delay_ms) {
    return InstallQdisc("netem delay " + std::to_string(delay_ms) + "ms limit 1");
  }
  static constexpr const char* kNoNetem = "`tc qdisc ... netem` failed (needs root, tc, sch_netem)";
  bool qdisc_ = false;
};

TEST_F(VcanQueueFullTest, WithoutRetriesEnobufsIsReturnedAndCounted) {
  // 200 ms: the queue stays full for the whole loop below, however slowly the guest runs.
  if (!InstallNetem(200)) GTEST_SKIP() << kNoNetem;
  CanTransportOptions no_retry;
  no_retry.send_retry_limit = 0;
  SocketCanTransport tx = SocketCanTransport::Open(iface2_, no_retry);
  ASSERT_FALSE(tx.Send(CanFrame::Classic(0x1, {})));
  std::error_code ec;
  for (int i = 0; i < 10 && !ec; ++i) ec = tx.Send(CanFrame::Classic(0x2, {}));
  EXPECT_EQ(ec, std::error_code(ENOBUFS, std::system_category()));
  EXPECT_EQ(tx.stats().send_failures, 1u);
  EXPECT_EQ(tx.stats().send_retries, 0u);
}

TEST_F(VcanQueueFullTest, RetriesGetEveryFrameOutInOrder) {
  if (!InstallNetem(5)) GTEST_SKIP() << kNoNetem;
  CanTransportOptions retry;
  retry.send_retry_limit = 30;
  retry.send_retry_budget_us = 500'000;
  SocketCanTransport tx = SocketCanTransport::Open(iface2_, retry);
  SocketCanTransport rx = SocketCanTransport::Open(iface2_);
  constexpr std::uint32_t kFrames = 5;
  for (std::uint32_t i = 0; i < kFrames; ++i) {
    ASSERT_FALSE(tx.Send(CanFrame::Classic(0x10 + i, {}))) << i;
  }
  EXPECT_GT(tx.stats().send_retries, 0u);
  EXPECT_EQ(tx.stats().send_failures, 0u);
  EXPECT_EQ(tx.stats().sent, kFrames);
  EXPECT_EQ(Ids(Drain(rx)), (std::vector<std::uint32_t>{0x10, 0x11, 0x12, 0x13, 0x14}));
}

TEST_F(VcanQueueFullTest, WithoutRetriesFullSendBufferIsEagain) {
  if (!InstallQdisc("tbf rate 16kbit burst 100 limit 10000")) {
    GTEST_SKIP() << "`tc qdisc ... tbf` failed (needs root, tc, sch_tbf)";
  }
  CanTransportOptions no_retry;
  no_retry.send_retry_limit = 0;
  SocketCanTransport tx = SocketCanTransport::Open(iface2_, no_retry);
  const int tiny = 1;
  ASSERT_EQ(::setsockopt(tx.fd(), SOL_SOCKET, SO_SNDBUF, &tiny, sizeof(tiny)), 0);
  std::error_code ec;
  for (int i = 0; i < 100 && !ec; ++i) ec = tx.Send(CanFrame::Classic(0x4FF, {}));
  EXPECT_EQ(ec, std::errc::resource_unavailable_try_again) << ec.message();
  EXPECT_EQ(tx.stats().send_failures, 1u);
}

// A slow token bucket keeps frames (and the send-buffer memory they are charged to) in the
// device queue; with the smallest SO_SNDBUF, writes fail with EAGAIN until frames leave, and
// Send() waits for POLLOUT instead of failing.
TEST_F(VcanQueueFullTest, FullSendBufferIsWaitedOut) {
  if (!InstallQdisc("tbf rate 16kbit burst 100 limit 10000")) {
    GTEST_SKIP() << "`tc qdisc ... tbf` failed (needs root, tc, sch_tbf)";
  }
  CanTransportOptions retry;
  retry.send_retry_limit = 100;
  retry.send_retry_budget_us = 2'000'000;
  SocketCanTransport tx = SocketCanTransport::Open(iface2_, retry);
  SocketCanTransport rx = SocketCanTransport::Open(iface2_);
  const int tiny = 1;  // Rounded up by the kernel to its minimum, a few frames.
  ASSERT_EQ(::setsockopt(tx.fd(), SOL_SOCKET, SO_SNDBUF, &tiny, sizeof(tiny)), 0);
  constexpr std::uint32_t kFrames = 40;
  std::vector<std::uint32_t> expected;
  for (std::uint32_t i = 0; i < kFrames; ++i) {
    ASSERT_FALSE(tx.Send(CanFrame::Classic(0x400 + i, {}))) << i;
    expected.push_back(0x400 + i);
  }
  EXPECT_GT(tx.stats().send_retries, 0u);
  EXPECT_EQ(tx.stats().send_failures, 0u);
  EXPECT_EQ(Ids(Drain(rx, 2000)), expected);
}

}  // namespace
}  // namespace wheelhil::bus
