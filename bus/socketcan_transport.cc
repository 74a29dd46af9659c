#include "bus/socketcan_transport.h"

#include <fcntl.h>
#include <linux/can.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <net/if_arp.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <fmt/format.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstddef>
#include <cstring>
#include <ctime>
#include <stdexcept>
#include <utility>

#include "bus/internal/socketcan_convert.h"
#include "bus/internal/unique_fd.h"

#ifndef CANFD_FDF
#define CANFD_FDF 0x04
#endif
#ifndef SO_RXQ_OVFL
#define SO_RXQ_OVFL 40
#endif

namespace wheelhil::bus {
namespace internal {

std::size_t EncodeFrame(const CanFrame& frame, canfd_frame& buf) noexcept {
  std::memset(&buf, 0, sizeof(buf));
  if (!frame.IsValid()) return 0;
  if (frame.fd) {
    buf.can_id = frame.id | (frame.extended ? CAN_EFF_FLAG : 0u);
    buf.len = frame.len;
    buf.flags = static_cast<std::uint8_t>((frame.fd_flags & (CANFD_BRS | CANFD_ESI)) | CANFD_FDF);
    std::memcpy(buf.data, frame.data.data(), frame.len);
    return CANFD_MTU;
  }
  can_frame cf{};
  if (frame.error) {
    cf.can_id = (frame.id & CAN_ERR_MASK) | CAN_ERR_FLAG;
  } else {
    cf.can_id = frame.id | (frame.extended ? CAN_EFF_FLAG : 0u) | (frame.rtr ? CAN_RTR_FLAG : 0u);
  }
  cf.len = frame.len;
  if (!frame.rtr) std::memcpy(cf.data, frame.data.data(), frame.len);
  static_assert(sizeof(can_frame) <= sizeof(canfd_frame));
  std::memcpy(&buf, &cf, sizeof(cf));
  return CAN_MTU;
}

std::error_code DecodeFrame(const void* data, std::size_t size, CanFrame& out) noexcept {
  const auto bad = std::make_error_code(std::errc::bad_message);
  out = CanFrame{};
  if (size == CAN_MTU) {
    can_frame cf;
    std::memcpy(&cf, data, sizeof(cf));
    if (cf.len > CanFrame::kMaxClassicLen) return bad;
    out.len = cf.len;
    if (cf.can_id & CAN_ERR_FLAG) {
      out.error = true;
      out.id = cf.can_id & CAN_ERR_MASK;
    } else {
      out.extended = (cf.can_id & CAN_EFF_FLAG) != 0;
      out.rtr = (cf.can_id & CAN_RTR_FLAG) != 0;
      out.id = cf.can_id & CAN_EFF_MASK;
      if (!out.extended && out.id > CanFrame::kMaxStandardId) return bad;
    }
    if (!out.rtr) std::memcpy(out.data.data(), cf.data, cf.len);
    return out.IsValid() ? std::error_code{} : bad;
  }
  if (size == CANFD_MTU) {
    canfd_frame fdf;
    std::memcpy(&fdf, data, sizeof(fdf));
    if (fdf.can_id & (CAN_ERR_FLAG | CAN_RTR_FLAG)) return bad;
    if (!IsValidFdLength(fdf.len)) return bad;
    out.fd = true;
    out.extended = (fdf.can_id & CAN_EFF_FLAG) != 0;
    out.id = fdf.can_id & CAN_EFF_MASK;
    out.fd_flags = static_cast<std::uint8_t>(fdf.flags & (CANFD_BRS | CANFD_ESI));
    out.len = fdf.len;
    std::memcpy(out.data.data(), fdf.data, fdf.len);
    return out.IsValid() ? std::error_code{} : bad;
  }
  return bad;
}

std::vector<can_filter> ToKernelFilters(const std::vector<CanFilter>& filters) {
  std::vector<can_filter> out;
  out.reserve(filters.size());
  for (const CanFilter& f : filters) {
    can_filter k{};
    const std::uint32_t id_mask = f.extended ? CAN_EFF_MASK : CAN_SFF_MASK;
    k.can_id = (f.id & id_mask) | (f.extended ? CAN_EFF_FLAG : 0u);
    // Always compare the format bit; error frames are governed by error_mask, not filters.
    k.can_mask = (f.mask & id_mask) | CAN_EFF_FLAG;
    if (f.inverse) k.can_id |= CAN_INV_FILTER;
    out.push_back(k);
  }
  return out;
}

std::string NoSocketCanMessage(const std::string& iface, int err) {
  return fmt::format(
      "cannot open CAN interface '{}': this kernel has no SocketCAN support "
      "(socket(PF_CAN, SOCK_RAW, CAN_RAW) failed: {}). AF_CAN is missing or the can/can-raw "
      "modules are not loaded (try: modprobe can-raw vcan). Without kernel CAN, run the program "
      "on wheelhil's userspace bus instead: `wheelhil exec -- <program>` (ucan), which provides "
      "SocketCAN interfaces without the kernel",
      iface, std::strerror(err));
}

std::string InterfaceNotFoundMessage(const std::string& iface) {
  return fmt::format(
      "CAN interface '{}' not found (ENODEV). Create it, e.g. for a virtual one: "
      "ip link add dev {} type vcan && ip link set {} up; or run on the userspace bus "
      "(`wheelhil exec`)",
      iface, iface, iface);
}

std::string InterfaceDownMessage(const std::string& iface) {
  return fmt::format("CAN interface '{}' is down: ip link set {} up", iface, iface);
}

std::string NotCanInterfaceMessage(const std::string& iface) {
  return fmt::format("network interface '{}' is not a CAN interface (ENODEV)", iface);
}

}  // namespace internal

struct SocketCanTransport::Counters {
  std::atomic<std::uint64_t> sent{0};
  std::atomic<std::uint64_t> received{0};
  std::atomic<std::uint64_t> send_retries{0};
  std::atomic<std::uint64_t> send_failures{0};
  std::atomic<std::uint64_t> rx_invalid{0};
  std::atomic<std::uint64_t> rx_kernel_drops{0};
};

namespace {

[[noreturn]] void ThrowErrno(int err, const std::string& what) {
  throw std::system_error(err, std::system_category(), what);
}

void SetIntOption(int fd, int level, int name, int value, const char* what,
                  const std::string& iface) {
  if (::setsockopt(fd, level, name, &value, sizeof(value)) != 0) {
    const int err = errno;
    ThrowErrno(err, fmt::format("CAN interface '{}': setsockopt({}) failed", iface, what));
  }
}

std::int64_t RealtimeNowNs() noexcept {
  timespec ts{};
  ::clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

// Sleeps `us` microseconds; with `fd` >= 0 wakes early when it becomes writable.
void WaitMicros(int fd, std::int64_t us) noexcept {
  timespec ts{static_cast<time_t>(us / 1'000'000), static_cast<long>((us % 1'000'000) * 1000)};
  pollfd pfd{fd, POLLOUT, 0};
  ::ppoll(fd >= 0 ? &pfd : nullptr, fd >= 0 ? 1 : 0, &ts, nullptr);
}

}  // namespace

SocketCanTransport SocketCanTransport::Open(const std::string& iface,
                                            const CanTransportOptions& options) {
  if (iface.empty() || iface.size() >= IFNAMSIZ || iface.find('/') != std::string::npos) {
    throw std::invalid_argument(fmt::format(
        "CAN interface name '{}' is invalid (1..{} characters, no '/')", iface, IFNAMSIZ - 1));
  }
  if (options.filters.size() > CAN_RAW_FILTER_MAX) {
    throw std::invalid_argument(fmt::format("CAN interface '{}': {} filters (at most {})", iface,
                                            options.filters.size(), CAN_RAW_FILTER_MAX));
  }
  if (options.send_retry_limit < 0 || options.send_retry_initial_us < 0 ||
      options.send_retry_budget_us < 0) {
    throw std::invalid_argument(
        fmt::format("CAN interface '{}': send retry limits must be >= 0", iface));
  }

  internal::UniqueFd sock(::socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, CAN_RAW));
  if (sock.get() < 0) {
    const int err = errno;
    ThrowErrno(err, internal::NoSocketCanMessage(iface, err));
  }
  // Some socket emulations ignore SOCK_NONBLOCK in socket(); make sure.
  const int fl = ::fcntl(sock.get(), F_GETFL);
  if (fl >= 0 && !(fl & O_NONBLOCK)) ::fcntl(sock.get(), F_SETFL, fl | O_NONBLOCK);

