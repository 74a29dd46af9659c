#pragma once
/// SocketCAN transport: one CAN_RAW socket bound to one Linux CAN interface (`vcan0`, `can0`,
/// or a userspace-bus interface such as `ucan0` when the ucan interposition library is loaded).
/// The only place that converts `CanFrame` to and from the kernel's `struct can_frame` /
/// `struct canfd_frame`; it uses nothing but the plain SocketCAN API (socket, ioctl, bind,
/// setsockopt, write, recvmsg, poll), which is what lets it run unchanged on the userspace bus.
///
/// Open() throws (a missing, down or non-CAN interface, a kernel without AF_CAN: fixable setup
/// errors). Send()/Receive() never throw and never abort on what comes off the wire: they
/// return a std::error_code and count what happened in stats().
///
/// Thread-safety: one thread may call Send() while another calls Receive() on the same object;
/// stats() may be called from any thread. Everything else is thread-compatible.

#include <cstdint>
#include <memory>
#include <string>
#include <system_error>
#include <vector>

#include "bus/can_frame.h"

namespace wheelhil::bus {

/// One kernel acceptance filter. A frame passes when (frame_id & mask) == (id & mask) and its
/// identifier format (11/29-bit) equals `extended`; `inverse` accepts exactly the frames that
/// would be rejected. Data and remote frames pass alike. A socket receives a frame when any of
/// its filters accepts it.
struct CanFilter {
  std::uint32_t id = 0;
  std::uint32_t mask = CanFrame::kMaxExtendedId;
  bool extended = false;
  bool inverse = false;
};

struct CanTransportOptions {
  bool fd_frames = false;    ///< CAN_RAW_FD_FRAMES: send and receive CAN FD frames too.
  bool receive_own = false;  ///< CAN_RAW_RECV_OWN_MSGS: receive the frames this socket sent.
  bool loopback = true;      ///< CAN_RAW_LOOPBACK: other local sockets see what we send.
  /// Empty: receive every frame. Otherwise at most 512 filters (CAN_RAW_FILTER_MAX).
  std::vector<CanFilter> filters;
  /// CAN_RAW_ERR_FILTER: CAN_ERR_* classes (linux/can/error.h) delivered as error frames;
  /// 0 = none. Error frames arrive with CanFrame::error set and the class bits in `id`.
  std::uint32_t error_mask = 0;
  /// Send() retries a write that failed with ENOBUFS (device queue full) or EAGAIN (socket
  /// send buffer full) up to this many times, waiting send_retry_initial_us, then doubling
  /// (for EAGAIN the wait is a poll for POLLOUT, which ends early when the buffer drains), and
  /// never waiting more than send_retry_budget_us in total. 0 = no retry.
  int send_retry_limit = 8;
  int send_retry_initial_us = 100;
  int send_retry_budget_us = 20000;
};

struct ReceivedFrame {
  CanFrame frame;
  /// Receive time, ns since the Unix epoch (CLOCK_REALTIME). From the kernel
  /// (SO_TIMESTAMPNS, or SO_TIMESTAMP in µs) when kernel_timestamp, else read in Receive().
  std::int64_t timestamp_ns = 0;
  bool kernel_timestamp = false;
  /// Interface the frame arrived on (from recvmsg's sockaddr_can); see InterfaceName().
  int ifindex = 0;
  /// One of this socket's own frames (receive_own: the kernel flags it MSG_CONFIRM). The
  /// kernel hands a frame to every socket of the interface in one pass: when its sender has it
  /// back, every other socket has it too.
  bool own = false;
};

struct TransportStats {
  std::uint64_t sent = 0;           ///< Frames written.
  std::uint64_t received = 0;       ///< Valid frames returned by Receive().
  std::uint64_t send_retries = 0;   ///< Writes retried after ENOBUFS / EAGAIN.
  std::uint64_t send_failures = 0;  ///< Send() calls that returned an error.
  std::uint64_t rx_invalid = 0;     ///< Received datagrams rejected (bad size, length, flags).
  /// Frames the kernel dropped because this socket's receive queue was full (SO_RXQ_OVFL);
  /// the kernel reports the total with the next frame that is queued, so it lags by one frame.
  std::uint64_t rx_kernel_drops = 0;
};

class SocketCanTransport {
 public:
  /// Opens `iface` (e.g. "vcan0"). Throws std::system_error with a message that names the
  /// interface and says how to fix it: not found (ENODEV), down ("ip link set can7 up"), not a
  /// CAN interface, no AF_CAN in this kernel (points at the userspace bus, `wheelhil exec`);
  /// std::invalid_argument for a bad name or bad options.
  static SocketCanTransport Open(const std::string& iface, const CanTransportOptions& options = {});

  SocketCanTransport(SocketCanTransport&& other) noexcept;
  SocketCanTransport& operator=(SocketCanTransport&& other) noexcept;
  SocketCanTransport(const SocketCanTransport&) = delete;
  SocketCanTransport& operator=(const SocketCanTransport&) = delete;
  ~SocketCanTransport();

  /// Writes one frame. Errors: std::errc::invalid_argument (frame not IsValid()),
  /// std::errc::operation_not_supported (FD frame without options.fd_frames), ENOBUFS/EAGAIN
  /// after the retry budget is spent, ENETDOWN, or any other errno from write(2).
  [[nodiscard]] std::error_code Send(const CanFrame& frame) noexcept;

  /// Reads one frame, waiting up to timeout_ms (0: do not wait, < 0: wait forever).
  /// Nothing there: std::errc::resource_unavailable_try_again (timeout_ms == 0) or
  /// std::errc::timed_out. A datagram that is not a valid frame: std::errc::bad_message
  /// (counted in rx_invalid; call again for the next one). Other errors: errno from recvmsg.
  [[nodiscard]] std::error_code Receive(ReceivedFrame& out, int timeout_ms) noexcept;

  /// Name of an interface index as seen in ReceivedFrame::ifindex; "" when unknown.
  std::string InterfaceName(int ifindex) const;

  int fd() const noexcept { return fd_; }
  int ifindex() const noexcept { return ifindex_; }
  const std::string& name() const noexcept { return name_; }
  const CanTransportOptions& options() const noexcept { return options_; }
  TransportStats stats() const noexcept;

 private:
  struct Counters;
  SocketCanTransport(int fd, int ifindex, std::string name, CanTransportOptions options);
  void Close() noexcept;

  int fd_ = -1;
  int ifindex_ = 0;
  std::string name_;
  CanTransportOptions options_;
  std::unique_ptr<Counters> counters_;
};

}  // namespace wheelhil::bus
