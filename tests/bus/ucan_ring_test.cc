// The ucan shared-memory ring path (bus/ucan_protocol.h "Rings", docs/ucan.md): the hard parts
// of the doorbell protocol. Sockets opened here use rings (the library's default); a socket
// opened with WHEELHIL_UCAN_RINGS=0 uses one message per frame. Waits are failure signals
// (a lost wakeup shows as a poll/read that never returns), never measurements.

#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/mman.h>
#include <sys/syscall.h>
#include <sys/wait.h>

#include <gtest/gtest.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <random>
#include <set>
#include <thread>
#include <vector>

#include "bus/ucan_broker.h"
#include "bus/ucan_protocol.h"
#include "tests/bus/ucan_test_util.h"

namespace wheelhil::bus {
namespace {

using testing::Frame;
using testing::OpenCan;
using testing::Readable;
using testing::Receive;
using testing::Send;
using testing::SetInt;

/// Size of the next message queued in the socket itself (raw syscall, past the library);
/// -1 when none.
long PeekSocketMessage(int fd) {
  std::uint8_t buf[256];
  return ::syscall(SYS_recvfrom, fd, buf, sizeof(buf), MSG_PEEK | MSG_DONTWAIT | MSG_TRUNC, nullptr,
                   nullptr);
}

class UcanRingTest : public ::testing::Test {
 protected:
  explicit UcanRingTest(std::size_t limit = 8192)
      : broker_(testing::TestBrokerOptions(dir_.path(), limit)) {
    broker_.AddBus("ucan0");
  }
  testing::TempRuntimeDir dir_;
  UcanBroker broker_;
};

TEST_F(UcanRingTest, RingSocketsGetDoorbellsAndInteroperateWithMessageSockets) {
  const int ring_rx = OpenCan("ucan0");
  ::setenv("WHEELHIL_UCAN_RINGS", "0", 1);
  const int plain_rx = OpenCan("ucan0");
  const int plain_tx = OpenCan("ucan0");
  ::unsetenv("WHEELHIL_UCAN_RINGS");
  const int ring_tx = OpenCan("ucan0");
  ASSERT_GE(ring_rx, 0);
  ASSERT_GE(plain_rx, 0);
  ASSERT_GE(plain_tx, 0);
  ASSERT_GE(ring_tx, 0);
  for (int i = 0; i < 20; ++i) ASSERT_TRUE(Send(i % 2 ? ring_tx : plain_tx, Frame(0x100 + i)));
  ASSERT_TRUE(Readable(ring_rx, 2000));
  ASSERT_TRUE(Readable(plain_rx, 2000));
  // The ring reader's socket carries a doorbell (8 bytes), the plain one frame + RxTrailer.
  EXPECT_EQ(PeekSocketMessage(ring_rx), static_cast<long>(ucan::kDoorbellSize));
  EXPECT_EQ(PeekSocketMessage(plain_rx),
            static_cast<long>(sizeof(can_frame) + sizeof(ucan::RxTrailer)));
  for (int r : {ring_rx, plain_rx}) {
    for (int i = 0; i < 20; ++i) ASSERT_EQ(Receive(r).can_id, 0x100u + i) << r;
  }
  for (int s : {ring_rx, plain_rx, plain_tx, ring_tx}) ::close(s);
}

TEST_F(UcanRingTest, EpollStaysReadableUntilTheRingIsReadDryAndPeekLeavesTheFrame) {
  const int tx = OpenCan("ucan0"), rx = OpenCan("ucan0", SOCK_NONBLOCK);
  ASSERT_GE(tx, 0);
  ASSERT_GE(rx, 0);
  const int ep = ::epoll_create1(EPOLL_CLOEXEC);
  epoll_event ev{};
  ev.events = EPOLLIN;
  ev.data.fd = rx;
  ASSERT_EQ(::epoll_ctl(ep, EPOLL_CTL_ADD, rx, &ev), 0);
  for (int i = 0; i < 10; ++i) ASSERT_TRUE(Send(tx, Frame(0x200 + i)));
  epoll_event out{};
  can_frame f{};
  std::set<canid_t> seen;
  int got = 0;
  // Partial reads: after each one the fd must still be readable while frames remain.
  while (got < 10) {
    ASSERT_EQ(::epoll_wait(ep, &out, 1, 2000), 1) << "after " << got << " frames";
    const int take = got < 3 ? 3 : 1;
    for (int k = 0; k < take && got < 10; ++k) {
      const ssize_t n = ::read(rx, &f, sizeof(f));
      if (n < 0) {
        ASSERT_EQ(errno, EAGAIN);  // routed in two broker passes: the rest comes later
        break;
      }
      ASSERT_EQ(n, static_cast<ssize_t>(sizeof(f)));
      ASSERT_EQ(f.can_id, 0x200u + got);
      ++got;
    }
  }
  // Read dry: EAGAIN, and no readiness left behind (stale doorbells were discarded).
  EXPECT_EQ(::read(rx, &f, sizeof(f)), -1);
  EXPECT_EQ(errno, EAGAIN);
  EXPECT_EQ(::epoll_wait(ep, &out, 1, 0), 0);
  // MSG_PEEK returns the frame and leaves it (and the readiness) in place.
  ASSERT_TRUE(Send(tx, Frame(0x2AA)));
  ASSERT_EQ(::epoll_wait(ep, &out, 1, 2000), 1);
  ASSERT_EQ(::recv(rx, &f, sizeof(f), MSG_PEEK), static_cast<ssize_t>(sizeof(f)));
  EXPECT_EQ(f.can_id, 0x2AAu);
  EXPECT_EQ(::epoll_wait(ep, &out, 1, 0), 1);
  f = {};
  ASSERT_EQ(::read(rx, &f, sizeof(f)), static_cast<ssize_t>(sizeof(f)));
  EXPECT_EQ(f.can_id, 0x2AAu);
  EXPECT_EQ(::epoll_wait(ep, &out, 1, 0), 0);
  ::close(ep);
  for (int s : {tx, rx}) ::close(s);
}

// A producer racing consumers on both rings: a writer thread in bursts with random pauses, two
// reader threads on one fd that sleep in poll() whenever the ring looks empty. A lost doorbell
// leaves a reader in poll() with frames in the ring: the 5 s poll timeout fails the test.
TEST_F(UcanRingTest, NoWakeupIsLostWhenWritersRaceReaders) {
  const int tx = OpenCan("ucan0"), rx = OpenCan("ucan0", SOCK_NONBLOCK);
  ASSERT_GE(tx, 0);
  ASSERT_GE(rx, 0);
  constexpr int kFrames = 20000;
  std::atomic<int> received{0};
  std::atomic<int> lost_wakeups{0};
  std::atomic<std::uint64_t> id_sum{0};
  const int all_read = ::eventfd(0, EFD_CLOEXEC);  // ends the other reader's last poll
  auto reader = [&] {
    can_frame f{};
    while (received.load() < kFrames) {
      pollfd p[2] = {{rx, POLLIN, 0}, {all_read, POLLIN, 0}};
      if (::poll(p, 2, 5000) == 0) {
        if (received.load() < kFrames) lost_wakeups.fetch_add(1);
        return;
      }
      while (::read(rx, &f, sizeof(f)) == static_cast<ssize_t>(sizeof(f))) {
        id_sum.fetch_add(f.can_id);
        if (received.fetch_add(1) + 1 == kFrames) {
          const std::uint64_t one = 1;
          [[maybe_unused]] ssize_t n = ::write(all_read, &one, sizeof(one));
        }
      }
    }
  };
  std::thread r1(reader), r2(reader);
  std::mt19937 rng(7);
  std::uint64_t expect_sum = 0;
  for (int i = 0; i < kFrames;) {
    const int burst = 1 + static_cast<int>(rng() % 12);
    for (int k = 0; k < burst && i < kFrames; ++k, ++i) {
      const canid_t id = static_cast<canid_t>(i % 0x7FF);
      ASSERT_TRUE(Send(tx, Frame(id)));
      expect_sum += id;
    }
    if (rng() % 8 == 0) std::this_thread::yield();
    // Let the readers catch up now and then, so they go to sleep on an empty ring.
    if (rng() % 64 == 0) {
      while (received.load() < i && lost_wakeups.load() == 0) std::this_thread::yield();
    }
  }
  r1.join();
  r2.join();
  EXPECT_EQ(lost_wakeups.load(), 0);
  EXPECT_EQ(received.load(), kFrames);
  EXPECT_EQ(id_sum.load(), expect_sum);
  ::close(all_read);
  for (int s : {tx, rx}) ::close(s);
}

class UcanRingSmallQueueTest : public UcanRingTest {
 protected:
  UcanRingSmallQueueTest() : UcanRingTest(16) {}
};

TEST_F(UcanRingSmallQueueTest, FullRingDropsAreCountedAndTheRestReadsInOrder) {
  const int tx = OpenCan("ucan0"), fast = OpenCan("ucan0"), slow = OpenCan("ucan0", SOCK_NONBLOCK);
  ASSERT_TRUE(SetInt(slow, SOL_SOCKET, SO_RXQ_OVFL, 1));
  constexpr int kFrames = 500;
  for (int i = 0; i < kFrames; ++i) {
    ASSERT_TRUE(Send(tx, Frame(static_cast<canid_t>(i))));
    ASSERT_EQ(Receive(fast).can_id, static_cast<canid_t>(i));
  }
  const std::uint64_t drops = broker_.Stats().at(0).drops;
  ASSERT_GT(drops, 0u);
  can_frame f{};
  int queued = 0;
  while (::read(slow, &f, sizeof(f)) == static_cast<ssize_t>(sizeof(f))) {
    ASSERT_EQ(f.can_id, static_cast<canid_t>(queued));
    ++queued;
  }
  EXPECT_EQ(errno, EAGAIN);
  EXPECT_EQ(static_cast<std::uint64_t>(queued) + drops, static_cast<std::uint64_t>(kFrames));
  EXPECT_FALSE(Readable(slow, 0));  // read dry: no doorbell left
  // The next frame carries the socket's drop count, like the kernel's SO_RXQ_OVFL.
  ASSERT_TRUE(Send(tx, Frame(0x1)));
  ASSERT_TRUE(Readable(slow, 2000));
  const auto reported = testing::ReceiveDropCount(slow, &f);
  ASSERT_TRUE(reported.has_value());
  EXPECT_EQ(*reported, drops);
  for (int s : {tx, fast, slow}) ::close(s);
}

// One ring socket shared by forked processes (parent + 2 children): every frame is read
// exactly once, and each reader gets woken for its share. Blocking reads with SO_RCVTIMEO: a
// lost wakeup shows as a read that times out.
TEST_F(UcanRingTest, ForkedProcessesShareOneRingSocket) {
  const int tx = OpenCan("ucan0"), rx = OpenCan("ucan0");
  ASSERT_GE(tx, 0);
  ASSERT_GE(rx, 0);
  timeval tv{5, 0};
  ASSERT_EQ(::setsockopt(rx, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv)), 0);
  constexpr int kReaders = 3;
  constexpr int kFrames = 3000;
  constexpr canid_t kStop = 0x7FF;
  int pipes[2];
  ASSERT_EQ(::pipe(pipes), 0);
  // Reads until a stop frame; reports {frames, sum of ids, timed out}.
  auto read_share = [&](int report) {
    std::uint64_t r[3] = {0, 0, 0};
    can_frame f{};
    for (;;) {
      if (::read(rx, &f, sizeof(f)) != static_cast<ssize_t>(sizeof(f))) {
        r[2] = 1;
        break;
      }
      if (f.can_id == kStop) break;
      ++r[0];
      r[1] += f.can_id;
    }
    [[maybe_unused]] ssize_t n = ::write(report, r, sizeof(r));
  };
  std::vector<pid_t> kids;
  for (int k = 0; k < kReaders - 1; ++k) {
    const pid_t pid = ::fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
      read_share(pipes[1]);
      _exit(0);
    }
    kids.push_back(pid);
  }
  std::thread parent_reader([&] { read_share(pipes[1]); });
  std::uint64_t expect_sum = 0;
  for (int i = 0; i < kFrames; ++i) {
    const canid_t id = static_cast<canid_t>(i % 0x700);
    ASSERT_TRUE(Send(tx, Frame(id)));
    expect_sum += id;
    if (i % 97 == 0) std::this_thread::yield();
  }
  for (int k = 0; k < kReaders; ++k) ASSERT_TRUE(Send(tx, Frame(kStop)));
  parent_reader.join();
  for (pid_t pid : kids) {
    int status = 0;
    ASSERT_EQ(::waitpid(pid, &status, 0), pid);
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
  }
  std::uint64_t frames = 0, sum = 0, timeouts = 0;
  for (int k = 0; k < kReaders; ++k) {
    std::uint64_t r[3];
    ASSERT_EQ(::read(pipes[0], r, sizeof(r)), static_cast<ssize_t>(sizeof(r)));
    frames += r[0];
    sum += r[1];
    timeouts += r[2];
  }
  EXPECT_EQ(timeouts, 0u);
  EXPECT_EQ(frames, static_cast<std::uint64_t>(kFrames));
  EXPECT_EQ(sum, expect_sum);
  ::close(pipes[0]);
  ::close(pipes[1]);
  for (int s : {tx, rx}) ::close(s);
}