  ifreq ifr{};
  std::memcpy(ifr.ifr_name, iface.c_str(), iface.size() + 1);
  int ifindex = 0;
  if (::ioctl(sock.get(), SIOCGIFINDEX, &ifr) == 0) {
    ifindex = ifr.ifr_ifindex;
  } else {
    const int err = errno;
    if (err == ENODEV) ThrowErrno(ENODEV, internal::InterfaceNotFoundMessage(iface));
    ifindex = static_cast<int>(::if_nametoindex(iface.c_str()));
    if (ifindex == 0) ThrowErrno(ENODEV, internal::InterfaceNotFoundMessage(iface));
  }
  // bind() would say ENODEV for a non-CAN device too; tell the two apart by hardware type.
  ifreq hw_req{};
  std::memcpy(hw_req.ifr_name, iface.c_str(), iface.size() + 1);
  if (::ioctl(sock.get(), SIOCGIFHWADDR, &hw_req) == 0 &&
      hw_req.ifr_hwaddr.sa_family != ARPHRD_CAN) {
    ThrowErrno(ENODEV, internal::NotCanInterfaceMessage(iface));
  }
  // Binding to a down interface succeeds and every write then fails with ENETDOWN; say it now.
  ifreq flags_req{};
  std::memcpy(flags_req.ifr_name, iface.c_str(), iface.size() + 1);
  if (::ioctl(sock.get(), SIOCGIFFLAGS, &flags_req) == 0 && !(flags_req.ifr_flags & IFF_UP)) {
    ThrowErrno(ENETDOWN, internal::InterfaceDownMessage(iface));
  }

