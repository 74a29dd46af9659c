// The userspace CAN bus through the plain SocketCAN API: this binary links
// libwheelhil_ucan.so, so socket(PF_CAN)/bind/read/write/... reach an in-process UcanBroker in
// a private temp runtime dir. "Not delivered" is always checked with a sentinel frame sent
// after it (one global order per bus), never by waiting.

#include "bus/ucan_broker.h"

#include <fcntl.h>
#include <linux/can/error.h>
#include <linux/close_range.h>
#include <linux/filter.h>
#include <linux/net_tstamp.h>
#include <linux/sockios.h>
#include <sys/epoll.h>
#include <sys/ioctl.h>
#include <sys/syscall.h>
#include <sys/uio.h>
#include <sys/un.h>
#include <sys/wait.h>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <array>
#include <atomic>
#include <cerrno>
#include <random>
#include <thread>

#include "bus/ucan_protocol.h"
#include "bus/ucan_runtime_dir.h"
#include "tests/bus/timestamping_expectations.h"
#include "tests/bus/ucan_test_util.h"

namespace wheelhil::bus {
namespace {

using testing::Frame;
using testing::OpenCan;
using testing::Receive;
using testing::Send;
using testing::SetInt;
constexpr canid_t kSentinel = 0x7FF;
constexpr canid_t kNothing = 0xFFFFFFFFu;

class UcanBusTest : public ::testing::Test {
 protected:
  UcanBusTest() : broker_(testing::TestBrokerOptions(dir_.path(), 8192)) {
    broker_.AddBus("ucan0");
    broker_.AddBus("ucan1");
  }
  UcanBusStats StatsOf(const std::string& name) const {
    for (const auto& s : broker_.Stats()) {
      if (s.name == name) return s;
    }
    return {};
  }

  testing::TempRuntimeDir dir_;
  UcanBroker broker_;
};

TEST_F(UcanBusTest, InterfaceIndexesAreStableAndResolveBothWays) {
  EXPECT_EQ(if_nametoindex("ucan0"), 1000u);
  EXPECT_EQ(if_nametoindex("ucan1"), 1001u);
  EXPECT_EQ(broker_.AddBus("chassis"), 2000);
  EXPECT_EQ(broker_.AddBus("ucan0"), 1000);  // idempotent
  char name[IF_NAMESIZE] = {};
  ASSERT_NE(if_indextoname(1001, name), nullptr);
  EXPECT_STREQ(name, "ucan1");
  const int fd = ::socket(PF_CAN, SOCK_RAW, CAN_RAW);
  ASSERT_GE(fd, 0);
  ifreq ifr{};
  std::strcpy(ifr.ifr_name, "chassis");
  ASSERT_EQ(::ioctl(fd, SIOCGIFINDEX, &ifr), 0);
  EXPECT_EQ(ifr.ifr_ifindex, 2000);
  ifr.ifr_ifindex = 1000;
  ASSERT_EQ(::ioctl(fd, SIOCGIFNAME, &ifr), 0);
  EXPECT_STREQ(ifr.ifr_name, "ucan0");
  ::close(fd);
  EXPECT_TRUE(broker_.RemoveBus("chassis"));
  EXPECT_EQ(broker_.AddBus("chassis"), 2000);  // a re-added bus keeps its index
  EXPECT_THROW(broker_.AddBus("bad/name"), std::invalid_argument);
}

TEST_F(UcanBusTest, KernelNamesPassThroughWithTheKernelsError) {
  EXPECT_EQ(if_nametoindex("vcan0"), 0u);
  const int fd = ::socket(PF_CAN, SOCK_RAW, CAN_RAW);
  ASSERT_GE(fd, 0);
  ifreq ifr{};
  std::strcpy(ifr.ifr_name, "vcan0");
  EXPECT_EQ(::ioctl(fd, SIOCGIFINDEX, &ifr), -1);
  EXPECT_EQ(errno, ENODEV);
  // Index 1 is "lo": not a ucan bus, so bind asks the kernel for a real PF_CAN socket.
  sockaddr_can addr{};
  addr.can_family = AF_CAN;
  addr.can_ifindex = 1;
  const int rc = ::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr));
  EXPECT_EQ(rc, -1);
  EXPECT_THAT(errno, ::testing::AnyOf(EAFNOSUPPORT, ENODEV, EINVAL));
  ::close(fd);
}

TEST_F(UcanBusTest, FrameReachesEveryOtherSocketButNotTheSender) {
  const int a = OpenCan("ucan0"), b = OpenCan("ucan0"), c = OpenCan("ucan0");
  const int other_bus = OpenCan("ucan1");
  ASSERT_GE(a, 0);
  ASSERT_GE(b, 0);
  ASSERT_GE(c, 0);
  ASSERT_GE(other_bus, 0);
  ASSERT_TRUE(Send(a, Frame(0x123, {1, 2, 3})));
  for (int r : {b, c}) {
    const can_frame f = Receive(r);
    EXPECT_EQ(f.can_id, 0x123u);
    EXPECT_EQ(f.can_dlc, 3);
    EXPECT_EQ(f.data[2], 3);
  }
  ASSERT_TRUE(Send(b, Frame(kSentinel)));
  EXPECT_EQ(Receive(a).can_id, kSentinel);  // a never saw its own 0x123
  ASSERT_TRUE(Send(other_bus, Frame(0x55)));
  ASSERT_TRUE(Send(a, Frame(kSentinel)));
  EXPECT_EQ(Receive(b).can_id, kSentinel);  // 0x55 stayed on ucan1
  EXPECT_EQ(StatsOf("ucan0").clients, 3u);
  EXPECT_EQ(StatsOf("ucan0").frames, 3u);
  for (int fd : {a, b, c, other_bus}) ::close(fd);
}