// Frames written by a process that exits right away (cansend) are on the bus: the broker
// drains a closed client's ring before it drops the connection.
TEST_F(UcanRingTest, FramesOfAClientThatClosedAreDelivered) {
  const int rx = OpenCan("ucan0");
  ASSERT_GE(rx, 0);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    const int s = OpenCan("ucan0");
    for (int i = 0; i < 10; ++i) Send(s, Frame(0x300 + i));
    _exit(0);
  }
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  for (int i = 0; i < 10; ++i) ASSERT_EQ(Receive(rx).can_id, 0x300u + i);
  ::close(rx);
}

// The eventcount itself (ucan::RingTakeDoorbell / ucan::RingSettle, as the broker and the
// library use them) with its race windows widened by random spins: one producer (the broker's
// side of an rx ring) pushing bursts, three consumers sharing one socket end and the ring (two
// threads and a forked process, under the ring's robust process-shared lock) that sleep in
// poll() whenever the ring looks empty. A lost doorbell leaves a consumer in poll() while the
// ring holds entries: counted after a 2 s timeout, and the test fails. (The first design of the
// settle step, "re-set pending when entries are found, else take one doorbell", fails here.)
struct SharedRing {
  ucan::RingIndex index;
  std::atomic<int> done{0};
  std::atomic<std::uint64_t> consumed{0};
  std::atomic<std::uint64_t> sum{0};
  std::atomic<std::uint64_t> lost{0};
  std::uint64_t slots[256] = {};
};