  const int fd = sock.get();
  SetIntOption(fd, SOL_CAN_RAW, CAN_RAW_LOOPBACK, options.loopback ? 1 : 0, "CAN_RAW_LOOPBACK",
               iface);
  SetIntOption(fd, SOL_CAN_RAW, CAN_RAW_RECV_OWN_MSGS, options.receive_own ? 1 : 0,
               "CAN_RAW_RECV_OWN_MSGS", iface);
  if (options.fd_frames) {
    SetIntOption(fd, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, 1, "CAN_RAW_FD_FRAMES", iface);
  }
  if (!options.filters.empty()) {
    const std::vector<can_filter> kf = internal::ToKernelFilters(options.filters);
    if (::setsockopt(fd, SOL_CAN_RAW, CAN_RAW_FILTER, kf.data(),
                     static_cast<socklen_t>(kf.size() * sizeof(can_filter))) != 0) {
      const int err = errno;
      ThrowErrno(err, fmt::format("CAN interface '{}': setsockopt(CAN_RAW_FILTER) failed", iface));
    }
  }
  if (options.error_mask != 0) {
    const can_err_mask_t mask = options.error_mask & CAN_ERR_MASK;
    if (::setsockopt(fd, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &mask, sizeof(mask)) != 0) {
      const int err = errno;
      ThrowErrno(err,
                 fmt::format("CAN interface '{}': setsockopt(CAN_RAW_ERR_FILTER) failed", iface));
    }
  }
  // Kernel receive timestamps: ns if possible, else µs; without either Receive() stamps itself.
  const int one = 1;
  if (::setsockopt(fd, SOL_SOCKET, SO_TIMESTAMPNS, &one, sizeof(one)) != 0) {
    (void)::setsockopt(fd, SOL_SOCKET, SO_TIMESTAMP, &one, sizeof(one));
  }
  // Optional: count of frames the kernel dropped because our receive queue was full.
  (void)::setsockopt(fd, SOL_SOCKET, SO_RXQ_OVFL, &one, sizeof(one));

  sockaddr_can addr{};
  addr.can_family = AF_CAN;
  addr.can_ifindex = ifindex;
  if (::bind(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)) != 0) {
    const int err = errno;
    if (err == ENODEV) ThrowErrno(ENODEV, internal::NotCanInterfaceMessage(iface));
    ThrowErrno(err, fmt::format("CAN interface '{}': bind failed", iface));
  }
  return SocketCanTransport(sock.release(), ifindex, iface, options);
}

