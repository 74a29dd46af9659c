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
/// Nothing a client sends or writes is trusted: a request may act only on the data connection
/// whose kOpen Reply carried its `token`; the rings' geometry and the broker's own indexes are
/// kept in the broker, the client's indexes are checked (a client that writes impossible ones
/// is disconnected). Connections are limited (UcanBrokerOptions): past a limit the broker
/// answers the first request with EMFILE and closes the connection.
///
/// Rings (v3, opt-in per data connection: Request::flags & kOpenRings): the kOpen Reply then
/// carries (SCM_RIGHTS) a sealed memfd holding a RingHeader and two rings of RingSlot: broker ->
/// client (slot = the message above: frame + RxTrailer) and client -> broker (frame + TxStamp
/// [+ TxAddress]). The socket stays the readiness signal and carries 8-byte doorbells (and, when
/// the client's ring is full, plain frame messages, merged by TxStamp). Invariant: a ring that
/// holds entries has a doorbell queued (or being sent) on its socket; spurious doorbells are
/// allowed. See docs/ucan.md "Rings".
///
/// Plain C layout, host byte order (both ends run on the same machine). No C++ runtime needed,
/// so the interposition library can include it.

#include <poll.h>
#include <pthread.h>
#include <sys/socket.h>

#include <atomic>
#include <cstddef>
#include <cstdint>

namespace wheelhil::bus::ucan {

inline constexpr char kSocketName[] = "ucan.sock";
inline constexpr char kLockName[] = "ucan.lock";
inline constexpr std::uint32_t kMagic = 0x34414355u;  // "UCA4" (v4: request tokens)
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
  kSetOptions = 2,    ///< Replace the CAN_RAW options of data client `client_id` (+ `token`).
  kResolveName = 3,   ///< name -> ifindex.
  kResolveIndex = 4,  ///< ifindex -> name.
  kAddBus = 5,        ///< Idempotent; replies with the ifindex. EPERM: control requests off.
  kRemoveBus = 6,     ///< Disconnects the bus's clients; ENODEV when unknown. EPERM: as above.
  kList = 7,          ///< Reply followed by `count` BusInfo records.
  kShutdown = 8,      ///< Stops the broker. EPERM: as above.
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
  std::uint32_t flags = 0;  ///< kOpen: kOpenRings, kOpenOwnBell.
  std::uint32_t reserved = 0;
  std::uint64_t token = 0;  ///< kSetOptions: the token of `client_id`'s kOpen Reply.
};

inline constexpr std::uint32_t kOpenRings = 1;
/// With kOpenRings: the Request carries (SCM_RIGHTS) one end of a socket pair the client made,
/// which the broker takes as its end of the data connection (the Reply still comes on the
/// connection the request came on, which the broker then closes; Reply::flags says it took
/// it). The client keeps a copy of that end, so it can ring its own socket's doorbell: a
/// firmware that moves its clock itself delivers the frames the broker put in its ring ahead
/// of their instants (runahead, docs/virtual-time.md).
inline constexpr std::uint32_t kOpenOwnBell = 2;
/// Set (to anything) in a client's environment: its sockets ask for kOpenOwnBell (the run puts
/// it in the firmware's environment when the firmware may run ahead).
inline constexpr char kOwnBellEnv[] = "WHEELHIL_UCAN_OWN_BELL";