TEST_F(UcanBusTest, RecvOwnMsgsAndMessageFlags) {
  const int a = OpenCan("ucan0"), b = OpenCan("ucan0");
  ASSERT_TRUE(SetInt(a, SOL_CAN_RAW, CAN_RAW_RECV_OWN_MSGS, 1));
  int v = 0;
  socklen_t len = sizeof(v);
  ASSERT_EQ(::getsockopt(a, SOL_CAN_RAW, CAN_RAW_RECV_OWN_MSGS, &v, &len), 0);
  EXPECT_EQ(v, 1);
  ASSERT_TRUE(Send(a, Frame(0x10)));
  ASSERT_TRUE(Send(b, Frame(0x20)));
  for (canid_t want : {0x10u, 0x20u}) {
    can_frame f{};
    iovec iov{&f, sizeof(f)};
    sockaddr_can from{};
    msghdr msg{};
    msg.msg_name = &from;
    msg.msg_namelen = sizeof(from);
    msg.msg_iov = &iov;
    msg.msg_iovlen = 1;
    ASSERT_TRUE(testing::Readable(a, 2000));
    ASSERT_EQ(::recvmsg(a, &msg, 0), static_cast<ssize_t>(sizeof(f)));
    EXPECT_EQ(f.can_id, want);
    EXPECT_EQ(from.can_family, AF_CAN);
    EXPECT_EQ(from.can_ifindex, 1000);
    EXPECT_EQ(msg.msg_namelen, sizeof(sockaddr_can));
    EXPECT_TRUE(msg.msg_flags & MSG_DONTROUTE);
    EXPECT_EQ((msg.msg_flags & MSG_CONFIRM) != 0, want == 0x10u) << std::hex << want;
  }
  ::close(a);
  ::close(b);
}

TEST_F(UcanBusTest, LoopbackOffHidesFramesFromSocketsOfTheSameProcess) {
  const int a = OpenCan("ucan0"), b = OpenCan("ucan0");
  ASSERT_TRUE(SetInt(a, SOL_CAN_RAW, CAN_RAW_LOOPBACK, 0));
  ASSERT_TRUE(Send(a, Frame(0x100)));
  ASSERT_TRUE(SetInt(a, SOL_CAN_RAW, CAN_RAW_LOOPBACK, 1));
  ASSERT_TRUE(Send(a, Frame(kSentinel)));
  EXPECT_EQ(Receive(b).can_id, kSentinel);
  ::close(a);
  ::close(b);
}

TEST_F(UcanBusTest, FiltersMatchLikeTheKernel) {
  const int tx = OpenCan("ucan0");
  const int plain = OpenCan("ucan0"), inverse = OpenCan("ucan0"), eff = OpenCan("ucan0");
  const int joined = OpenCan("ucan0"), none = OpenCan("ucan0");
  const can_filter range[] = {{0x100, 0x7F0}, {kSentinel, CAN_SFF_MASK}};
  ASSERT_EQ(::setsockopt(plain, SOL_CAN_RAW, CAN_RAW_FILTER, range, sizeof(range)), 0);
  const can_filter inv[] = {{0x100 | CAN_INV_FILTER, 0x700}};
  ASSERT_EQ(::setsockopt(inverse, SOL_CAN_RAW, CAN_RAW_FILTER, inv, sizeof(inv)), 0);
  // Only extended frames with id 0x12345 (EFF flag in the mask makes the format count).
  const can_filter ext[] = {{0x12345 | CAN_EFF_FLAG, CAN_EFF_MASK | CAN_EFF_FLAG},
                            {kSentinel, CAN_SFF_MASK | CAN_EFF_FLAG}};
  ASSERT_EQ(::setsockopt(eff, SOL_CAN_RAW, CAN_RAW_FILTER, ext, sizeof(ext)), 0);
  // Joined: id must match 0x1x0 AND have bit 0x008 set -> 0x108 only of those sent below.
  const can_filter both[] = {{0x100, 0x700}, {0x008, 0x008}};
  ASSERT_EQ(::setsockopt(joined, SOL_CAN_RAW, CAN_RAW_FILTER, both, sizeof(both)), 0);
  ASSERT_TRUE(SetInt(joined, SOL_CAN_RAW, CAN_RAW_JOIN_FILTERS, 1));
  ASSERT_EQ(::setsockopt(none, SOL_CAN_RAW, CAN_RAW_FILTER, nullptr, 0), 0);
  can_filter got[4] = {};
  socklen_t len = sizeof(got);
  ASSERT_EQ(::getsockopt(plain, SOL_CAN_RAW, CAN_RAW_FILTER, got, &len), 0);
  EXPECT_EQ(len, sizeof(range));
  EXPECT_EQ(got[0].can_mask, 0x7F0u);

  for (canid_t id : {0x105u, 0x205u, 0x108u, 0x12345u | CAN_EFF_FLAG, 0x345u}) {
    ASSERT_TRUE(Send(tx, Frame(id)));
  }
  ASSERT_TRUE(Send(tx, Frame(kSentinel)));
  ASSERT_TRUE(Send(tx, Frame(0x1F8)));  // the joined socket's sentinel; nobody else takes it
  auto drain = [](int fd, canid_t last = kSentinel) {
    std::vector<canid_t> ids;
    for (;;) {
      const can_frame f = Receive(fd);
      ids.push_back(f.can_id);
      if (f.can_id == last || f.can_id == kNothing) return ids;
    }
  };
  using V = std::vector<canid_t>;
  EXPECT_EQ(drain(plain), (V{0x105, 0x108, kSentinel}));
  EXPECT_EQ(drain(inverse), (V{0x205, 0x12345u | CAN_EFF_FLAG, 0x345, kSentinel}));
  EXPECT_EQ(drain(eff), (V{0x12345u | CAN_EFF_FLAG, kSentinel}));
  EXPECT_EQ(drain(joined, 0x1F8), (V{0x108, 0x1F8}));
  EXPECT_TRUE(testing::NothingPending(none));

  // Changing the filter of a bound socket takes effect for the next frame.
  const can_filter only_300[] = {{0x300, CAN_SFF_MASK}};
  ASSERT_EQ(::setsockopt(plain, SOL_CAN_RAW, CAN_RAW_FILTER, only_300, sizeof(only_300)), 0);
  ASSERT_TRUE(Send(tx, Frame(0x105)));
  ASSERT_TRUE(Send(tx, Frame(0x300)));
  EXPECT_EQ(Receive(plain).can_id, 0x300u);
  for (int fd : {tx, plain, inverse, eff, joined, none}) ::close(fd);
}

