#pragma once
/// The reader side of a fan-out throughput measurement: one writer -> N readers of classic CAN
/// frames through the plain SocketCAN API (a kernel vcan, or ucan with libwheelhil_ucan.so
/// preloaded), flow-controlled so that at most a window of frames is in flight to the slowest
/// reader. Shared by `wheelhil bench` (bench_workloads.cc) and tests/bench/ucan_bench.cc, which
/// each drive their own writer. Header-only (the benchmark binary does not link the bench
/// library). Counters are atomics: the writer's thread may poll them while the readers run.

#include <linux/can.h>
#include <net/if.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <limits>
#include <thread>
#include <vector>

namespace wheelhil::emulator::bench {

/// A raw CAN socket bound to `iface`; -1 (errno set) when it cannot be opened or bound.
inline int OpenRawCan(const char* iface) {
  const int fd = ::socket(PF_CAN, SOCK_RAW, CAN_RAW);
  if (fd < 0) return -1;
  sockaddr_can addr{};
  addr.can_family = AF_CAN;
  addr.can_ifindex = static_cast<int>(::if_nametoindex(iface));
  if (addr.can_ifindex == 0 || ::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0) {
    const int saved = addr.can_ifindex == 0 ? ENODEV : errno;
    ::close(fd);
    errno = saved;
    return -1;
  }
  return fd;
}

/// One thread per socket, each reading classic frames and counting them, until Stop() (after
/// which a reader ends at its first 100 ms without a frame) or a read error. The sockets stay
/// the caller's: close them after Stop().
class FanOutReaders {
 public:
  using Clock = std::chrono::steady_clock;

  explicit FanOutReaders(const std::vector<int>& fds) : received_(fds.size()) {
    for (std::size_t i = 0; i < fds.size(); ++i) {
      threads_.emplace_back([this, i, fd = fds[i]] { Read(i, fd); });
    }
  }
  ~FanOutReaders() { Stop(); }
  FanOutReaders(const FanOutReaders&) = delete;
  FanOutReaders& operator=(const FanOutReaders&) = delete;

  /// Frames the slowest reader has read (0 without readers).
  std::uint64_t Slowest() const {
    std::uint64_t m = std::numeric_limits<std::uint64_t>::max();
    for (const auto& r : received_) m = std::min(m, r.load(std::memory_order_acquire));
    return received_.empty() ? 0 : m;
  }

  /// Sleeps in 20 µs steps until fewer than `window` of the `sent` frames are still on their
  /// way to the slowest reader; false when `give_up` passed first (a reader stalled).
  bool WaitForWindow(std::uint64_t sent, std::uint64_t window, Clock::time_point give_up) const {
    while (sent - Slowest() >= window) {
      if (Clock::now() > give_up) return false;
      std::this_thread::sleep_for(std::chrono::microseconds(20));
    }
    return true;
  }

  /// Waits (50 µs steps) until every reader has `sent` frames or `timeout_s` passed; true when
  /// all arrived (frames a bus dropped never do).
  bool WaitForAll(std::uint64_t sent, double timeout_s) const {
    const Clock::time_point end = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                                     std::chrono::duration<double>(timeout_s));
    while (Slowest() < sent) {
      if (Clock::now() > end) return false;
      std::this_thread::sleep_for(std::chrono::microseconds(50));
    }
    return true;
  }

  /// Ends and joins the readers (each once it has been idle for 100 ms). Idempotent.
  void Stop() {
    stop_.store(true, std::memory_order_release);
    for (auto& t : threads_) {
      if (t.joinable()) t.join();
    }
  }

 private:
  void Read(std::size_t i, int fd) {
    can_frame f{};
    pollfd p{fd, POLLIN, 0};
    while (true) {
      const int n = ::poll(&p, 1, 100);
      if (n > 0) {
        if (::read(fd, &f, sizeof(f)) != static_cast<ssize_t>(sizeof(f))) return;
        received_[i].fetch_add(1, std::memory_order_release);
      } else if (n == 0 && stop_.load(std::memory_order_acquire)) {
        return;
      } else if (n < 0 && errno != EINTR) {
        return;
      }
    }
  }

  std::vector<std::atomic<std::uint64_t>> received_;
  std::atomic<bool> stop_{false};
  std::vector<std::thread> threads_;
};

}  // namespace wheelhil::emulator::bench