SocketCanTransport::SocketCanTransport(int fd, int ifindex, std::string name,
                                       CanTransportOptions options)
    : fd_(fd),
      ifindex_(ifindex),
      name_(std::move(name)),
      options_(std::move(options)),
      counters_(std::make_unique<Counters>()) {}

SocketCanTransport::SocketCanTransport(SocketCanTransport&& other) noexcept
    : fd_(std::exchange(other.fd_, -1)),
      ifindex_(other.ifindex_),
      name_(std::move(other.name_)),
      options_(std::move(other.options_)),
      counters_(std::move(other.counters_)) {}

SocketCanTransport& SocketCanTransport::operator=(SocketCanTransport&& other) noexcept {
  if (this != &other) {
    Close();
    fd_ = std::exchange(other.fd_, -1);
    ifindex_ = other.ifindex_;
    name_ = std::move(other.name_);
    options_ = std::move(other.options_);
    counters_ = std::move(other.counters_);
  }
  return *this;
}

SocketCanTransport::~SocketCanTransport() { Close(); }

void SocketCanTransport::Close() noexcept {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

std::error_code SocketCanTransport::Send(const CanFrame& frame) noexcept {
  if (fd_ < 0 || !counters_) return std::make_error_code(std::errc::bad_file_descriptor);
  Counters& c = *counters_;
  if (frame.fd && !options_.fd_frames) {
    c.send_failures.fetch_add(1, std::memory_order_relaxed);
    return std::make_error_code(std::errc::operation_not_supported);
  }
  canfd_frame buf;
  const std::size_t size = internal::EncodeFrame(frame, buf);
  if (size == 0) {
    c.send_failures.fetch_add(1, std::memory_order_relaxed);
    return std::make_error_code(std::errc::invalid_argument);
  }
  std::int64_t waited_us = 0;
  std::int64_t backoff_us = std::max(options_.send_retry_initial_us, 1);
  int retries = 0;
  for (;;) {
    const ssize_t n = ::write(fd_, &buf, size);
    if (n == static_cast<ssize_t>(size)) {
      c.sent.fetch_add(1, std::memory_order_relaxed);
      return {};
    }
    const int err = n < 0 ? errno : EIO;  // A short write of a datagram is an I/O error.
    if (err == EINTR) continue;
    const bool retryable = err == ENOBUFS || err == EAGAIN || err == EWOULDBLOCK;
    if (retryable && retries < options_.send_retry_limit &&
        waited_us < options_.send_retry_budget_us) {
      const std::int64_t wait_us = std::min(backoff_us, options_.send_retry_budget_us - waited_us);
      // EAGAIN: the socket's send buffer is full, wake as soon as it drains. ENOBUFS: the
      // device queue is full and the socket stays writable, so just sleep.
      WaitMicros(err == ENOBUFS ? -1 : fd_, wait_us);
      waited_us += wait_us;
      backoff_us *= 2;
      ++retries;
      c.send_retries.fetch_add(1, std::memory_order_relaxed);
      continue;
    }
    c.send_failures.fetch_add(1, std::memory_order_relaxed);
    return {err, std::system_category()};
  }
}

std::error_code SocketCanTransport::Receive(ReceivedFrame& out, int timeout_ms) noexcept {
  if (fd_ < 0 || !counters_) return std::make_error_code(std::errc::bad_file_descriptor);
  Counters& c = *counters_;
  canfd_frame buf;
  sockaddr_can addr{};
  alignas(cmsghdr) char control[CMSG_SPACE(sizeof(timespec)) + CMSG_SPACE(sizeof(timeval)) +
                                CMSG_SPACE(sizeof(std::uint32_t)) + 64];
  const auto deadline =
      std::chrono::steady_clock::now() + std::chrono::milliseconds(std::max(timeout_ms, 0));
  for (;;) {
    iovec iov{&buf, sizeof(buf)};
    msghdr msg{};
    msg.msg_name = &addr;
    msg.msg_namelen = sizeof(addr);
    msg.msg_iov = &iov;
    msg.msg_iovlen = 1;
    msg.msg_control = control;
    msg.msg_controllen = sizeof(control);
    const ssize_t n = ::recvmsg(fd_, &msg, MSG_DONTWAIT);
    if (n < 0) {
      const int err = errno;
      if (err == EINTR) continue;
      if (err != EAGAIN && err != EWOULDBLOCK) return {err, std::system_category()};
      if (timeout_ms == 0) return std::make_error_code(std::errc::resource_unavailable_try_again);
      int wait_ms = -1;
      if (timeout_ms > 0) {
        const auto left = std::chrono::ceil<std::chrono::milliseconds>(
            deadline - std::chrono::steady_clock::now());
        if (left.count() <= 0) return std::make_error_code(std::errc::timed_out);
        wait_ms = static_cast<int>(left.count());
      }
      pollfd pfd{fd_, POLLIN, 0};
      const int pr = ::poll(&pfd, 1, wait_ms);
      if (pr < 0 && errno != EINTR) return {errno, std::system_category()};
      continue;
    }
    out.kernel_timestamp = false;
    out.timestamp_ns = 0;
    for (cmsghdr* cm = CMSG_FIRSTHDR(&msg); cm != nullptr; cm = CMSG_NXTHDR(&msg, cm)) {
      if (cm->cmsg_level != SOL_SOCKET) continue;
      if (cm->cmsg_type == SCM_TIMESTAMPNS && cm->cmsg_len >= CMSG_LEN(sizeof(timespec))) {
        timespec ts;
        std::memcpy(&ts, CMSG_DATA(cm), sizeof(ts));
        out.timestamp_ns = static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
        out.kernel_timestamp = true;
      } else if (cm->cmsg_type == SCM_TIMESTAMP && cm->cmsg_len >= CMSG_LEN(sizeof(timeval))) {
        timeval tv;
        std::memcpy(&tv, CMSG_DATA(cm), sizeof(tv));
        out.timestamp_ns = static_cast<std::int64_t>(tv.tv_sec) * 1'000'000'000 +
                           static_cast<std::int64_t>(tv.tv_usec) * 1000;
        out.kernel_timestamp = true;
      } else if (cm->cmsg_type == SO_RXQ_OVFL && cm->cmsg_len >= CMSG_LEN(sizeof(std::uint32_t))) {
        std::uint32_t drops;
        std::memcpy(&drops, CMSG_DATA(cm), sizeof(drops));
        c.rx_kernel_drops.store(drops, std::memory_order_relaxed);
      }
    }
    if (!out.kernel_timestamp) out.timestamp_ns = RealtimeNowNs();
    out.own = (msg.msg_flags & MSG_CONFIRM) != 0;
    out.ifindex = msg.msg_namelen >= offsetof(sockaddr_can, can_ifindex) + sizeof(int)
                      ? addr.can_ifindex
                      : ifindex_;
    if (internal::DecodeFrame(&buf, static_cast<std::size_t>(n), out.frame)) {
      c.rx_invalid.fetch_add(1, std::memory_order_relaxed);
      return std::make_error_code(std::errc::bad_message);
    }
    c.received.fetch_add(1, std::memory_order_relaxed);
    return {};
  }
}

std::string SocketCanTransport::InterfaceName(int ifindex) const {
  if (ifindex == ifindex_) return name_;
  ifreq ifr{};
  ifr.ifr_ifindex = ifindex;
  if (fd_ >= 0 && ::ioctl(fd_, SIOCGIFNAME, &ifr) == 0) return ifr.ifr_name;
  char name[IF_NAMESIZE] = {};
  if (::if_indextoname(static_cast<unsigned>(ifindex), name) != nullptr) return name;
  return {};
}

TransportStats SocketCanTransport::stats() const noexcept {
  TransportStats s;
  if (!counters_) return s;
  s.sent = counters_->sent.load(std::memory_order_relaxed);
  s.received = counters_->received.load(std::memory_order_relaxed);
  s.send_retries = counters_->send_retries.load(std::memory_order_relaxed);
  s.send_failures = counters_->send_failures.load(std::memory_order_relaxed);
  s.rx_invalid = counters_->rx_invalid.load(std::memory_order_relaxed);
  s.rx_kernel_drops = counters_->rx_kernel_drops.load(std::memory_order_relaxed);
  return s;
}

}  // namespace wheelhil::bus