TEST_F(UcanBusTest, ErrorFramesOnlyThroughTheErrorMask) {
  const int tx = OpenCan("ucan0"), busoff = OpenCan("ucan0"), ctrl = OpenCan("ucan0");
  const int plain = OpenCan("ucan0");
  const can_err_mask_t m1 = CAN_ERR_BUSOFF, m2 = CAN_ERR_CRTL;
  ASSERT_EQ(::setsockopt(busoff, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &m1, sizeof(m1)), 0);
  ASSERT_EQ(::setsockopt(ctrl, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &m2, sizeof(m2)), 0);
  ASSERT_TRUE(Send(tx, Frame(CAN_ERR_FLAG | CAN_ERR_BUSOFF, {0, 0, 0, 0, 0, 0, 0, 0})));
  ASSERT_TRUE(Send(tx, Frame(kSentinel)));
  EXPECT_EQ(Receive(busoff).can_id, CAN_ERR_FLAG | CAN_ERR_BUSOFF);
  EXPECT_EQ(Receive(ctrl).can_id, kSentinel);
  EXPECT_EQ(Receive(plain).can_id, kSentinel);
  for (int fd : {tx, busoff, ctrl, plain}) ::close(fd);
}

TEST_F(UcanBusTest, FdFramesAndMtuChecks) {
  const int classic = OpenCan("ucan0"), fd_tx = OpenCan("ucan0"), fd_rx = OpenCan("ucan0");
  ASSERT_TRUE(SetInt(fd_tx, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, 1));
  ASSERT_TRUE(SetInt(fd_rx, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, 1));
  canfd_frame fd{};
  fd.can_id = 0x42;
  fd.len = 64;
  fd.flags = CANFD_BRS;
  fd.data[63] = 0xAB;
  EXPECT_EQ(::write(classic, &fd, sizeof(fd)), -1);  // FD frame on a non-FD socket
  EXPECT_EQ(errno, EINVAL);
  EXPECT_EQ(::write(classic, &fd, 10), -1);  // neither CAN_MTU nor CANFD_MTU
  EXPECT_EQ(errno, EINVAL);
  can_frame too_long = Frame(0x1);
  too_long.can_dlc = 9;
  EXPECT_EQ(::write(classic, &too_long, sizeof(too_long)), -1);
  EXPECT_EQ(errno, EINVAL);
  ASSERT_EQ(::write(fd_tx, &fd, sizeof(fd)), static_cast<ssize_t>(sizeof(fd)));
  ASSERT_TRUE(Send(fd_tx, Frame(kSentinel)));
  canfd_frame got{};
  ASSERT_TRUE(testing::Readable(fd_rx, 2000));
  ASSERT_EQ(::read(fd_rx, &got, sizeof(got)), static_cast<ssize_t>(CANFD_MTU));
  EXPECT_EQ(got.len, 64);
  EXPECT_EQ(got.flags, CANFD_BRS);
  EXPECT_EQ(got.data[63], 0xAB);
  ASSERT_TRUE(testing::Readable(fd_rx, 2000));
  EXPECT_EQ(::read(fd_rx, &got, sizeof(got)), static_cast<ssize_t>(CAN_MTU));  // classic: 16
  EXPECT_EQ(Receive(classic).can_id, kSentinel);  // the FD frame never reached it
  for (int s : {classic, fd_tx, fd_rx}) ::close(s);
}