void SpinSometimes(std::minstd_rand& rng) {
  if (rng() % 4 != 0) return;
  const unsigned n = rng() % 2000;
  for (unsigned i = 0; i < n; ++i) asm volatile("" ::: "memory");
}

TEST(UcanRingEventcount, NoDoorbellIsLostUnderRacingProducerAndConsumers) {
  void* mem = ::mmap(nullptr, sizeof(SharedRing), PROT_READ | PROT_WRITE,
                     MAP_SHARED | MAP_ANONYMOUS, -1, 0);
  ASSERT_NE(mem, MAP_FAILED);
  auto* sr = new (mem) SharedRing;
  pthread_mutexattr_t a;
  pthread_mutexattr_init(&a);
  pthread_mutexattr_setpshared(&a, PTHREAD_PROCESS_SHARED);
  pthread_mutexattr_setrobust(&a, PTHREAD_MUTEX_ROBUST);
  pthread_mutex_init(&sr->index.lock, &a);
  int sv[2];
  ASSERT_EQ(::socketpair(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0, sv), 0);
  constexpr std::uint64_t kFrames = 150000;
  ucan::RingIndex& r = sr->index;
  auto consume = [&](unsigned seed) {
    std::minstd_rand rng(seed);
    auto discard_one = [&] {
      return ucan::ReceiveDoorbell(sv[1], ucan::kDoorbellInFlightMs, ::recv, ::poll);
    };
    auto spin = [&] { SpinSometimes(rng); };
    for (;;) {
      if (pthread_mutex_lock(&r.lock) == EOWNERDEAD) pthread_mutex_consistent(&r.lock);
      const std::uint64_t head = r.head.load(std::memory_order_relaxed);
      const std::uint64_t tail = r.tail.load(std::memory_order_acquire);
      if (head != tail) {
        const std::uint64_t v = sr->slots[head % 256];
        r.head.store(head + 1, std::memory_order_release);
        if (head + 1 == tail) ucan::RingSettle(r, head + 1, discard_one, spin);
        pthread_mutex_unlock(&r.lock);
        sr->sum.fetch_add(v);
        sr->consumed.fetch_add(1);
        continue;
      }
      ucan::RingSettle(r, head, discard_one, spin);
      pthread_mutex_unlock(&r.lock);
      if (sr->done.load() != 0) return;
      pollfd p{sv[1], POLLIN, 0};
      if (::poll(&p, 1, 2000) == 0 && r.head.load() != r.tail.load()) sr->lost.fetch_add(1);
    }
  };
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    consume(3);
    _exit(0);
  }
  std::thread c1(consume, 1), c2(consume, 2);
  std::minstd_rand rng(11);
  std::uint64_t pushed = 0, expect_sum = 0;
  while (pushed < kFrames) {
    const std::uint64_t burst = 1 + rng() % 8;
    for (std::uint64_t k = 0; k < burst && pushed < kFrames; ++k) {
      const std::uint64_t tail = r.tail.load(std::memory_order_relaxed);
      if (tail - r.head.load(std::memory_order_acquire) >= 256) break;  // full: ring first
      sr->slots[tail % 256] = pushed + 1;
      r.tail.store(tail + 1, std::memory_order_release);
      expect_sum += ++pushed;
      SpinSometimes(rng);
    }
    if (ucan::RingTakeDoorbell(r, ucan::kDoorbellTries) == 1) {
      const std::uint64_t bell = 1;
      ASSERT_EQ(::send(sv[0], &bell, sizeof(bell), MSG_NOSIGNAL), 8);
    }
    if (rng() % 32 == 0) {  // let the consumers drain and fall asleep
      while (sr->consumed.load() < pushed) std::this_thread::yield();
    }
  }
  while (sr->consumed.load() < kFrames) std::this_thread::yield();
  sr->done.store(1);
  for (int k = 0; k < 3; ++k) {  // wake every consumer for its exit (outside the count)
    const std::uint64_t bell = 1;
    ::send(sv[0], &bell, sizeof(bell), MSG_NOSIGNAL);
  }
  c1.join();
  c2.join();
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  EXPECT_EQ(sr->lost.load(), 0u);
  EXPECT_EQ(sr->consumed.load(), kFrames);
  EXPECT_EQ(sr->sum.load(), expect_sum);
  ::close(sv[0]);
  ::close(sv[1]);
  ::munmap(mem, sizeof(SharedRing));
}

