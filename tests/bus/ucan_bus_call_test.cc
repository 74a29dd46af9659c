// The counts the bus library gives the virtual clock around a call the broker sees on a socket
// rather than in a ring (wheelhil_vtime_note_bus_call, bus/vtime_protocol.h Page::bus_calls):
// the emulator skips its look at the broker's sockets while the count stays what it was at its
// last look, so the last count of a call must come after the call's effect is on the socket.
// A count taken only before a send lets a look between the count and the send miss the frame
// for good (the run then moves the clock past it, and the firmware's timing depends on the
// host's load). This binary defines the counting function itself (exported: the library finds
// it with dlsym) and records what the watched socket holds at each count. The broker is pumped
// by the test, so nothing reads a socket while the test looks at it.
#include <linux/sockios.h>
#include <sys/ioctl.h>
#include <sys/syscall.h>

#include <gtest/gtest.h>

#include <atomic>
#include <mutex>
#include <thread>
#include <vector>

#include "bus/ucan_broker.h"
#include "tests/bus/ucan_test_util.h"

namespace {

struct SocketAtCount {
  int unsent = -1;  // SIOCOUTQ: bytes written and not yet read by the broker
  int unread = -1;  // SIOCINQ: bytes waiting to be read
};

std::atomic<int> g_watched_fd{-1};
std::mutex g_counts_mu;
std::vector<SocketAtCount> g_counts;

}  // namespace

extern "C" __attribute__((visibility("default"))) void wheelhil_vtime_note_bus_call() {
  const int fd = g_watched_fd.load();
  if (fd < 0) return;
  SocketAtCount c;
  // Raw system calls: past the library this binary links.
  ::syscall(SYS_ioctl, fd, SIOCOUTQ, &c.unsent);
  ::syscall(SYS_ioctl, fd, SIOCINQ, &c.unread);
  std::lock_guard lk(g_counts_mu);
  g_counts.push_back(c);
}

namespace wheelhil::bus {
namespace {

using testing::Frame;
using testing::OpenCan;

class UcanBusCallTest : public ::testing::Test {
 protected:
  UcanBusCallTest() : broker_(testing::TestBrokerOptions(dir_.path(), 64)) {
    broker_.AddBus("ucan0");
    broker_.UseCallerThread();
  }
  ~UcanBusCallTest() override { g_watched_fd.store(-1); }

  // Pumps the broker on another thread while `work` runs here (a socket open waits for the
  // broker's answer).
  template <typename Work>
  void WithPumping(Work&& work) {
    std::atomic<bool> done{false};
    std::thread pump([&] {
      while (!done.load()) broker_.Pump(1);
    });
    work();
    done.store(true);
    pump.join();
  }
  // Opens a socket with one message per frame (no rings).
  int OpenPlain() {
    ::setenv("WHEELHIL_UCAN_RINGS", "0", 1);
    int fd = -1;
    WithPumping([&] { fd = OpenCan("ucan0"); });
    ::unsetenv("WHEELHIL_UCAN_RINGS");
    return fd;
  }
  void Watch(int fd) {
    std::lock_guard lk(g_counts_mu);
    g_counts.clear();
    g_watched_fd.store(fd);
  }
  std::vector<SocketAtCount> Counts() {
    g_watched_fd.store(-1);
    std::lock_guard lk(g_counts_mu);
    return g_counts;
  }

  testing::TempRuntimeDir dir_;
  UcanBroker broker_;
};

TEST_F(UcanBusCallTest, ASendIsCountedAfterItsFrameIsOnTheSocket) {
  const int tx = OpenPlain();
  ASSERT_GE(tx, 0);
  Watch(tx);
  ASSERT_TRUE(testing::Send(tx, Frame(0x123, {1, 2})));
  const auto counts = Counts();
  ASSERT_FALSE(counts.empty()) << "the send was not counted";
  EXPECT_EQ(counts.front().unsent, 0) << "counted before the send as well";
  EXPECT_GT(counts.back().unsent, 0) << "the last count came before the frame was sent";
  ::close(tx);
}

TEST_F(UcanBusCallTest, AReceiveIsCountedAfterItsFrameLeftTheSocket) {
  const int tx = OpenPlain();
  const int rx = OpenPlain();
  ASSERT_GE(tx, 0);
  ASSERT_GE(rx, 0);
  ASSERT_TRUE(testing::Send(tx, Frame(0x124, {3})));
  WithPumping([&] { ASSERT_TRUE(testing::Readable(rx, 5000)); });
  Watch(rx);
  EXPECT_EQ(testing::Receive(rx).can_id, 0x124u);
  const auto counts = Counts();
  ASSERT_FALSE(counts.empty()) << "the receive was not counted";
  EXPECT_EQ(counts.back().unread, 0) << "the last count came before the frame was taken";
  ::close(rx);
  ::close(tx);
}

TEST_F(UcanBusCallTest, ACloseIsCountedAfterTheSocketIsClosed) {
  const int tx = OpenPlain();
  ASSERT_GE(tx, 0);
  Watch(tx);
  ASSERT_EQ(::close(tx), 0);
  const auto counts = Counts();
  ASSERT_GE(counts.size(), 2u);
  // The watched number no longer names a socket at the last count.
  EXPECT_EQ(counts.back().unsent, -1);
}

}  // namespace
}  // namespace wheelhil::bus