TEST_F(UcanBusTest, TimestampsAreMonotonicAndMatchSiocgstamp) {
  const int tx = OpenCan("ucan0"), rx = OpenCan("ucan0"), rx_us = OpenCan("ucan0");
  ASSERT_TRUE(SetInt(rx, SOL_SOCKET, SO_TIMESTAMPNS, 1));
  ASSERT_TRUE(SetInt(rx_us, SOL_SOCKET, SO_TIMESTAMP, 1));
  for (int i = 0; i < 50; ++i) ASSERT_TRUE(Send(tx, Frame(static_cast<canid_t>(i))));
  std::int64_t last_ns = 0;
  for (int i = 0; i < 50; ++i) {
    can_frame f{};
    iovec iov{&f, sizeof(f)};
    alignas(cmsghdr) char control[CMSG_SPACE(sizeof(timespec))];
    msghdr msg{};
    msg.msg_iov = &iov;
    msg.msg_iovlen = 1;
    msg.msg_control = control;
    msg.msg_controllen = sizeof(control);
    ASSERT_TRUE(testing::Readable(rx, 2000));
    ASSERT_EQ(::recvmsg(rx, &msg, 0), static_cast<ssize_t>(sizeof(f)));
    EXPECT_EQ(f.can_id, static_cast<canid_t>(i));
    cmsghdr* c = CMSG_FIRSTHDR(&msg);
    ASSERT_NE(c, nullptr);
    EXPECT_EQ(c->cmsg_level, SOL_SOCKET);
    EXPECT_EQ(c->cmsg_type, SCM_TIMESTAMPNS);
    timespec ts{};
    std::memcpy(&ts, CMSG_DATA(c), sizeof(ts));
    const std::int64_t ns = ts.tv_sec * 1000000000LL + ts.tv_nsec;
    EXPECT_GE(ns, last_ns);
    EXPECT_GT(ts.tv_sec, 1600000000);  // CLOCK_REALTIME, like the kernel
    last_ns = ns;
    EXPECT_EQ(CMSG_NXTHDR(&msg, c), nullptr);
  }
  timespec stamp{};
  ASSERT_EQ(::ioctl(rx, SIOCGSTAMPNS, &stamp), 0);
  EXPECT_EQ(stamp.tv_sec * 1000000000LL + stamp.tv_nsec, last_ns);
  // SO_TIMESTAMP: a timeval with the same instant in µs.
  can_frame f{};
  iovec iov{&f, sizeof(f)};
  alignas(cmsghdr) char control[CMSG_SPACE(sizeof(timeval))];
  msghdr msg{};
  msg.msg_iov = &iov;
  msg.msg_iovlen = 1;
  msg.msg_control = control;
  msg.msg_controllen = sizeof(control);
  ASSERT_TRUE(testing::Readable(rx_us, 2000));
  ASSERT_EQ(::recvmsg(rx_us, &msg, 0), static_cast<ssize_t>(sizeof(f)));
  cmsghdr* c = CMSG_FIRSTHDR(&msg);
  ASSERT_NE(c, nullptr);
  EXPECT_EQ(c->cmsg_type, SCM_TIMESTAMP);
  timeval tv{};
  std::memcpy(&tv, CMSG_DATA(c), sizeof(tv));
  EXPECT_GT(tv.tv_sec, 1600000000);
  EXPECT_LT(tv.tv_usec, 1000000);
  for (int s : {tx, rx, rx_us}) ::close(s);
}

// SO_TIMESTAMPING as on a kernel CAN socket: with SOF_TIMESTAMPING_SOFTWARE each frame carries
// an SCM_TIMESTAMPING after the SCM_TIMESTAMPNS, whose software stamp equals it and whose
// other two are zero (no hardware clock on the bus); the flags read back; flags the kernel
// refuses are refused; without the reporting flag nothing is added. Options the bus cannot
// honour are refused instead of acting on its connection to the broker.
TEST_F(UcanBusTest, SoTimestampingDeliversTheSoftwareStampOfSoTimestampns) {
  const int tx = OpenCan("ucan0"), rx = OpenCan("ucan0"), quiet = OpenCan("ucan0");
  const int flags = testing::kSoftwareRxStamps;
  ASSERT_TRUE(SetInt(rx, SOL_SOCKET, SO_TIMESTAMPNS, 1));
  ASSERT_TRUE(SetInt(rx, SOL_SOCKET, SO_TIMESTAMPING, flags));
  ASSERT_TRUE(SetInt(quiet, SOL_SOCKET, SO_TIMESTAMPING, SOF_TIMESTAMPING_RX_SOFTWARE));
  so_timestamping back{};
  socklen_t len = sizeof(back);
  ASSERT_EQ(::getsockopt(rx, SOL_SOCKET, SO_TIMESTAMPING, &back, &len), 0);
  EXPECT_EQ(len, sizeof(back));
  EXPECT_EQ(back.flags, flags);
  EXPECT_EQ(back.bind_phc, 0);
  EXPECT_FALSE(SetInt(rx, SOL_SOCKET, SO_TIMESTAMPING, SOF_TIMESTAMPING_MASK + 1));
  EXPECT_EQ(errno, EINVAL);
  EXPECT_FALSE(SetInt(rx, SOL_SOCKET, SO_TIMESTAMPING, flags | SOF_TIMESTAMPING_OPT_STATS));
  EXPECT_EQ(errno, EINVAL);
  EXPECT_FALSE(SetInt(rx, SOL_SOCKET, SO_PEEK_OFF, 0));
  EXPECT_EQ(errno, EOPNOTSUPP);
  sock_filter accept_all{0x06, 0, 0, 0xFFFFFFFF};  // BPF_RET | BPF_K
  sock_fprog prog{1, &accept_all};
  EXPECT_NE(::setsockopt(rx, SOL_SOCKET, SO_ATTACH_FILTER, &prog, sizeof(prog)), 0);
  EXPECT_EQ(errno, ENOPROTOOPT);

  for (int i = 0; i < 20; ++i) ASSERT_TRUE(Send(tx, Frame(static_cast<canid_t>(i))));
  for (int i = 0; i < 20; ++i) {
    ASSERT_TRUE(testing::Readable(rx, 2000));
    ASSERT_TRUE(testing::Readable(quiet, 2000));
    EXPECT_GT(testing::ExpectSoftwareTimestamping(rx, quiet), 1600000000LL * 1000000000LL);
  }
  for (int s : {tx, rx, quiet}) ::close(s);
}

