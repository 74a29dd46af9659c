#pragma once
/// Wire protocol of the userspace CAN bus ("ucan") between the broker (bus/ucan_broker.h) and
/// its clients (the interposition library bus/ucan_interpose.cc, `wheelhil bus`).
///
/// Transport: AF_UNIX SOCK_SEQPACKET connections to `<runtime dir>/ucan.sock`; message
/// boundaries are kept by the kernel, so one message is one frame or one request.
///
/// Every connection starts with one Request. kOpen turns the connection into a data connection:
///   client -> broker: `struct can_frame` (16 bytes) or `struct canfd_frame` (72 bytes), then a
///                     TxStamp (24 / 80 bytes) for the bound bus, or frame + TxStamp + TxAddress
///                     (32 / 88 bytes) to send on another bus (sockets bound to "any"). Any other
///                     size is counted as a bad message and ignored.
///   broker -> client: the frame (16 / 72 bytes) followed by an RxTrailer (24 bytes).
/// All other ops are one request, one Reply, then the broker closes the connection.
///
/// Plain C layout, host byte order (both ends run on the same machine). No C++ runtime needed,
/// so the interposition library can include it.

#include <cstddef>
#include <cstdint>

namespace wheelhil::bus::ucan {

inline constexpr char kSocketName[] = "ucan.sock";
inline constexpr char kLockName[] = "ucan.lock";
inline constexpr std::uint32_t kMagic = 0x32414355u;  // "UCA2" (v2: frames carry a TxStamp)
inline constexpr std::size_t kNameSize = 16;          // IFNAMSIZ, including the NUL
inline constexpr std::size_t kCanMtu = 16;            // sizeof(struct can_frame)
inline constexpr std::size_t kCanFdMtu = 72;          // sizeof(struct canfd_frame)
inline constexpr std::uint32_t kMaxFilters = 512;     // CAN_RAW_FILTER_MAX
/// Interface indexes: "ucanN" (N < 1000) gets 1000 + N; any other name 2000 + creation order.
inline constexpr int kFirstIfindex = 1000;
inline constexpr int kFirstNamedIfindex = 2000;
/// Reply timeout for a request, ms.
inline constexpr int kRequestTimeoutMs = 5000;

enum class Op : std::uint32_t {
  kOpen = 1,          ///< Become a data connection on `name` ("" = any bus, ifindex 0).
  kSetOptions = 2,    ///< Replace the CAN_RAW options of data client `client_id`.
  kResolveName = 3,   ///< name -> ifindex.
  kResolveIndex = 4,  ///< ifindex -> name.
  kAddBus = 5,        ///< Idempotent; replies with the ifindex.
  kRemoveBus = 6,     ///< Disconnects the bus's clients; ENODEV when unknown.
  kList = 7,          ///< Reply followed by `count` BusInfo records.
  kShutdown = 8,      ///< Stops the broker.
};

/// The CAN_RAW socket options the broker applies (filters follow the Request).
struct RawOptions {
  std::uint32_t err_mask = 0;
  std::uint8_t loopback = 1;
  std::uint8_t recv_own = 0;
  std::uint8_t fd_frames = 0;
  std::uint8_t join_filters = 0;
  /// Number of `struct can_filter` {u32 can_id; u32 can_mask} records after the Request
  /// (a new socket has one: {0, 0}, receive everything).
  std::uint32_t filter_count = 0;
};

struct Request {
  std::uint32_t magic = kMagic;
  Op op = Op::kOpen;
  char name[kNameSize] = {};
  std::int32_t ifindex = 0;
  std::uint32_t client_id = 0;
  RawOptions options;
};

struct Reply {
  std::uint32_t magic = kMagic;
  std::int32_t error = 0;  ///< 0 or an errno value.
  std::int32_t ifindex = 0;
  std::uint32_t client_id = 0;
  char name[kNameSize] = {};
  std::uint32_t count = 0;  ///< kList: BusInfo records that follow.
  std::uint32_t reserved = 0;
};

struct BusInfo {
  char name[kNameSize] = {};
  std::int32_t ifindex = 0;
  std::uint32_t clients = 0;
  std::uint64_t frames = 0;        ///< Frames accepted on the bus.
  std::uint64_t drops = 0;         ///< Deliveries dropped because a reader's queue was full.
  std::uint64_t bad_messages = 0;  ///< Client messages rejected (bad size, invalid frame).
};

inline constexpr std::uint32_t kRxOwn = 1;  ///< The receiving socket sent this frame.

struct RxTrailer {
  std::int32_t ifindex = 0;
  std::uint32_t flags = 0;
  std::int64_t timestamp_ns = 0;  ///< CLOCK_REALTIME at the broker, non-decreasing per bus.
  std::uint32_t drops = 0;        ///< Frames dropped for this socket so far (SO_RXQ_OVFL).
  std::uint32_t magic = kMagic;
};

/// Follows every frame a client sends: CLOCK_MONOTONIC ns taken right before the send() (vDSO).
/// The broker dispatches in stamp order, so a write that returned before another began is
/// delivered first even when the two went through different connections (docs/ucan.md).
struct TxStamp {
  std::int64_t monotonic_ns = 0;
};

struct TxAddress {
  std::int32_t ifindex = 0;
  std::uint32_t magic = kMagic;
};

static_assert(sizeof(RxTrailer) == 24);
static_assert(sizeof(TxAddress) == 8);
static_assert(sizeof(TxStamp) == 8);
inline constexpr std::size_t kMaxRxMessage = kCanFdMtu + sizeof(RxTrailer);

}  // namespace wheelhil::bus::ucan