// A doorbell on its way when the consumer empties the ring (the producer took it, and sends it
// a moment later) is waited for and taken then: afterwards the socket is not readable with the
// ring empty. Left to a later call (as the library did), it made the socket readable with
// nothing to read, and a blocking read after a poll that said readable waited for the next
// frame: a reader that polls with a timeout to see whether it should stop hung in its read
// (wheelhil bench's fan-out readers, once).
TEST(UcanRingEventcount, ADoorbellOnItsWayIsTakenBeforeTheConsumerCallsTheRingEmpty) {
  ucan::RingIndex r;
  int sv[2];
  ASSERT_EQ(::socketpair(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0, sv), 0);
  r.tail.store(1);  // one entry pushed
  ASSERT_EQ(ucan::RingTakeDoorbell(r, ucan::kDoorbellTries), 1);
  std::thread late_bell([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    const std::uint64_t bell = 1;
    ::send(sv[0], &bell, sizeof(bell), MSG_NOSIGNAL);
  });
  // The consumer takes the entry and settles before the doorbell is there.
  r.head.store(1);
  ucan::RingSettle(r, 1, [&] {
    return ucan::ReceiveDoorbell(sv[1], ucan::kDoorbellInFlightMs, ::recv, ::poll);
  });
  late_bell.join();
  pollfd p{sv[1], POLLIN, 0};
  EXPECT_EQ(::poll(&p, 1, 0), 0) << "a doorbell left with the ring empty";
  EXPECT_EQ(r.bells_taken, 1u);
  ::close(sv[0]);
  ::close(sv[1]);
}

}  // namespace
}  // namespace wheelhil::bus