TEST_F(UcanBusTest, PollAndEpollReportReadiness) {
  const int tx = OpenCan("ucan0"), rx = OpenCan("ucan0", SOCK_NONBLOCK);
  can_frame f{};
  EXPECT_EQ(::read(rx, &f, sizeof(f)), -1);
  EXPECT_EQ(errno, EAGAIN);
  pollfd p{rx, POLLIN, 0};
  EXPECT_EQ(::poll(&p, 1, 0), 0);
  p.revents = 0;
  EXPECT_EQ(::poll(&p, 1, 0), 0);
  const int ep = ::epoll_create1(EPOLL_CLOEXEC);
  epoll_event ev{};
  ev.events = EPOLLIN;
  ev.data.fd = rx;
  ASSERT_EQ(::epoll_ctl(ep, EPOLL_CTL_ADD, rx, &ev), 0);
  epoll_event out{};
  EXPECT_EQ(::epoll_wait(ep, &out, 1, 0), 0);
  ASSERT_TRUE(Send(tx, Frame(0x77)));
  ASSERT_EQ(::epoll_wait(ep, &out, 1, 2000), 1);
  EXPECT_EQ(out.data.fd, rx);
  EXPECT_EQ(::poll(&p, 1, 2000), 1);
  EXPECT_TRUE(p.revents & POLLIN);
  pollfd w{tx, POLLOUT, 0};
  EXPECT_EQ(::poll(&w, 1, 0), 1);  // writable
  EXPECT_EQ(::read(rx, &f, sizeof(f)), static_cast<ssize_t>(sizeof(f)));
  EXPECT_EQ(f.can_id, 0x77u);
  ::close(ep);
  ::close(tx);
  ::close(rx);
}

TEST_F(UcanBusTest, ManyReadersSeeOneGlobalOrder) {
  const int w1 = OpenCan("ucan0"), w2 = OpenCan("ucan0");
  std::vector<int> readers;
  for (int i = 0; i < 4; ++i) readers.push_back(OpenCan("ucan0"));
  constexpr int kPerWriter = 300;
  std::thread t1([&] {
    for (int i = 0; i < kPerWriter; ++i) Send(w1, Frame(0x100 + (i % 0x100), {1}));
  });
  std::thread t2([&] {
    for (int i = 0; i < kPerWriter; ++i) Send(w2, Frame(0x200 + (i % 0x100), {2}));
  });
  t1.join();
  t2.join();
  std::vector<std::vector<canid_t>> seen(readers.size());
  for (std::size_t r = 0; r < readers.size(); ++r) {
    for (int i = 0; i < 2 * kPerWriter; ++i) seen[r].push_back(Receive(readers[r]).can_id);
  }
  for (std::size_t r = 1; r < readers.size(); ++r) EXPECT_EQ(seen[r], seen[0]);
  // Each writer's own frames keep their order.
  std::vector<canid_t> from_w1;
  for (canid_t id : seen[0]) {
    if (id >= 0x100 && id < 0x200) from_w1.push_back(id);
  }
  ASSERT_EQ(from_w1.size(), static_cast<std::size_t>(kPerWriter));
  for (int i = 0; i < kPerWriter; ++i) EXPECT_EQ(from_w1[i], 0x100u + (i % 0x100));
  for (int fd : readers) ::close(fd);
  ::close(w1);
  ::close(w2);
}

// vcan: a write() that returned happens-before the next write(), so frames written back to back
// from one thread through two sockets reach every reader in that order. Each ucan socket is
// its own connection to the broker, whose epoll loop may service B's before A's.
TEST_F(UcanBusTest, BackToBackWritesThroughTwoSocketsKeepTheirOrder) {
  const int a = OpenCan("ucan0"), b = OpenCan("ucan0"), c = OpenCan("ucan0");
  ASSERT_GE(a, 0);
  ASSERT_GE(b, 0);
  ASSERT_GE(c, 0);
  constexpr int kIterations = 20000;
  constexpr int kChunk = 200;  // pairs in flight before C reads (well under C's queue)
  int reversed = 0;
  int lost = 0;
  for (int base = 0; base < kIterations; base += kChunk) {
    for (int i = base; i < base + kChunk; ++i) {
      const auto lo = static_cast<std::uint8_t>(i), hi = static_cast<std::uint8_t>(i >> 8);
      ASSERT_TRUE(Send(a, Frame(0x100, {lo, hi})));
      ASSERT_TRUE(Send(b, Frame(0x200, {lo, hi})));
    }
    // Expected: A(base) B(base) A(base+1) ...; count the places where the sequence goes back.
    int last_key = -1;
    for (int k = 0; k < 2 * kChunk; ++k) {
      const can_frame f = Receive(c);
      if (f.can_id == kNothing) {
        ++lost;
        break;
      }
      const int key = 2 * (f.data[0] | (f.data[1] << 8)) + (f.can_id == 0x200 ? 1 : 0);
      if (key < last_key) ++reversed;
      last_key = key;
    }
    if (lost > 0) break;
  }
  EXPECT_EQ(lost, 0);
  EXPECT_EQ(reversed, 0) << "of " << kIterations << " A-then-B pairs";
  ::close(a);
  ::close(b);
  ::close(c);
}