struct Reply {
  std::uint32_t magic = kMagic;
  std::int32_t error = 0;  ///< 0 or an errno value.
  std::int32_t ifindex = 0;
  std::uint32_t client_id = 0;
  char name[kNameSize] = {};
  std::uint32_t count = 0;  ///< kList: BusInfo records that follow.
  std::uint32_t flags = 0;  ///< kOpen: kOpenOwnBell when the broker took the client's end.
  std::uint64_t token = 0;  ///< kOpen: a random secret; requests about this client quote it.
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

// ---- rings ----

inline constexpr std::size_t kDoorbellSize = 8;  ///< A doorbell message (content ignored).
inline constexpr std::size_t kSlotBytes = 120;

struct RingSlot {
  std::uint32_t len = 0;  ///< Bytes used in `bytes` (a message as on the socket).
  std::uint32_t reserved = 0;
  std::uint8_t bytes[kSlotBytes] = {};
};

/// One single-consumer or single-producer ring's indexes. `bell` = (doorbells triggered << 1)
/// | pending: a producer, after pushing (seq_cst), sends a doorbell only when it sets pending
/// (count + 1); consumers never set it. A client consumer that finds the ring empty right after
/// clearing pending discards only doorbells triggered before its clear (`bells_taken` counts
/// them), so a doorbell for a later push is never taken by mistake.
struct RingIndex {
  alignas(64) std::atomic<std::uint64_t> tail{0};  ///< Next slot to write (producer).
  alignas(64) std::atomic<std::uint64_t> head{0};  ///< Next slot to read (consumer).
  alignas(64) std::atomic<std::uint64_t> bell{0};
  std::uint64_t bells_taken = 0;  ///< Client consumers, under `lock`.
  pthread_mutex_t lock;           ///< Client side (threads, forked processes): robust, shared.
};

/// Client-writable: the broker reads only the client's indexes (rx.head, tx.tail, the bells)
/// and checks them; `slots` and its own indexes it keeps to itself.
struct RingHeader {
  std::uint32_t magic = kMagic;
  std::uint32_t slots = 0;               ///< Per ring, a power of two.
  std::atomic<std::uint32_t> closed{0};  ///< Set by the broker before it drops the connection.
  /// Set by a broker whose every pass drains the tx ring (an owner that pumps it and never
  /// waits in the pass for traffic): the client may leave out its tx doorbells. Only the
  /// client's own wake-up of the broker depends on it.
  std::atomic<std::uint32_t> tx_drained_every_pass{0};
  RingIndex rx;  ///< broker -> client
  RingIndex tx;  ///< client -> broker
  /// Runahead (kOpenOwnBell): frames the broker put in the rx ring ahead of their instants,
  /// from rx.tail (what the client sees) to here, each with its instant (RxInstants: the
  /// virtual CLOCK_MONOTONIC ns at which the firmware gets it). The client's library publishes
  /// them (moves rx.tail, rings its own doorbell) as it moves its clock to their instants; the
  /// broker takes the published ones for delivered and drops the rest when it has the clock
  /// again.
  alignas(64) std::atomic<std::uint64_t> rx_prepared_tail{0};
};

inline std::size_t RingBytes(std::uint32_t slots) {
  return (sizeof(RingHeader) + 63) / 64 * 64 + 2 * std::size_t{slots} * sizeof(RingSlot) +
         std::size_t{slots} * sizeof(std::int64_t);
}
inline RingSlot* RxSlots(RingHeader* h) {
  return reinterpret_cast<RingSlot*>(reinterpret_cast<std::uint8_t*>(h) +
                                     (sizeof(RingHeader) + 63) / 64 * 64);
}
/// `slots`: the geometry as the caller knows it (the broker never takes it from the header).
inline RingSlot* TxSlots(RingHeader* h, std::uint32_t slots) { return RxSlots(h) + slots; }
/// The instants of the rx slots put ahead (RingHeader::rx_prepared_tail), by slot.
inline std::int64_t* RxInstants(RingHeader* h, std::uint32_t slots) {
  return reinterpret_cast<std::int64_t*>(TxSlots(h, slots) + slots);
}

/// A producer's doorbell takes one compare-exchange unless the consumer clears `pending` at
/// the same moment; this many failures mean the other side keeps rewriting the word.
inline constexpr int kDoorbellTries = 64;

/// After a producer's pushes: 1 when it must send one doorbell, 0 when one is pending, -1 when
/// `max_tries` compare-exchanges failed (the other side keeps rewriting the word).
inline int RingTakeDoorbell(RingIndex& r, int max_tries) {
  std::atomic_thread_fence(std::memory_order_seq_cst);
  std::uint64_t w = r.bell.load();
  for (int i = 0; i < max_tries && !(w & 1); ++i) {
    if (r.bell.compare_exchange_weak(w, w + 3)) return 1;
  }
  return (w & 1) ? 0 : -1;
}

/// A client consumer, `lock` held, after it found the ring empty at `head` or took its last
/// entry: clears `pending`; if the ring is still empty after that, discards the doorbells
/// triggered before the clear (`discard_one()`: ReceiveDoorbell, false when none came: then a
/// later call discards it). Doorbells triggered after the clear announce later pushes and stay.
/// `between` runs between the clear and the re-check (tests widen that window with it).
template <typename DiscardOne, typename Between>
void RingSettle(RingIndex& r, std::uint64_t head, DiscardOne discard_one, Between between) {
  const std::uint64_t w = r.bell.fetch_and(~std::uint64_t{1});  // seq_cst
  between();
  if (r.tail.load() != head) return;  // entries: every doorbell stays
  const std::uint64_t triggered = w >> 1;
  while (r.bells_taken < triggered && discard_one()) ++r.bells_taken;
}

template <typename DiscardOne>
void RingSettle(RingIndex& r, std::uint64_t head, DiscardOne discard_one) {
  RingSettle(r, head, discard_one, [] {});
}

/// How long RingSettle's consumer waits for a doorbell on its way.
inline constexpr int kDoorbellInFlightMs = 1000;

/// One doorbell off socket `fd` for RingSettle: at once if it is there, else (the producer
/// sends one right after it took it with RingTakeDoorbell, so one counted and not yet here is on
/// its way) waiting up to `wait_ms` for it. Left to a later call, it would arrive after the
/// consumer emptied the ring: the socket readable with nothing to read, and a blocking receive
/// after a poll that said readable would wait for the next frame. `recv_fn(fd, buf, len, flags)`
/// and `poll_fn(pollfd*, nfds, timeout_ms)` as recv(2) and poll(2). False when none came.
template <typename RecvFn, typename PollFn>
bool ReceiveDoorbell(int fd, int wait_ms, RecvFn recv_fn, PollFn poll_fn) {
  std::uint64_t bell = 0;
  if (recv_fn(fd, &bell, sizeof(bell), MSG_DONTWAIT) == static_cast<long>(sizeof(bell))) {
    return true;
  }
  pollfd p{fd, POLLIN, 0};
  if (wait_ms <= 0 || poll_fn(&p, 1, wait_ms) <= 0) return false;
  return recv_fn(fd, &bell, sizeof(bell), MSG_DONTWAIT) == static_cast<long>(sizeof(bell));
}

static_assert(std::atomic<std::uint64_t>::is_always_lock_free);
static_assert(std::atomic<std::uint32_t>::is_always_lock_free);
static_assert(sizeof(RxTrailer) == 24);
static_assert(sizeof(TxAddress) == 8);
static_assert(sizeof(TxStamp) == 8);
static_assert(sizeof(Request) == 64);
static_assert(sizeof(Reply) == 48);
inline constexpr std::size_t kMaxRxMessage = kCanFdMtu + sizeof(RxTrailer);
static_assert(kMaxRxMessage <= kSlotBytes);
static_assert(kCanFdMtu + sizeof(TxStamp) + sizeof(TxAddress) <= kSlotBytes);

}  // namespace wheelhil::bus::ucan