TEST(UcanBroker, SlowReaderDropsAreCountedAndNeverStallOthers) {
  testing::TempRuntimeDir dir;
  UcanBrokerOptions options;
  options.runtime_dir = dir.path();
  options.client_queue_limit = 16;
  UcanBroker broker(options);
  broker.AddBus("ucan0");
  const int tx = OpenCan("ucan0"), fast = OpenCan("ucan0"), slow = OpenCan("ucan0");
  ASSERT_TRUE(SetInt(slow, SOL_SOCKET, SO_RXQ_OVFL, 1));
  constexpr int kFrames = 5000;
  for (int i = 0; i < kFrames; ++i) {
    ASSERT_TRUE(Send(tx, Frame(static_cast<canid_t>(i & 0x7FF), {static_cast<std::uint8_t>(i)})));
    const can_frame f = Receive(fast);  // lock step: the fast reader never has a backlog
    ASSERT_EQ(f.can_id, static_cast<canid_t>(i & 0x7FF));
  }
  // Every frame is routed by now (the fast reader has them all): the drop count is final.
  const UcanBusStats stats = broker.Stats().at(0);
  EXPECT_GT(stats.drops, 0u);
  ASSERT_LT(stats.drops, static_cast<std::uint64_t>(kFrames));
  // What was not dropped is still queued (socket buffer + broker queue), in order.
  const int queued = kFrames - static_cast<int>(stats.drops);
  can_frame f{};
  for (int i = 0; i < queued; ++i) {
    f = Receive(slow);
    ASSERT_EQ(f.can_id, static_cast<canid_t>(i & 0x7FF)) << i;
  }
  // The next frame carries the reader's drop count (SO_RXQ_OVFL), like the kernel.
  ASSERT_TRUE(Send(tx, Frame(0x1)));
  ASSERT_TRUE(testing::Readable(slow, 2000));
  const auto drops = testing::ReceiveDropCount(slow, &f);
  EXPECT_EQ(f.can_id, 0x1u);
  ASSERT_TRUE(drops.has_value());
  EXPECT_EQ(*drops, stats.drops);
  for (int s : {tx, fast, slow}) ::close(s);
}

TEST_F(UcanBusTest, GarbageCrashedAndSilentClientsDoNotHurtOthers) {
  const int tx = OpenCan("ucan0"), rx = OpenCan("ucan0"), garbage = OpenCan("ucan0");
  const int never_reads = OpenCan("ucan0");
  ASSERT_GE(never_reads, 0);
  // Garbage on a data connection, bypassing the library's checks with raw syscalls.
  std::mt19937 rng(42);
  std::vector<std::uint8_t> junk(4000);
  for (auto& b : junk) b = static_cast<std::uint8_t>(rng());
  int bad = 0;
  for (std::size_t size : {1u, 15u, 17u, 71u, 73u, 100u, 4000u}) {
    ASSERT_EQ(::syscall(SYS_sendto, garbage, junk.data(), size, MSG_NOSIGNAL, nullptr, 0),
              static_cast<long>(size));
    ++bad;
  }
  can_frame dlc_too_big = Frame(0x1);
  dlc_too_big.can_dlc = 200;
  ASSERT_EQ(
      ::syscall(SYS_sendto, garbage, &dlc_too_big, sizeof(dlc_too_big), MSG_NOSIGNAL, nullptr, 0),
      static_cast<long>(sizeof(dlc_too_big)));
  ++bad;
  // Garbage as the first message of a fresh connection, then a broken-off connection.
  for (std::size_t size : {std::size_t{3}, sizeof(ucan::Request)}) {
    const int s = ::socket(AF_UNIX, SOCK_SEQPACKET, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::strcpy(addr.sun_path, broker_.socket_path().c_str());
    ASSERT_EQ(::connect(s, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)), 0);
    ASSERT_EQ(::send(s, junk.data(), size, MSG_NOSIGNAL), static_cast<ssize_t>(size));
    ::close(s);
  }
  // A client process killed in the middle of sending.
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    const int s = OpenCan("ucan0");
    for (int i = 0; i < 10; ++i) Send(s, Frame(0x600));
    ::raise(SIGKILL);
  }
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  // Everything still flows, in order, for the healthy pair.
  for (int i = 0; i < 10; ++i) ASSERT_EQ(Receive(rx).can_id, 0x600u);
  for (int i = 0; i < 100; ++i) ASSERT_TRUE(Send(tx, Frame(0x100 + i)));
  for (int i = 0; i < 100; ++i) ASSERT_EQ(Receive(rx).can_id, 0x100u + i);
  EXPECT_EQ(StatsOf("ucan0").bad_messages, static_cast<std::uint64_t>(bad));
  EXPECT_EQ(StatsOf("ucan0").clients, 4u);  // the killed child's socket is gone
  for (int s : {tx, rx, garbage, never_reads}) ::close(s);
}

TEST_F(UcanBusTest, BusDownGivesEnetdown) {
  const int rx = OpenCan("ucan1"), tx = OpenCan("ucan1");
  ASSERT_GE(rx, 0);
  ASSERT_TRUE(broker_.RemoveBus("ucan1"));
  can_frame f{};
  ASSERT_TRUE(testing::Readable(rx, 2000));  // EOF from the broker
  EXPECT_EQ(::read(rx, &f, sizeof(f)), -1);
  EXPECT_EQ(errno, ENETDOWN);
  EXPECT_FALSE(Send(tx, Frame(0x1)));
  EXPECT_EQ(errno, ENETDOWN);
  EXPECT_EQ(if_nametoindex("ucan1"), 0u);
  ::close(rx);
  ::close(tx);
}

TEST_F(UcanBusTest, AnySocketHearsAllBusesAndSendsByAddress) {
  const int any = OpenCan("");
  const int on0 = OpenCan("ucan0"), on1 = OpenCan("ucan1");
  ASSERT_GE(any, 0);
  // Order between buses is not defined: one bus at a time.
  for (auto [id, index] : {std::pair{0x10u, 1000}, std::pair{0x11u, 1001}}) {
    ASSERT_TRUE(Send(index == 1000 ? on0 : on1, Frame(id)));
    can_frame f{};
    sockaddr_can from{};
    socklen_t len = sizeof(from);
    ASSERT_TRUE(testing::Readable(any, 2000));
    ASSERT_EQ(::recvfrom(any, &f, sizeof(f), 0, reinterpret_cast<sockaddr*>(&from), &len),
              static_cast<ssize_t>(sizeof(f)));
    EXPECT_EQ(f.can_id, id);
    EXPECT_EQ(from.can_ifindex, index);
  }
  can_frame f = Frame(0x22);
  EXPECT_EQ(::write(any, &f, sizeof(f)), -1);  // no interface to send on
  EXPECT_EQ(errno, ENXIO);
  sockaddr_can to{};
  to.can_family = AF_CAN;
  to.can_ifindex = 1001;
  ASSERT_EQ(::sendto(any, &f, sizeof(f), 0, reinterpret_cast<sockaddr*>(&to), sizeof(to)),
            static_cast<ssize_t>(sizeof(f)));
  EXPECT_EQ(Receive(on1).can_id, 0x22u);
  sockaddr_can name{};
  socklen_t len = sizeof(name);
  ASSERT_EQ(::getsockname(on1, reinterpret_cast<sockaddr*>(&name), &len), 0);
  EXPECT_EQ(name.can_family, AF_CAN);
  EXPECT_EQ(name.can_ifindex, 1001);
  for (int s : {any, on0, on1}) ::close(s);
}

TEST_F(UcanBusTest, VectoredAndBatchedCalls) {
  const int tx = OpenCan("ucan0"), rx = OpenCan("ucan0");
  can_frame f = Frame(0x41, {7});
  iovec halves[2] = {{&f, 8}, {reinterpret_cast<std::uint8_t*>(&f) + 8, 8}};
  ASSERT_EQ(::writev(tx, halves, 2), static_cast<ssize_t>(sizeof(f)));
  std::array<can_frame, 3> out{Frame(0x42), Frame(0x43), Frame(0x44)};
  std::array<iovec, 3> iovs{};
  std::array<mmsghdr, 3> msgs{};
  for (std::size_t i = 0; i < 3; ++i) {
    iovs[i] = {&out[i], sizeof(can_frame)};
    msgs[i].msg_hdr.msg_iov = &iovs[i];
    msgs[i].msg_hdr.msg_iovlen = 1;
  }
  ASSERT_EQ(::sendmmsg(tx, msgs.data(), 3, 0), 3);
  can_frame got{};
  iovec in{&got, sizeof(got)};
  ASSERT_TRUE(testing::Readable(rx, 2000));
  ASSERT_EQ(::readv(rx, &in, 1), static_cast<ssize_t>(sizeof(got)));
  EXPECT_EQ(got.can_id, 0x41u);
  std::array<can_frame, 3> batch{};
  for (std::size_t i = 0; i < 3; ++i) {
    iovs[i] = {&batch[i], sizeof(can_frame)};
    msgs[i] = {};
    msgs[i].msg_hdr.msg_iov = &iovs[i];
    msgs[i].msg_hdr.msg_iovlen = 1;
  }
  ASSERT_EQ(::recvmmsg(rx, msgs.data(), 3, 0, nullptr), 3);  // waits for each
  EXPECT_EQ(batch[0].can_id, 0x42u);
  EXPECT_EQ(batch[2].can_id, 0x44u);
  EXPECT_EQ(msgs[2].msg_len, sizeof(can_frame));
  ::close(tx);
  ::close(rx);
}

TEST_F(UcanBusTest, DupSharesTheSocketAndCloseForgetsIt) {
  const int tx = OpenCan("ucan0"), rx = OpenCan("ucan0");
  const int copy = ::dup(tx);
  const int copy2 = ::fcntl(tx, F_DUPFD_CLOEXEC, 100);
  ASSERT_GE(copy2, 100);
  ::close(tx);
  ASSERT_TRUE(Send(copy, Frame(0x31)));
  ASSERT_TRUE(Send(copy2, Frame(0x32)));
  EXPECT_EQ(Receive(rx).can_id, 0x31u);
  EXPECT_EQ(Receive(rx).can_id, 0x32u);
  int type = 0, domain = 0;
  socklen_t len = sizeof(type);
  ASSERT_EQ(::getsockopt(copy, SOL_SOCKET, SO_TYPE, &type, &len), 0);
  ASSERT_EQ(::getsockopt(copy, SOL_SOCKET, SO_DOMAIN, &domain, &len), 0);
  EXPECT_EQ(type, SOCK_RAW);
  EXPECT_EQ(domain, AF_CAN);
  ::close(copy);
  ::close(copy2);
  // A plain pipe that lands on a recycled fd number is not taken for a CAN socket, also when
  // the socket went away through close_range().
  const int gone = OpenCan("ucan0");
  ASSERT_EQ(::close_range(static_cast<unsigned>(gone), static_cast<unsigned>(gone), 0), 0);
  int p[2];
  ASSERT_EQ(::pipe(p), 0);
  EXPECT_EQ(p[0], gone);
  ASSERT_EQ(::write(p[1], "xy", 2), 2);
  char buf[4] = {};
  EXPECT_EQ(::read(p[0], buf, sizeof(buf)), 2);
  ::close(p[0]);
  ::close(p[1]);
  ::close(rx);
}

TEST(UcanBroker, RefusesAnUnsafeRuntimeDirAndASecondBroker) {
  testing::TempRuntimeDir dir;
  ASSERT_EQ(::chmod(dir.path().c_str(), 0755), 0);
  UcanBrokerOptions options;
  options.runtime_dir = dir.path();
  EXPECT_THROW(UcanBroker{options}, std::system_error);
  ASSERT_EQ(::chmod(dir.path().c_str(), 0700), 0);
  UcanBroker first(options);
  try {
    UcanBroker second(options);
    ADD_FAILURE() << "a second broker started in the same directory";
  } catch (const std::system_error& e) {
    EXPECT_EQ(e.code().value(), EBUSY);
  }
  // A client refuses a directory that is not private: no ucan bus is visible through it.
  first.AddBus("ucan0");
  EXPECT_EQ(if_nametoindex("ucan0"), 1000u);
  ASSERT_EQ(::chmod(dir.path().c_str(), 0750), 0);
  EXPECT_EQ(if_nametoindex("ucan0"), 0u);
  ASSERT_EQ(::chmod(dir.path().c_str(), 0700), 0);
}

TEST(UcanBroker, PrivateRuntimeDirIsRemovedWithTheBroker) {
  const std::string dir = CreateTempUcanRuntimeDir();
  ASSERT_FALSE(VerifyUcanRuntimeDir(dir));  // mode 0700, ours
  {
    UcanBrokerOptions options;
    options.runtime_dir = dir;
    options.remove_runtime_dir = true;
    UcanBroker broker(options);
    broker.AddBus("ucan0");
    EXPECT_EQ(broker.runtime_dir(), dir);
  }
  EXPECT_EQ(VerifyUcanRuntimeDir(dir), std::errc::no_such_file_or_directory);
}

TEST(UcanBroker, ControlRequestsListAddRemove) {
  testing::TempRuntimeDir dir;
  UcanBrokerOptions options;
  options.runtime_dir = dir.path();
  UcanBroker broker(options);
  int index = 0;
  ASSERT_FALSE(UcanAddBus(dir.path(), "ucan3", &index));
  EXPECT_EQ(index, 1003);
  EXPECT_EQ(UcanAddBus(dir.path(), "no/slash", &index), std::errc::invalid_argument);
  std::vector<UcanBusStats> list;
  ASSERT_FALSE(UcanListBuses(dir.path(), &list));
  ASSERT_EQ(list.size(), 1u);
  EXPECT_EQ(list[0].name, "ucan3");
  EXPECT_EQ(UcanRemoveBus(dir.path(), "nope"), std::errc::no_such_device);
  EXPECT_FALSE(UcanRemoveBus(dir.path(), "ucan3"));
  ASSERT_FALSE(UcanShutdown(dir.path()));
  broker.Wait();  // returns: the broker stopped
  testing::TempRuntimeDir empty;
  EXPECT_TRUE(UcanListBuses(empty.path(), &list));  // no broker there
}

// Lockstep runs drive the broker from their own thread and talk to it through an in-process
// port: nothing moves between two Pump() calls, and the local port keeps the bus order with
// the socket clients.
TEST_F(UcanBusTest, PumpedBrokerWithLocalPortRoutesOnlyWhenPumpedAndKeepsOrder) {
  // bind() waits for the broker's answer: pump from a helper thread while the client opens.
  broker_.UseCallerThread();
  std::atomic<bool> opening{true};
  std::thread pumper([&] {
    while (opening) broker_.Pump(5);
  });
  const int fw = OpenCan("ucan0");
  opening = false;
  pumper.join();
  ASSERT_GE(fw, 0);
  const int port = broker_.OpenLocalPort("ucan0");
  EXPECT_THROW(broker_.OpenLocalPort("nosuchbus"), std::invalid_argument);
  EXPECT_EQ(StatsOf("ucan0").clients, 2u);

  // Emulator -> firmware: queued until the next pass, then in send order.
  for (std::uint8_t i = 0; i < 5; ++i) {
    ASSERT_TRUE(broker_.SendLocal(port, CanFrame::Classic(0x180 + i, std::array{i})));
  }
  EXPECT_TRUE(testing::NothingPending(fw));
  ASSERT_TRUE(broker_.Pump(0));
  for (canid_t i = 0; i < 5; ++i) EXPECT_EQ(Receive(fw).can_id, 0x180 + i);

  // Firmware -> emulator: the pass waits for the write, and the local port gets it in order.
  CanFrame got;
  EXPECT_FALSE(broker_.ReceiveLocal(port, &got));
  ASSERT_TRUE(Send(fw, Frame(0x680, {1})));
  ASSERT_TRUE(Send(fw, Frame(0x681, {2})));
  ASSERT_TRUE(broker_.Pump(1000));
  ASSERT_TRUE(broker_.ReceiveLocal(port, &got));
  EXPECT_EQ(got.id, 0x680u);
  EXPECT_EQ(got.len, 1u);
  EXPECT_EQ(got.data[0], 1u);
  ASSERT_TRUE(broker_.ReceiveLocal(port, &got));
  EXPECT_EQ(got.id, 0x681u);
  EXPECT_FALSE(broker_.ReceiveLocal(port, &got));  // its own frames are not looped back

  // A frame the firmware wrote before the local one is delivered first (one bus order).
  ASSERT_TRUE(Send(fw, Frame(0x700)));
  ASSERT_TRUE(broker_.SendLocal(port, CanFrame::Classic(0x080, {})));
  ASSERT_TRUE(broker_.Pump(0));
  ASSERT_TRUE(broker_.ReceiveLocal(port, &got));
  EXPECT_EQ(got.id, 0x700u);
  EXPECT_EQ(Receive(fw).can_id, 0x080u);
  EXPECT_THROW(UcanBroker(testing::TestBrokerOptions(dir_.path(), 8)),
               std::system_error);                               // still serving
  EXPECT_FALSE(broker_.SendLocal(port, CanFrame{.id = 0x800}));  // invalid: 12-bit id
  ::close(fw);
}

}  // namespace
}  // namespace wheelhil::bus
