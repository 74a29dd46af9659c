// libwheelhil_ucan.so: makes the plain SocketCAN API (PF_CAN / SOCK_RAW / CAN_RAW) work on the
// userspace CAN bus of bus/ucan_broker.h, preloaded (LD_PRELOAD) or linked into a program.
//
// A ucan socket IS a real fd: socket(PF_CAN, SOCK_RAW, CAN_RAW) returns an AF_UNIX
// SOCK_SEQPACKET placeholder; bind() to a ucan bus replaces it (dup3) by a connection to the
// broker, so poll/select/epoll/fcntl/dup work unchanged. The broker applies the filters; each
// message it sends is a frame plus an RxTrailer, which the recv* wrappers strip, returning what
// the kernel would (address, SCM_TIMESTAMP[NS], SCM_TIMESTAMPING, SO_RXQ_OVFL, MSG_DONTROUTE /
// MSG_CONFIRM).
// bind() to a name that is not a ucan bus opens a real PF_CAN socket in place (options replayed)
// or fails with the kernel's own error.
//
// Per-fd state lives in a table indexed by fd, guarded by one mutex (fork-safe through
// pthread_atfork); a lock-free byte per fd keeps the fast path for other fds to one load.
// No global objects with constructors: the library is loaded into python, candump, ...
//
// One file on purpose (~1300 lines): an interposition library is one translation unit of
// exported libc symbols over one fd table and its lock; every wrapper below depends on both.

#include <dlfcn.h>
#include <fcntl.h>
#include <linux/can.h>
#include <linux/can/raw.h>
#include <linux/close_range.h>
#include <linux/net_tstamp.h>
#include <net/if.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <stdarg.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/uio.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <new>

#include "bus/internal/interpose_real.h"
#include "bus/internal/passed_fd.h"
#include "bus/internal/peer_symbol.h"
#include "bus/ucan_protocol.h"
#include "bus/ucan_runtime_dir.h"
#include "bus/vtime_protocol.h"

#define UCAN_EXPORT extern "C" __attribute__((visibility("default")))

namespace {

namespace ucan = wheelhil::bus::ucan;
namespace internal = wheelhil::bus::internal;

constexpr int kMaxFds = 1 << 16;
constexpr int kSoTimestampOld = 29;
constexpr int kSoTimestampNsOld = 35;
constexpr int kSoTimestampNew = 63;
constexpr int kSoTimestampNsNew = 64;
constexpr int kSoRxqOvfl = 40;
constexpr int kSoTimestampingOld = 37;      // SCM_TIMESTAMPING_OLD: struct scm_timestamping
constexpr int kSoTimestampingNew = 65;      // SCM_TIMESTAMPING_NEW: the same layout on 64-bit
constexpr unsigned short kArphrdCan = 280;  // ARPHRD_CAN
constexpr unsigned long kSiocgstampOld = 0x8906;
constexpr unsigned long kSiocgstampNsOld = 0x8907;
constexpr unsigned long kSiocgstampNew = _IOR(0x89, 0x06, long long[2]);
constexpr unsigned long kSiocgstampNsNew = _IOR(0x89, 0x07, long long[2]);

// ---- the real functions (bus/internal/interpose_real.h) ----

using wheelhil::bus::interpose::Resolve;

REAL_FN(socket, int, (int, int, int))
REAL_FN(bind, int, (int, const sockaddr*, socklen_t))
REAL_FN(close, int, (int))
REAL_FN(dup, int, (int))
REAL_FN(dup2, int, (int, int))
REAL_FN(dup3, int, (int, int, int))
REAL_FN(fcntl, int, (int, int, ...))
REAL_FN(fcntl64, int, (int, int, ...))
REAL_FN(ioctl, int, (int, unsigned long, ...))
REAL_FN(setsockopt, int, (int, int, int, const void*, socklen_t))
REAL_FN(getsockopt, int, (int, int, int, void*, socklen_t*))
REAL_FN(getsockname, int, (int, sockaddr*, socklen_t*))
REAL_FN(read, ssize_t, (int, void*, size_t))
REAL_FN(write, ssize_t, (int, const void*, size_t))
REAL_FN(send, ssize_t, (int, const void*, size_t, int))
REAL_FN(sendto, ssize_t, (int, const void*, size_t, int, const sockaddr*, socklen_t))
REAL_FN(sendmsg, ssize_t, (int, const msghdr*, int))
REAL_FN(recv, ssize_t, (int, void*, size_t, int))
REAL_FN(recvfrom, ssize_t, (int, void*, size_t, int, sockaddr*, socklen_t*))
REAL_FN(recvmsg, ssize_t, (int, msghdr*, int))
REAL_FN(readv, ssize_t, (int, const iovec*, int))
REAL_FN(writev, ssize_t, (int, const iovec*, int))
REAL_FN(sendmmsg, int, (int, mmsghdr*, unsigned, int))
REAL_FN(recvmmsg, int, (int, mmsghdr*, unsigned, int, timespec*))
REAL_FN(if_nametoindex, unsigned, (const char*))
REAL_FN(if_indextoname, char*, (unsigned, char*))
REAL_FN(clock_gettime, int, (clockid_t, timespec*))
REAL_FN(poll, int, (pollfd*, nfds_t, int))

// ---- per-fd state ----

/// The shared-memory rings of a bound socket (bus/ucan_protocol.h "Rings"); refcounted because
/// a data call keeps using them outside the table lock while another thread may rebind/close.
/// `refs` is atomic: references are taken under the table lock (from a socket, which holds one
/// while the rings are attached) but may be dropped without it.
struct MappedRings {
  int refs = 1;
  ucan::RingHeader* header = nullptr;
  std::size_t bytes = 0;
  /// kOpenOwnBell: a copy of the broker's end of the socket's connection (writing to it makes
  /// the socket readable), -1 without.
  int bell_fd = -1;
  std::uint32_t client_id = 0;
};

/// Rings with their own doorbell (runahead: frames put ahead), under g_lock.
constexpr int kMaxBellRings = 64;
MappedRings* g_bell_rings[kMaxBellRings];
int g_bell_rings_used = 0;

/// With or without the lock. The last reference unmaps: by then no socket in the table points
/// to the rings, so no one can take a new reference.
void ReleaseRings(MappedRings* m) {
  if (m != nullptr && __atomic_sub_fetch(&m->refs, 1, __ATOMIC_ACQ_REL) == 0) {
    if (m->bell_fd >= 0) {
      for (int i = 0; i < g_bell_rings_used; ++i) {
        if (g_bell_rings[i] == m) g_bell_rings[i] = g_bell_rings[--g_bell_rings_used];
      }
      real_close()(m->bell_fd);
    }
    ::munmap(m->header, m->bytes);
    delete m;
  }
}

struct UcanSocket {
  int refs = 1;
  int type_flags = 0;  // SOCK_NONBLOCK | SOCK_CLOEXEC given to socket()
  bool bound = false;
  int ifindex = 0;
  char name[ucan::kNameSize] = {};
  std::uint32_t client_id = 0;
  std::uint64_t token = 0;  // the broker's kOpen Reply: quoted by kSetOptions
  ucan::RawOptions options;
  can_filter* filters = nullptr;  // options.filter_count entries (malloc'd)
  int timestamp_mode = 0;         // 0 none, 1 us, 2 ns
  int timestamp_cmsg = 0;         // SCM type to emit
  int timestamping = 0;           // SO_TIMESTAMPING flags (SOF_TIMESTAMPING_*)
  int timestamping_cmsg = 0;      // SCM_TIMESTAMPING type to emit (the option set)
  bool rxq_ovfl = false;
  MappedRings* rings = nullptr;  // bound with rings
};

void LockTable();
void UnlockTable();

/// What the data path needs, copied out under the lock (holds a reference to the rings).
struct View {
  bool bound = false;
  int ifindex = 0;
  std::uint32_t client_id = 0;
  bool fd_frames = false;
  int timestamp_mode = 0;
  int timestamp_cmsg = 0;
  int timestamping = 0;
  int timestamping_cmsg = 0;
  bool rxq_ovfl = false;
  char name[ucan::kNameSize] = {};
  MappedRings* rings = nullptr;
  View() = default;
  View(const View&) = delete;
  View& operator=(const View&) = delete;
  ~View() { ReleaseRings(rings); }  // no table lock: one less lock round per data call
};

pthread_mutex_t g_lock = PTHREAD_MUTEX_INITIALIZER;
unsigned char g_is_ucan[kMaxFds];
UcanSocket* g_sockets[kMaxFds];
std::int64_t g_last_ts_ns[kMaxFds];

void LockTable() { pthread_mutex_lock(&g_lock); }
void UnlockTable() { pthread_mutex_unlock(&g_lock); }

__attribute__((constructor)) void InstallForkHandlers() {
  pthread_atfork(LockTable, UnlockTable, UnlockTable);
}

inline bool IsUcan(int fd) {
  return fd >= 0 && fd < kMaxFds && __atomic_load_n(&g_is_ucan[fd], __ATOMIC_ACQUIRE) != 0;
}

void Release(UcanSocket* s) {
  if (s != nullptr && --s->refs == 0) {
    free(s->filters);
    ReleaseRings(s->rings);
    delete s;
  }
}

/// Before and after every call the broker sees on a socket rather than in a ring (a
/// connection, a frame sent or received as a message, a doorbell for it, a close): the virtual
/// clock's library (bus/vtime_interpose.cc) counts them, so the emulator knows when a look at
/// the sockets can find nothing new from the firmware. Counted after the call as well: a look
/// taken between the count and the call's effect did not see it. Nothing without that library.
internal::PeerSymbol<void (*)()> g_vtime_note_bus_call("wheelhil_vtime_note_bus_call");
void NoteBusCall() {
  if (auto f = g_vtime_note_bus_call.get()) f();
}

/// `call()` (a system call on a socket of the broker's), counted before and after it.
template <typename Call>
auto BrokerSocketCall(Call&& call) {
  NoteBusCall();
  const auto rc = call();
  const int err = errno;
  NoteBusCall();
  errno = err;
  return rc;
}

/// Every frame sent counts for the virtual clock's library (Page::bus_sends): while the firmware
/// runs ahead on its own clock, a send gives the clock back to the emulator unless the library
/// finds it cannot change what the emulator prepared (`frame`: the frame as written, nullptr
/// for one sent another way than through the socket's ring).
internal::PeerSymbol<void (*)(const void*, std::size_t)> g_vtime_note_frame_sent(
    "wheelhil_vtime_note_frame_sent");
void NoteFrameSent(const void* frame, std::size_t frame_len) {
  if (auto f = g_vtime_note_frame_sent.get()) f(frame, frame_len);
}

/// The run asked for runahead (ucan::kOwnBellEnv) and the virtual clock's library is loaded:
/// the firmware may move the clock itself and deliver the frames the broker put ahead in its
/// rings (kOpenOwnBell).
bool OwnBellWanted() {
  static const bool wanted =
      getenv(ucan::kOwnBellEnv) != nullptr && g_vtime_note_frame_sent.get() != nullptr;
  return wanted;
}

/// Lock held. Drops fd's reference, if any.

void DetachLocked(int fd) {
  if (fd < 0 || fd >= kMaxFds || g_sockets[fd] == nullptr) return;
  NoteBusCall();
  __atomic_store_n(&g_is_ucan[fd], 0, __ATOMIC_RELEASE);
  Release(g_sockets[fd]);
  g_sockets[fd] = nullptr;
  g_last_ts_ns[fd] = 0;
}

/// Lock held.
void AttachLocked(int fd, UcanSocket* s) {
  DetachLocked(fd);
  g_sockets[fd] = s;
  g_last_ts_ns[fd] = 0;
  __atomic_store_n(&g_is_ucan[fd], 1, __ATOMIC_RELEASE);
}

void ShareFd(int from, int to) {
  if (to < 0 || to >= kMaxFds || from == to) return;
  LockTable();
  if (from >= 0 && from < kMaxFds && g_sockets[from] != nullptr) {
    UcanSocket* s = g_sockets[from];
    ++s->refs;
    AttachLocked(to, s);
  } else {
    DetachLocked(to);
  }
  UnlockTable();
}

bool GetView(int fd, View* v) {
  if (!IsUcan(fd)) return false;
  bool ok = false;
  LockTable();
  if (const UcanSocket* s = g_sockets[fd]) {
    v->bound = s->bound;
    v->ifindex = s->ifindex;
    v->client_id = s->client_id;
    v->fd_frames = s->options.fd_frames != 0;
    v->timestamp_mode = s->timestamp_mode;
    v->timestamp_cmsg = s->timestamp_cmsg;
    v->timestamping = s->timestamping;
    v->timestamping_cmsg = s->timestamping_cmsg;
    v->rxq_ovfl = s->rxq_ovfl;
    std::memcpy(v->name, s->name, sizeof(v->name));
    if (s->rings != nullptr) {
      __atomic_add_fetch(&s->rings->refs, 1, __ATOMIC_RELAXED);
      v->rings = s->rings;
    }
    ok = true;
  }
  UnlockTable();
  return ok;
}

// ---- broker requests ----

/// Connects to the broker of the current runtime directory. -1 and errno when there is none
/// (or the directory is not private).
int ConnectBroker() {
  std::string dir;
  try {
    dir = wheelhil::bus::ResolveUcanRuntimeDir();
  } catch (...) {
    errno = ENOMEM;
    return -1;
  }
  if (auto ec = wheelhil::bus::VerifyUcanRuntimeDir(dir)) {
    errno = ENOENT;
    return -1;
  }
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  const std::string path = dir + "/" + ucan::kSocketName;
  if (path.size() >= sizeof(addr.sun_path)) {
    errno = ENAMETOOLONG;
    return -1;
  }
  std::memcpy(addr.sun_path, path.c_str(), path.size() + 1);
  const int s = real_socket()(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0);
  if (s < 0) return -1;
  if (BrokerSocketCall(
          [&] { return ::connect(s, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)); }) != 0) {
    const int err = errno;
    real_close()(s);
    errno = err;
    return -1;
  }
  return s;
}

/// Sends `req` (+ filters) and waits for the reply. Returns the connected socket (caller
/// closes) or -1 with errno. A broker-side refusal is reported in reply->error.
int Transact(const ucan::Request& req, const can_filter* filters, ucan::Reply* reply,
             void* extra = nullptr, std::size_t extra_cap = 0, int* passed_fd = nullptr,
             int send_fd = -1) {
  if (passed_fd != nullptr) *passed_fd = -1;
  const int s = ConnectBroker();
  if (s < 0) return -1;
  iovec iov[2] = {
      {const_cast<ucan::Request*>(&req), sizeof(req)},
      {const_cast<can_filter*>(filters), req.options.filter_count * sizeof(can_filter)}};
  msghdr msg{};
  msg.msg_iov = iov;
  msg.msg_iovlen = (filters != nullptr && req.options.filter_count > 0) ? 2 : 1;
  internal::PassedFdControl send_control;
  if (send_fd >= 0) internal::AttachFd(msg, send_control, send_fd);
  if (BrokerSocketCall([&] { return real_sendmsg()(s, &msg, MSG_NOSIGNAL); }) < 0 &&
      errno != EPIPE && errno != ECONNRESET) {
    const int err = errno;
    real_close()(s);
    errno = err;
    return -1;
  }
  // EPIPE / ECONNRESET: a broker that refuses the connection (its limits) answers before it
  // reads the request and closes: the answer is waiting below.
  pollfd p{s, POLLIN, 0};
  int rc = 0;
  do {
    rc = ::poll(&p, 1, ucan::kRequestTimeoutMs);
  } while (rc < 0 && errno == EINTR);
  iovec riov[2] = {{reply, sizeof(*reply)}, {extra, extra_cap}};
  msghdr rmsg{};
  rmsg.msg_iov = riov;
  rmsg.msg_iovlen = extra != nullptr ? 2 : 1;
  internal::PassedFdControl control;
  internal::ExpectFd(rmsg, control);
  ssize_t n = rc == 1 ? real_recvmsg()(s, &rmsg, MSG_DONTWAIT | MSG_CMSG_CLOEXEC) : -1;
  // A socket closed with our request unread reports ECONNRESET once, before the reply.
  if (n < 0 && errno == ECONNRESET) n = real_recvmsg()(s, &rmsg, MSG_DONTWAIT | MSG_CMSG_CLOEXEC);
  if (const int got = n >= 0 ? internal::ReceivedFd(rmsg) : -1; got >= 0) {
    if (passed_fd != nullptr) {
      *passed_fd = got;
    } else {
      real_close()(got);
    }
  }
  if (n < static_cast<ssize_t>(sizeof(*reply)) || reply->magic != ucan::kMagic) {
    if (passed_fd != nullptr && *passed_fd >= 0) {
      real_close()(*passed_fd);
      *passed_fd = -1;
    }
    real_close()(s);
    errno = rc == 0 ? ETIMEDOUT : EIO;
    return -1;
  }
  return s;
}

/// name -> ifindex on the ucan broker; 0 when it is not a ucan bus (`*refused` = EMFILE when
/// the broker refused the connection: its limits, see bus/ucan_broker.h).
int ResolveName(const char* name, int* refused = nullptr) {
  ucan::Request req;
  req.op = ucan::Op::kResolveName;
  std::strncpy(req.name, name, ucan::kNameSize - 1);
  ucan::Reply reply;
  const int saved = errno;
  const int s = Transact(req, nullptr, &reply);
  errno = saved;
  if (s < 0) return 0;
  real_close()(s);
  if (refused != nullptr && reply.error == EMFILE) *refused = EMFILE;
  return reply.error == 0 ? reply.ifindex : 0;
}

/// ifindex -> name; false when it is not a ucan bus (`*refused` as for ResolveName).
bool ResolveIndex(int ifindex, char (&name)[ucan::kNameSize], int* refused = nullptr) {
  if (ifindex <= 0) return false;
  ucan::Request req;
  req.op = ucan::Op::kResolveIndex;
  req.ifindex = ifindex;
  ucan::Reply reply;
  const int saved = errno;
  const int s = Transact(req, nullptr, &reply);
  errno = saved;
  if (s < 0) return false;
  real_close()(s);
  if (refused != nullptr && reply.error == EMFILE) *refused = EMFILE;
  if (reply.error != 0) return false;
  std::memcpy(name, reply.name, sizeof(name));
  name[ucan::kNameSize - 1] = '\0';
  return true;
}

/// Copies the socket's options under the lock (filters into `filters`, malloc'd).
bool SnapshotOptions(int fd, ucan::RawOptions* opts, can_filter** filters, int* type_flags,
                     std::uint32_t* client_id, bool* bound, std::uint64_t* token = nullptr) {
  bool ok = false;
  LockTable();
  if (UcanSocket* s = (fd >= 0 && fd < kMaxFds) ? g_sockets[fd] : nullptr) {
    *opts = s->options;
    *filters = nullptr;
    if (s->options.filter_count > 0) {
      const std::size_t bytes = s->options.filter_count * sizeof(can_filter);
      *filters = static_cast<can_filter*>(malloc(bytes));
      if (*filters != nullptr) std::memcpy(*filters, s->filters, bytes);
    }
    *type_flags = s->type_flags;
    *client_id = s->client_id;
    if (token != nullptr) *token = s->token;
    *bound = s->bound;
    ok = s->options.filter_count == 0 || *filters != nullptr;
  }
  UnlockTable();
  return ok;
}

/// Pushes the socket's CAN_RAW options to the broker (bound sockets only).
void SyncOptions(int fd) {
  ucan::RawOptions opts;
  can_filter* filters = nullptr;
  int type_flags = 0;
  std::uint32_t client_id = 0;
  bool bound = false;
  std::uint64_t token = 0;
  if (!SnapshotOptions(fd, &opts, &filters, &type_flags, &client_id, &bound, &token)) return;
  if (bound) {
    ucan::Request req;
    req.op = ucan::Op::kSetOptions;
    req.client_id = client_id;
    req.token = token;
    req.options = opts;
    ucan::Reply reply;
    const int saved = errno;
    const int s = Transact(req, filters, &reply);
    if (s >= 0) real_close()(s);
    errno = saved;
  }
  free(filters);
}

/// Replaces fd by a real PF_CAN socket (bind to a non-ucan interface). Returns 0 or errno.
int SwitchToKernel(int fd, const sockaddr* addr, socklen_t len) {
  ucan::RawOptions opts;
  can_filter* filters = nullptr;
  int type_flags = 0;
  std::uint32_t client_id = 0;
  bool bound = false;
  if (!SnapshotOptions(fd, &opts, &filters, &type_flags, &client_id, &bound)) return ENOMEM;
  int timestamp_mode = 0;
  int timestamp_cmsg = 0;
  int timestamping = 0;
  int timestamping_cmsg = 0;
  bool rxq_ovfl = false;
  LockTable();
  if (UcanSocket* s = g_sockets[fd]) {
    timestamp_mode = s->timestamp_mode;
    timestamp_cmsg = s->timestamp_cmsg;
    timestamping = s->timestamping;
    timestamping_cmsg = s->timestamping_cmsg;
    rxq_ovfl = s->rxq_ovfl;
  }
  UnlockTable();
  const int k = real_socket()(PF_CAN, SOCK_RAW | type_flags, CAN_RAW);
  if (k < 0) {
    const int err = errno;
    free(filters);
    return err;
  }
  auto set = real_setsockopt();
  const int on = 1;
  const int off = 0;
  set(k, SOL_CAN_RAW, CAN_RAW_FILTER, filters, opts.filter_count * sizeof(can_filter));
  if (opts.err_mask) set(k, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &opts.err_mask, sizeof(opts.err_mask));
  if (!opts.loopback) set(k, SOL_CAN_RAW, CAN_RAW_LOOPBACK, &off, sizeof(off));
  if (opts.recv_own) set(k, SOL_CAN_RAW, CAN_RAW_RECV_OWN_MSGS, &on, sizeof(on));
  if (opts.fd_frames) set(k, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &on, sizeof(on));
  if (opts.join_filters) set(k, SOL_CAN_RAW, CAN_RAW_JOIN_FILTERS, &on, sizeof(on));
  if (timestamp_mode != 0) set(k, SOL_SOCKET, timestamp_cmsg, &on, sizeof(on));
  if (timestamping != 0) {
    set(k, SOL_SOCKET, timestamping_cmsg, &timestamping, sizeof(timestamping));
  }
  if (rxq_ovfl) set(k, SOL_SOCKET, kSoRxqOvfl, &on, sizeof(on));
  free(filters);
  LockTable();
  const int rc = real_dup3()(k, fd, (type_flags & SOCK_CLOEXEC) ? O_CLOEXEC : 0);
  if (rc >= 0) DetachLocked(fd);
  UnlockTable();
  const int err = errno;
  real_close()(k);
  if (rc < 0) return err;
  return real_bind()(fd, addr, len) == 0 ? 0 : errno;
}

/// Rings unless WHEELHIL_UCAN_RINGS=0 (then every frame is one socket message, protocol v2 style).
bool RingsWanted() {
  const char* v = getenv("WHEELHIL_UCAN_RINGS");
  return v == nullptr || std::strcmp(v, "0") != 0;
}

/// Maps the broker's ring memfd; nullptr (plain messages) when it does not look right.
MappedRings* MapRings(int memfd) {
  struct stat st {};
  if (::fstat(memfd, &st) != 0 || st.st_size < static_cast<off_t>(sizeof(ucan::RingHeader))) {
    return nullptr;
  }
  const auto bytes = static_cast<std::size_t>(st.st_size);
  void* p = ::mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_SHARED, memfd, 0);
  if (p == MAP_FAILED) return nullptr;
  auto* h = static_cast<ucan::RingHeader*>(p);
  const std::uint32_t slots = h->slots;
  if (h->magic != ucan::kMagic || slots == 0 || (slots & (slots - 1)) != 0 ||
      ucan::RingBytes(slots) != bytes) {
    ::munmap(p, bytes);
    return nullptr;
  }
  auto* m = new (std::nothrow) MappedRings;
  if (m == nullptr) {
    ::munmap(p, bytes);
    return nullptr;
  }
  m->header = h;
  m->bytes = bytes;
  return m;
}

int BindUcan(int fd, const sockaddr* addr, socklen_t len) {
  if (addr == nullptr) return EFAULT;
  if (len < static_cast<socklen_t>(offsetof(sockaddr_can, can_ifindex) + sizeof(int))) {
    return EINVAL;
  }
  sockaddr_can sa{};
  std::memcpy(&sa, addr, std::min<std::size_t>(len, sizeof(sa)));
  if (sa.can_family != AF_CAN) return EINVAL;
  char name[ucan::kNameSize] = {};
  int refused = 0;
  if (sa.can_ifindex != 0 && !ResolveIndex(sa.can_ifindex, name, &refused)) {
    return refused != 0 ? refused : SwitchToKernel(fd, addr, len);
  }
  ucan::RawOptions opts;
  can_filter* filters = nullptr;
  int type_flags = 0;
  std::uint32_t client_id = 0;
  bool bound = false;
  if (!SnapshotOptions(fd, &opts, &filters, &type_flags, &client_id, &bound)) return ENOMEM;
  ucan::Request req;
  req.op = ucan::Op::kOpen;
  std::memcpy(req.name, name, sizeof(name));
  req.options = opts;
  if (RingsWanted()) req.flags |= ucan::kOpenRings;
  // Rings: a socket pair whose one end the broker takes as its end of the connection, so that
  // this library can ring the socket's own doorbell (kOpenOwnBell).
  int pair[2] = {-1, -1};
  if ((req.flags & ucan::kOpenRings) && OwnBellWanted() &&
      ::socketpair(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0, pair) == 0) {
    req.flags |= ucan::kOpenOwnBell;
  }
  ucan::Reply reply;
  int ring_fd = -1;
  int conn = Transact(req, filters, &reply, nullptr, 0, &ring_fd, pair[1]);
  MappedRings* rings = ring_fd >= 0 ? MapRings(ring_fd) : nullptr;
  if (ring_fd >= 0) real_close()(ring_fd);
  int data = conn;  // the connection the program's fd becomes
  if (conn >= 0 && reply.error == 0 && (reply.flags & ucan::kOpenOwnBell)) {
    // The broker's end of the connection is now the pair's: the program's fd is the other.
    data = pair[0];
    pair[0] = -1;
    LockTable();
    if (rings != nullptr && g_bell_rings_used < kMaxBellRings) {
      rings->bell_fd = pair[1];
      pair[1] = -1;
      rings->client_id = reply.client_id;
      g_bell_rings[g_bell_rings_used++] = rings;
    }
    UnlockTable();
  }
  for (int& end : pair) {
    if (end >= 0) real_close()(end);
    end = -1;
  }
  if (conn >= 0 && reply.error == 0 && (req.flags & ucan::kOpenRings) && rings == nullptr) {
    // Rings granted but not usable here (no fd passed: out of fds; mapping refused): the
    // broker would fill a ring nobody reads. Open again without them.
    real_close()(conn);
    if (data != conn && data >= 0) real_close()(data);
    req.flags &= ~(ucan::kOpenRings | ucan::kOpenOwnBell);
    conn = Transact(req, filters, &reply);
    data = conn;
  }
  free(filters);
  if (conn < 0) {
    // No broker: only "any" can get here (an index was resolved above); let the kernel say.
    return SwitchToKernel(fd, addr, len);
  }
  if (reply.error != 0) {
    real_close()(conn);
    if (data != conn && data >= 0) real_close()(data);
    if (rings != nullptr) {
      LockTable();
      ReleaseRings(rings);
      UnlockTable();
    }
    return reply.error == ENODEV ? SwitchToKernel(fd, addr, len) : reply.error;
  }
  const int fl = real_fcntl()(fd, F_GETFL);
  if (fl >= 0 && (fl & O_NONBLOCK)) real_fcntl()(data, F_SETFL, O_NONBLOCK);
  const int fdfl = real_fcntl()(fd, F_GETFD);
  LockTable();
  int rc = real_dup3()(data, fd, (fdfl >= 0 && (fdfl & FD_CLOEXEC)) ? O_CLOEXEC : 0);
  const int err = errno;
  if (rc >= 0) {
    if (UcanSocket* s = g_sockets[fd]) {
      s->bound = true;
      s->ifindex = reply.ifindex;
      std::memcpy(s->name, reply.name, sizeof(s->name));
      s->name[ucan::kNameSize - 1] = '\0';
      s->client_id = reply.client_id;
      s->token = reply.token;
      ReleaseRings(s->rings);
      s->rings = rings;
      rings = nullptr;
    }
  }
  ReleaseRings(rings);
  UnlockTable();
  real_close()(conn);
  if (data != conn) real_close()(data);
  return rc < 0 ? err : 0;
}

// ---- data path ----

ssize_t Fail(int err) {
  errno = err;
  return -1;
}

void LockRing(ucan::RingIndex& r) {
  if (pthread_mutex_lock(&r.lock) == EOWNERDEAD) pthread_mutex_consistent(&r.lock);
}

/// The program's CLOCK_MONOTONIC (virtual under libwheelhil_vtime.so): SO_RCVTIMEO deadlines.
std::int64_t MonotonicNow() {
  timespec now{};
  ::clock_gettime(CLOCK_MONOTONIC, &now);
  return static_cast<std::int64_t>(now.tv_sec) * 1000000000 + now.tv_nsec;
}

/// The host's CLOCK_MONOTONIC, whatever the program's clock is: TxStamps order frames against
/// the broker's own clock (libc's clock_gettime, past any interposer loaded before this one).
std::int64_t StampNow() {
  timespec now{};
  real_clock_gettime()(CLOCK_MONOTONIC, &now);
  return static_cast<std::int64_t>(now.tv_sec) * 1000000000 + now.tv_nsec;
}

/// The tx ring: `msg` is frame + room for the TxStamp at `frame_len` (+ TxAddress), `len` bytes
/// in all. Stamped under the ring lock, so the ring order is the stamp order. A full ring sends
/// the frame as a plain message (blocking like a full socket); the broker merges by stamp.
ssize_t RingSend(int fd, ucan::RingHeader* h, std::uint8_t* msg, std::size_t frame_len,
                 std::size_t len, int flags) {
  ucan::RingIndex& r = h->tx;
  LockRing(r);
  if (h->closed.load() != 0) {
    pthread_mutex_unlock(&r.lock);
    return Fail(ENETDOWN);
  }
  ucan::TxStamp stamp;
  stamp.monotonic_ns = StampNow();
  std::memcpy(msg + frame_len, &stamp, sizeof(stamp));
  const std::uint64_t tail = r.tail.load(std::memory_order_relaxed);
  if (tail - r.head.load(std::memory_order_acquire) >= h->slots) {
    NoteFrameSent(nullptr, 0);
    const ssize_t n = BrokerSocketCall(
        [&] { return real_send()(fd, msg, len, MSG_NOSIGNAL | (flags & MSG_DONTWAIT)); });
    const int err = errno;
    pthread_mutex_unlock(&r.lock);
    if (n < 0) {
      if (err == EPIPE || err == ECONNRESET || err == ENOTCONN) return Fail(ENETDOWN);
      return Fail(err);
    }
    return static_cast<ssize_t>(frame_len);
  }
  ucan::RingSlot& slot = ucan::TxSlots(h, h->slots)[tail & (h->slots - 1)];
  std::memcpy(slot.bytes, msg, len);
  slot.len = static_cast<std::uint32_t>(len);
  r.tail.store(tail + 1, std::memory_order_release);
  // Under the ring's lock: the sends the virtual clock's library lets through a window are
  // judged in the ring's order, the order the run takes them in.
  NoteFrameSent(len == frame_len + sizeof(ucan::TxStamp) ? msg : nullptr, frame_len);
  pthread_mutex_unlock(&r.lock);
  // A doorbell too many (-1: the word kept changing) is harmless: they may be spurious.
  if (ucan::RingTakeDoorbell(r, ucan::kDoorbellTries) != 0 &&
      h->tx_drained_every_pass.load(std::memory_order_relaxed) == 0) {
    const std::uint64_t bell = 1;
    if (BrokerSocketCall([&] {
          return real_send()(fd, &bell, sizeof(bell), MSG_NOSIGNAL | MSG_DONTWAIT);
        }) < 0 &&
        (errno == EPIPE || errno == ECONNRESET || errno == ENOTCONN)) {
      return Fail(ENETDOWN);
    }
  }
  return static_cast<ssize_t>(frame_len);
}

/// rx ring, lock held; the ring was found empty at `head` (or its last entry just taken).
void SettleRx(int fd, ucan::RingIndex& r, std::uint64_t head) {
  // libc's poll, past libwheelhil_vtime.so's: with the ring's lock held, its look at this
  // socket's ring (wheelhil_ucan_bus_socket_state) would wait for this very lock; and the wait
  // for a doorbell on its way is the library's own, a few microseconds, no wait of the program.
  ucan::RingSettle(r, head, [fd] {
    return ucan::ReceiveDoorbell(
        fd, ucan::kDoorbellInFlightMs,
        [](int s, void* b, std::size_t n, int fl) { return real_recv()(s, b, n, fl); },
        [](pollfd* p, nfds_t n, int ms) { return real_poll()(p, n, ms); });
  });
}

/// One message (frame + RxTrailer) from the rx ring into `buf`: its length, 0 at the end of
/// the connection, -1 with errno. Waits like the socket's recv would (O_NONBLOCK, MSG_DONTWAIT,
/// SO_RCVTIMEO -> EAGAIN), but in poll(): a blocking recv wakes one waiter per message, and a
/// waiter that leaves the doorbell queued (frames left) would leave the others asleep. So a
/// signal interrupts the wait with EINTR even under SA_RESTART (docs/ucan.md).
ssize_t RingRecv(int fd, ucan::RingHeader* h, std::uint8_t* buf, std::size_t cap, int flags) {
  ucan::RingIndex& r = h->rx;
  bool may_block = (flags & MSG_DONTWAIT) == 0;
  bool checked_mode = false;
  bool polled = false;            // the socket was found readable by the poll below
  std::int64_t deadline_ns = -1;  // SO_RCVTIMEO
  for (;;) {
    LockRing(r);
    const std::uint64_t head = r.head.load(std::memory_order_relaxed);
    const std::uint64_t tail = r.tail.load(std::memory_order_acquire);
    if (tail - head > h->slots) {
      pthread_mutex_unlock(&r.lock);
      return Fail(EIO);
    }
    if (head != tail) {
      const ucan::RingSlot& slot = ucan::RxSlots(h)[head & (h->slots - 1)];
      const std::size_t len = std::min<std::size_t>({slot.len, ucan::kSlotBytes, cap});
      std::memcpy(buf, slot.bytes, len);
      if (!(flags & MSG_PEEK)) {
        r.head.store(head + 1, std::memory_order_release);
        if (head + 1 == tail) SettleRx(fd, r, head + 1);
      }
      pthread_mutex_unlock(&r.lock);
      return static_cast<ssize_t>(len);
    }
    SettleRx(fd, r, head);
    pthread_mutex_unlock(&r.lock);
    if (h->closed.load() != 0) return 0;
    // A frame pushed after the look above is the next call's, as it would be on a kernel
    // socket: a call that may not wait needs no look at the doorbells (one system call less).
    if (flags & MSG_DONTWAIT) return Fail(EAGAIN);
    if (polled) {
      // Readable, yet the ring is empty: a doorbell for a push after the clear above (take
      // the frame), or the end of the connection.
      polled = false;
      std::uint64_t bell = 0;
      const ssize_t n = real_recv()(fd, &bell, sizeof(bell), MSG_PEEK | MSG_DONTWAIT);
      if (n == 0) return 0;  // the broker closed the connection
      if (n > 0) continue;
      if (errno != EAGAIN) return -1;
    }
    if (!checked_mode && may_block) {
      checked_mode = true;
      const int fl = real_fcntl()(fd, F_GETFL);
      if (fl >= 0 && (fl & O_NONBLOCK)) may_block = false;
      timeval tv{};
      socklen_t len = sizeof(tv);
      if (may_block && real_getsockopt()(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, &len) == 0 &&
          (tv.tv_sec > 0 || tv.tv_usec > 0)) {
        deadline_ns = MonotonicNow() + static_cast<std::int64_t>(tv.tv_sec) * 1000000000 +
                      static_cast<std::int64_t>(tv.tv_usec) * 1000;
      }
    }
    if (!may_block) return Fail(EAGAIN);
    int timeout_ms = -1;
    if (deadline_ns >= 0) {
      const std::int64_t left_ns = deadline_ns - MonotonicNow();
      if (left_ns <= 0) return Fail(EAGAIN);
      timeout_ms = static_cast<int>((left_ns + 999999) / 1000000);
    }
    // A doorbell still queued ends this poll at once.
    pollfd p{fd, POLLIN, 0};
    const int rc = ::poll(&p, 1, timeout_ms);
    if (rc < 0) return -1;  // EINTR
    polled = rc > 0;
  }
}

/// Writes one frame gathered from iov to the broker, with the kernel's checks.
ssize_t SendFrame(int fd, const View& v, const iovec* iov, std::size_t iovcnt, int flags,
                  const void* dest, socklen_t dest_len) {
  std::size_t total = 0;
  for (std::size_t i = 0; i < iovcnt; ++i) total += iov[i].iov_len;
  if (total != ucan::kCanMtu && total != ucan::kCanFdMtu) return Fail(EINVAL);
  if (total == ucan::kCanFdMtu && !v.fd_frames) return Fail(EINVAL);
  std::uint8_t buf[ucan::kCanFdMtu + sizeof(ucan::TxStamp) + sizeof(ucan::TxAddress)];
  std::size_t off = 0;
  for (std::size_t i = 0; i < iovcnt; ++i) {
    if (iov[i].iov_len == 0) continue;
    if (iov[i].iov_base == nullptr) return Fail(EFAULT);
    std::memcpy(buf + off, iov[i].iov_base, iov[i].iov_len);
    off += iov[i].iov_len;
  }
  if (buf[4] > (total == ucan::kCanMtu ? CAN_MAX_DLEN : CANFD_MAX_DLEN)) return Fail(EINVAL);
  int ifindex = v.ifindex;
  if (dest != nullptr) {
    if (dest_len < static_cast<socklen_t>(offsetof(sockaddr_can, can_ifindex) + sizeof(int))) {
      return Fail(EINVAL);
    }
    sockaddr_can sa{};
    std::memcpy(&sa, dest, std::min<std::size_t>(dest_len, sizeof(sa)));
    if (sa.can_family != AF_CAN) return Fail(EINVAL);
    ifindex = sa.can_ifindex;
  }
  if (ifindex == 0 || !v.bound) return Fail(ENXIO);
  std::size_t len = total + sizeof(ucan::TxStamp);
  if (ifindex != v.ifindex) {
    ucan::TxAddress to;
    to.ifindex = ifindex;
    std::memcpy(buf + len, &to, sizeof(to));
    len += sizeof(to);
  }
  if (v.rings != nullptr) return RingSend(fd, v.rings->header, buf, total, len, flags);
  NoteFrameSent(nullptr, 0);
  // Stamped last, right before the send: a write that returned before this one began has a
  // smaller stamp (see ucan::TxStamp).
  ucan::TxStamp stamp;
  stamp.monotonic_ns = StampNow();
  std::memcpy(buf + total, &stamp, sizeof(stamp));
  const ssize_t n = BrokerSocketCall(
      [&] { return real_send()(fd, buf, len, MSG_NOSIGNAL | (flags & MSG_DONTWAIT)); });
  if (n < 0) {
    if (errno == EPIPE || errno == ECONNRESET || errno == ENOTCONN) return Fail(ENETDOWN);
    return -1;
  }
  return static_cast<ssize_t>(total);
}

/// Appends one cmsg; false (and MSG_CTRUNC) when it does not fit.
bool PutCmsg(msghdr* msg, std::size_t* used, int level, int type, const void* data,
             std::size_t len) {
  const std::size_t space = CMSG_SPACE(len);
  if (msg->msg_control == nullptr || *used + CMSG_LEN(len) > msg->msg_controllen) {
    msg->msg_flags |= MSG_CTRUNC;
    return false;
  }
  auto* c = reinterpret_cast<cmsghdr*>(static_cast<std::uint8_t*>(msg->msg_control) + *used);
  c->cmsg_level = level;
  c->cmsg_type = type;
  c->cmsg_len = CMSG_LEN(len);
  std::memcpy(CMSG_DATA(c), data, len);
  *used += std::min(space, msg->msg_controllen - *used);
  return true;
}

/// Receives one frame into `msg` (msg_name, msg_control, msg_flags optional).
ssize_t RecvFrame(int fd, const View& v, msghdr* msg, int flags) {
  if (!v.bound) {
    // An unbound CAN_RAW socket never receives anything.
    const int fl = real_fcntl()(fd, F_GETFL);
    if ((flags & MSG_DONTWAIT) || (fl >= 0 && (fl & O_NONBLOCK))) return Fail(EAGAIN);
    ::ppoll(nullptr, 0, nullptr, nullptr);
    return Fail(EINTR);
  }
  std::uint8_t buf[ucan::kMaxRxMessage + 8];
  iovec iov{buf, sizeof(buf)};
  msghdr m{};
  m.msg_iov = &iov;
  m.msg_iovlen = 1;
  // A message taken off the socket makes room for the broker's next frame.
  const ssize_t n =
      v.rings != nullptr
          ? RingRecv(fd, v.rings->header, buf, sizeof(buf), flags)
          : BrokerSocketCall([&] {
              return real_recvmsg()(fd, &m, flags & (MSG_DONTWAIT | MSG_PEEK | MSG_WAITALL));
            });
  if (n < 0) {
    if (errno == ECONNRESET || errno == EPIPE) return Fail(ENETDOWN);
    return -1;
  }
  if (n == 0) return Fail(ENETDOWN);  // the broker closed the bus
  const std::size_t frame_len = static_cast<std::size_t>(n) - sizeof(ucan::RxTrailer);
  ucan::RxTrailer t;
  if (static_cast<std::size_t>(n) < sizeof(t) ||
      (frame_len != ucan::kCanMtu && frame_len != ucan::kCanFdMtu)) {
    return Fail(EIO);
  }
  std::memcpy(&t, buf + frame_len, sizeof(t));
  if (t.magic != ucan::kMagic) return Fail(EIO);
  std::size_t copied = 0;
  for (std::size_t i = 0; i < static_cast<std::size_t>(msg->msg_iovlen) && copied < frame_len;
       ++i) {
    const std::size_t k = std::min(msg->msg_iov[i].iov_len, frame_len - copied);
    if (k > 0) std::memcpy(msg->msg_iov[i].iov_base, buf + copied, k);
    copied += k;
  }
  int out_flags = MSG_DONTROUTE;
  if (t.flags & ucan::kRxOwn) out_flags |= MSG_CONFIRM;
  if (copied < frame_len) out_flags |= MSG_TRUNC;
  msg->msg_flags = out_flags;
  if (msg->msg_name != nullptr) {
    sockaddr_can sa{};
    sa.can_family = AF_CAN;
    sa.can_ifindex = t.ifindex;
    std::memcpy(msg->msg_name, &sa, std::min<std::size_t>(msg->msg_namelen, sizeof(sa)));
    msg->msg_namelen = sizeof(sa);
  }
  std::size_t used = 0;
  if (v.timestamp_mode == 1) {
    struct {
      std::int64_t sec, usec;
    } tv{t.timestamp_ns / 1000000000, (t.timestamp_ns % 1000000000) / 1000};
    PutCmsg(msg, &used, SOL_SOCKET, v.timestamp_cmsg, &tv, sizeof(tv));
  } else if (v.timestamp_mode == 2) {
    struct {
      std::int64_t sec, nsec;
    } ts{t.timestamp_ns / 1000000000, t.timestamp_ns % 1000000000};
    PutCmsg(msg, &used, SOL_SOCKET, v.timestamp_cmsg, &ts, sizeof(ts));
  }
  if (v.timestamping & SOF_TIMESTAMPING_SOFTWARE) {
    // struct scm_timestamping: the software receive stamp, then the legacy and the hardware
    // ones, which a CAN bus without a clock of its own leaves zero (as vcan does).
    struct {
      std::int64_t sec, nsec;
    } ts[3] = {{t.timestamp_ns / 1000000000, t.timestamp_ns % 1000000000}, {0, 0}, {0, 0}};
    PutCmsg(msg, &used, SOL_SOCKET, v.timestamping_cmsg, &ts, sizeof(ts));
  }
  if (v.rxq_ovfl && t.drops != 0) {
    PutCmsg(msg, &used, SOL_SOCKET, kSoRxqOvfl, &t.drops, sizeof(t.drops));
  }
  msg->msg_controllen = used;
  if (fd < kMaxFds) __atomic_store_n(&g_last_ts_ns[fd], t.timestamp_ns, __ATOMIC_RELAXED);
  return static_cast<ssize_t>((flags & MSG_TRUNC) ? frame_len : copied);
}

ssize_t RecvSimple(int fd, const View& v, void* buf, std::size_t len, int flags, sockaddr* from,
                   socklen_t* from_len) {
  iovec iov{buf, len};
  msghdr m{};
  m.msg_iov = &iov;
  m.msg_iovlen = 1;
  if (from != nullptr && from_len != nullptr) {
    m.msg_name = from;
    m.msg_namelen = *from_len;
  }
  const ssize_t n = RecvFrame(fd, v, &m, flags);
  if (n >= 0 && from != nullptr && from_len != nullptr) *from_len = m.msg_namelen;
  return n;
}

// Some bus socket of this process signals its input (O_ASYNC, FIOASYNC): a frame for it may
// interrupt any thread's wait (SIGIO), which the virtual clock's library must know.
std::atomic<bool> g_signals_on_input{false};

int DupFcntl(int fd, int cmd, int rc, void* arg) {
  if (rc >= 0 && (cmd == F_DUPFD || cmd == F_DUPFD_CLOEXEC) && IsUcan(fd)) ShareFd(fd, rc);
  if (rc >= 0 && cmd == F_SETFL && (reinterpret_cast<std::intptr_t>(arg) & O_ASYNC) && IsUcan(fd)) {
    g_signals_on_input.store(true);
  }
  return rc;
}

}  // namespace

// ---- the interposed API ----

/// What the virtual clock's library (bus/vtime_interpose.cc) needs to know of fd to tell a wait
/// only the host ends: 0, not a socket bound to a bus of the broker; 1, one with nothing to read
/// (its rx ring empty, no doorbell pending or left on the socket); 2, one that may have
/// something to read (or no rings to tell). Only the broker makes such a socket readable.
/// `*client_id`: its id on the broker (the wake channel the host counts its writes on). 3, for
/// any fd: some bus socket of the process signals its input (O_ASYNC), so a frame may end any
/// thread's wait.
/// Runahead (bus/vtime_interpose.cc): the earliest instant (virtual CLOCK_MONOTONIC ns) of a
/// frame the broker put ahead in this process's rings and not published yet; INT64_MAX none.
UCAN_EXPORT std::int64_t wheelhil_ucan_next_prepared_ns() {
  std::int64_t next = INT64_MAX;
  LockTable();
  for (int i = 0; i < g_bell_rings_used; ++i) {
    ucan::RingHeader* h = g_bell_rings[i]->header;
    const std::uint64_t tail = h->rx.tail.load(std::memory_order_relaxed);
    const std::uint64_t prepared = h->rx_prepared_tail.load(std::memory_order_acquire);
    if (prepared - tail - 1 >= h->slots) continue;  // none ahead (or nonsense)
    next = std::min(next, ucan::RxInstants(h, h->slots)[tail & (h->slots - 1)]);
  }
  UnlockTable();
  return next;
}

/// Runahead: the frames put ahead whose instant is at or before `until_ns` become visible,
/// received at `realtime_ns` (their RxTrailer's time), and their sockets' doorbells ring, as
/// the broker's delivery at that instant would. Returns the wake channels of those sockets
/// (vtime::BusSocketChannel), for the count of writes that may end a vouched wait.
UCAN_EXPORT std::uint32_t wheelhil_ucan_publish_prepared(std::int64_t until_ns,
                                                         std::int64_t realtime_ns) {
  std::uint32_t channels = 0;
  LockTable();
  for (int i = 0; i < g_bell_rings_used; ++i) {
    MappedRings* m = g_bell_rings[i];
    ucan::RingHeader* h = m->header;
    const std::uint32_t slots = h->slots;
    const std::uint64_t prepared = h->rx_prepared_tail.load(std::memory_order_acquire);
    std::uint64_t tail = h->rx.tail.load(std::memory_order_relaxed);
    const std::uint64_t from = tail;
    if (prepared - tail > slots) continue;  // nonsense: the broker's to find
    while (tail != prepared && ucan::RxInstants(h, slots)[tail & (slots - 1)] <= until_ns) {
      ucan::RingSlot& slot = ucan::RxSlots(h)[tail & (slots - 1)];
      if (slot.len >= sizeof(ucan::RxTrailer) && slot.len <= ucan::kSlotBytes) {
        std::memcpy(slot.bytes + slot.len - sizeof(ucan::RxTrailer) +
                        offsetof(ucan::RxTrailer, timestamp_ns),
                    &realtime_ns, sizeof(realtime_ns));
      }
      ++tail;
    }
    if (tail == from) continue;
    h->rx.tail.store(tail, std::memory_order_release);
    if (ucan::RingTakeDoorbell(h->rx, ucan::kDoorbellTries) != 0) {
      const std::uint64_t bell = 1;
      (void)real_send()(m->bell_fd, &bell, sizeof(bell), MSG_NOSIGNAL | MSG_DONTWAIT);
    }
    channels |= wheelhil::bus::vtime::BusSocketChannel(m->client_id);
  }
  UnlockTable();
  return channels;
}

UCAN_EXPORT int wheelhil_ucan_bus_socket_state(int fd, std::uint32_t* client_id) {
  if (g_signals_on_input.load(std::memory_order_relaxed)) return 3;
  View v;
  if (!GetView(fd, &v) || !v.bound) return 0;
  *client_id = v.client_id;
  if (v.rings == nullptr) return 2;
  ucan::RingIndex& rx = v.rings->header->rx;
  LockRing(rx);
  const std::uint64_t bell = rx.bell.load();
  const bool empty =
      rx.tail.load() == rx.head.load() && (bell & 1) == 0 && rx.bells_taken >= (bell >> 1);
  pthread_mutex_unlock(&rx.lock);
  return empty ? 1 : 2;
}

UCAN_EXPORT int socket(int domain, int type, int protocol) {
  if (domain != PF_CAN || (type & 0xF) != SOCK_RAW || protocol != CAN_RAW) {
    return real_socket()(domain, type, protocol);
  }
  const int flags = type & (SOCK_NONBLOCK | SOCK_CLOEXEC);
  const int fd = real_socket()(AF_UNIX, SOCK_SEQPACKET | flags, 0);
  if (fd < 0) return fd;
  if (fd >= kMaxFds) {
    real_close()(fd);
    errno = EMFILE;
    return -1;
  }
  auto* s = new (std::nothrow) UcanSocket;
  auto* all = static_cast<can_filter*>(malloc(sizeof(can_filter)));
  if (s == nullptr || all == nullptr) {
    delete s;
    free(all);
    real_close()(fd);
    errno = ENOMEM;
    return -1;
  }
  all[0] = {0, 0};
  s->filters = all;
  s->options.filter_count = 1;
  s->type_flags = flags;
  LockTable();
  AttachLocked(fd, s);
  UnlockTable();
  return fd;
}

UCAN_EXPORT int bind(int fd, const sockaddr* addr, socklen_t len) {
  if (!IsUcan(fd)) return real_bind()(fd, addr, len);
  const int err = BindUcan(fd, addr, len);
  if (err != 0) {
    errno = err;
    return -1;
  }
  return 0;
}

UCAN_EXPORT int close(int fd) {
  if (!IsUcan(fd)) return real_close()(fd);
  LockTable();
  DetachLocked(fd);
  UnlockTable();
  return BrokerSocketCall([&] { return real_close()(fd); });
}

UCAN_EXPORT int close_range(unsigned first, unsigned last, int flags) {
  using Fn = int (*)(unsigned, unsigned, int);
  static Fn real = nullptr;
  Fn f = Resolve(real, "close_range");
  const int rc = f != nullptr ? f(first, last, flags) : static_cast<int>(Fail(ENOSYS));
  if (rc == 0 && !(flags & CLOSE_RANGE_CLOEXEC)) {
    LockTable();
    for (unsigned fd = first; fd <= last && fd < static_cast<unsigned>(kMaxFds); ++fd) {
      DetachLocked(static_cast<int>(fd));
    }
    UnlockTable();
  }
  return rc;
}

UCAN_EXPORT void closefrom(int lowfd) {
  using Fn = void (*)(int);
  static Fn real = nullptr;
  if (Fn f = Resolve(real, "closefrom")) f(lowfd);
  LockTable();
  for (int fd = lowfd < 0 ? 0 : lowfd; fd < kMaxFds; ++fd) {
    if (g_sockets[fd] != nullptr) DetachLocked(fd);
  }
  UnlockTable();
}

UCAN_EXPORT int dup(int fd) {
  const int rc = real_dup()(fd);
  if (rc >= 0 && IsUcan(fd)) ShareFd(fd, rc);
  return rc;
}

UCAN_EXPORT int dup2(int fd, int fd2) {
  const int rc = real_dup2()(fd, fd2);
  if (rc >= 0 && fd != fd2 && (IsUcan(fd) || IsUcan(fd2))) ShareFd(fd, fd2);
  return rc;
}

UCAN_EXPORT int dup3(int fd, int fd2, int flags) {
  const int rc = real_dup3()(fd, fd2, flags);
  if (rc >= 0 && (IsUcan(fd) || IsUcan(fd2))) ShareFd(fd, fd2);
  return rc;
}

UCAN_EXPORT int fcntl(int fd, int cmd, ...) {
  va_list ap;
  va_start(ap, cmd);
  void* arg = va_arg(ap, void*);
  va_end(ap);
  return DupFcntl(fd, cmd, real_fcntl()(fd, cmd, arg), arg);
}

UCAN_EXPORT int fcntl64(int fd, int cmd, ...) {
  va_list ap;
  va_start(ap, cmd);
  void* arg = va_arg(ap, void*);
  va_end(ap);
  auto f = real_fcntl64();
  return DupFcntl(fd, cmd, f != nullptr ? f(fd, cmd, arg) : real_fcntl()(fd, cmd, arg), arg);
}

UCAN_EXPORT int ioctl(int fd, unsigned long request, ...) {
  va_list ap;
  va_start(ap, request);
  void* arg = va_arg(ap, void*);
  va_end(ap);
  if (request == FIOASYNC && arg != nullptr && *static_cast<const int*>(arg) != 0 && IsUcan(fd)) {
    g_signals_on_input.store(true);  // and on to the kernel below
  } else if (request == SIOCGIFINDEX && arg != nullptr) {
    auto* ifr = static_cast<ifreq*>(arg);
    char name[ucan::kNameSize] = {};
    std::memcpy(name, ifr->ifr_name, sizeof(name) - 1);
    if (const int index = ResolveName(name); index > 0) {
      ifr->ifr_ifindex = index;
      return 0;
    }
  } else if ((request == SIOCGIFHWADDR || request == SIOCGIFFLAGS || request == SIOCGIFMTU) &&
             arg != nullptr) {
    // What vcan reports: a CAN device (ARPHRD_CAN), up and running, CAN FD MTU.
    auto* ifr = static_cast<ifreq*>(arg);
    char name[ucan::kNameSize] = {};
    std::memcpy(name, ifr->ifr_name, sizeof(name) - 1);
    if (ResolveName(name) > 0) {
      if (request == SIOCGIFHWADDR) {
        std::memset(&ifr->ifr_hwaddr, 0, sizeof(ifr->ifr_hwaddr));
        ifr->ifr_hwaddr.sa_family = kArphrdCan;
      } else if (request == SIOCGIFFLAGS) {
        ifr->ifr_flags = IFF_UP | IFF_RUNNING | IFF_NOARP;
      } else {
        ifr->ifr_mtu = static_cast<int>(ucan::kCanFdMtu);
      }
      return 0;
    }
  } else if (request == SIOCGIFNAME && arg != nullptr) {
    auto* ifr = static_cast<ifreq*>(arg);
    View v;
    if (GetView(fd, &v) && v.bound && v.ifindex == ifr->ifr_ifindex) {
      std::memcpy(ifr->ifr_name, v.name, sizeof(v.name));
      return 0;
    }
    char name[ucan::kNameSize] = {};
    if (ResolveIndex(ifr->ifr_ifindex, name)) {
      std::memcpy(ifr->ifr_name, name, sizeof(name));
      return 0;
    }
  } else if ((request == kSiocgstampOld || request == kSiocgstampNsOld ||
              request == kSiocgstampNew || request == kSiocgstampNsNew) &&
             IsUcan(fd)) {
    const std::int64_t ns = __atomic_load_n(&g_last_ts_ns[fd], __ATOMIC_RELAXED);
    if (ns == 0) {
      errno = ENOENT;
      return -1;
    }
    if (arg == nullptr) {
      errno = EFAULT;
      return -1;
    }
    const bool nano = request == kSiocgstampNsOld || request == kSiocgstampNsNew;
    const std::int64_t v[2] = {ns / 1000000000, nano ? ns % 1000000000 : (ns % 1000000000) / 1000};
    std::memcpy(arg, v, sizeof(v));
    return 0;
  }
  return real_ioctl()(fd, request, arg);
}

UCAN_EXPORT unsigned if_nametoindex(const char* name) {
  if (name != nullptr) {
    int refused = 0;
    if (const int index = ResolveName(name, &refused); index > 0) {
      return static_cast<unsigned>(index);
    }
    if (refused != 0) {
      errno = refused;
      return 0;
    }
  }
  return real_if_nametoindex()(name);
}

UCAN_EXPORT char* if_indextoname(unsigned index, char* name) {
  char found[ucan::kNameSize] = {};
  if (name != nullptr && index <= 0x7FFFFFFF && ResolveIndex(static_cast<int>(index), found)) {
    std::memcpy(name, found, sizeof(found));
    return name;
  }
  return real_if_indextoname()(index, name);
}

namespace {

/// SOL_SOCKET options a kernel CAN socket takes that the bus cannot honour (they would act on
/// its connection to the broker instead): their errno, 0 for the others. Socket filters and
/// SO_TXTIME are refused with ENOPROTOOPT; SO_PEEK_OFF gets the kernel's own answer for a CAN
/// socket (EOPNOTSUPP).
int UnsupportedSocketOption(int opt) {
  switch (opt) {
    case SO_ATTACH_FILTER:
    case SO_DETACH_FILTER:
    case SO_ATTACH_BPF:
    case SO_LOCK_FILTER:
    case SO_ATTACH_REUSEPORT_CBPF:
    case SO_ATTACH_REUSEPORT_EBPF:
    case SO_DETACH_REUSEPORT_BPF:
    case SO_TXTIME:
      return ENOPROTOOPT;
    case SO_PEEK_OFF:
      return EOPNOTSUPP;
    default:
      return 0;
  }
}

/// SO_TIMESTAMPING[_NEW], checked as net/core/sock.c sock_set_timestamping() does: an int of
/// SOF_TIMESTAMPING_* flags or a struct so_timestamping. Only software receive stamps exist on
/// the bus; binding to a PTP clock is refused as on a socket bound to no device.
int SetTimestamping(int fd, int opt, const void* val, socklen_t len) {
  if (val == nullptr) return static_cast<int>(Fail(EFAULT));
  so_timestamping ts{};
  if (len == sizeof(ts)) {
    std::memcpy(&ts, val, sizeof(ts));
  } else if (len >= static_cast<socklen_t>(sizeof(int))) {
    std::memcpy(&ts.flags, val, sizeof(int));
  } else {
    return static_cast<int>(Fail(EINVAL));
  }
  const int flags = ts.flags;
  if (flags & ~SOF_TIMESTAMPING_MASK) return static_cast<int>(Fail(EINVAL));
  if ((flags & SOF_TIMESTAMPING_OPT_STATS) && !(flags & SOF_TIMESTAMPING_OPT_TSONLY)) {
    return static_cast<int>(Fail(EINVAL));
  }
  if (flags & SOF_TIMESTAMPING_BIND_PHC) return static_cast<int>(Fail(EOPNOTSUPP));
  LockTable();
  if (UcanSocket* s = g_sockets[fd]) {
    s->timestamping = flags;
    s->timestamping_cmsg = opt;
  }
  UnlockTable();
  return 0;
}

}  // namespace

UCAN_EXPORT int setsockopt(int fd, int level, int opt, const void* val, socklen_t len) {
  if (!IsUcan(fd) || (level != SOL_CAN_RAW && level != SOL_SOCKET)) {
    return real_setsockopt()(fd, level, opt, val, len);
  }
  if (level == SOL_SOCKET) {
    if (opt == kSoTimestampingOld || opt == kSoTimestampingNew) {
      return SetTimestamping(fd, opt, val, len);
    }
    if (const int err = UnsupportedSocketOption(opt); err != 0) {
      return static_cast<int>(Fail(err));
    }
    if (opt != kSoTimestampOld && opt != kSoTimestampNsOld && opt != kSoTimestampNew &&
        opt != kSoTimestampNsNew && opt != kSoRxqOvfl) {
      return real_setsockopt()(fd, level, opt, val, len);
    }
    if (len < static_cast<socklen_t>(sizeof(int))) return static_cast<int>(Fail(EINVAL));
    if (val == nullptr) return static_cast<int>(Fail(EFAULT));
    int on = 0;
    std::memcpy(&on, val, sizeof(on));
    LockTable();
    if (UcanSocket* s = g_sockets[fd]) {
      if (opt == kSoRxqOvfl) {
        s->rxq_ovfl = on != 0;
      } else if (on == 0) {
        s->timestamp_mode = 0;
      } else {
        const bool ns = opt == kSoTimestampNsOld || opt == kSoTimestampNsNew;
        s->timestamp_mode = ns ? 2 : 1;
        s->timestamp_cmsg = opt;
      }
    }
    UnlockTable();
    return 0;
  }
  // SOL_CAN_RAW, checks as net/can/raw.c raw_setsockopt().
  if (len > 0 && val == nullptr) return static_cast<int>(Fail(EFAULT));
  switch (opt) {
    case CAN_RAW_FILTER: {
      if (len % sizeof(can_filter) != 0) return static_cast<int>(Fail(EINVAL));
      const std::uint32_t count = len / sizeof(can_filter);
      if (count > ucan::kMaxFilters) return static_cast<int>(Fail(EINVAL));
      can_filter* copy = nullptr;
      if (count > 0) {
        copy = static_cast<can_filter*>(malloc(len));
        if (copy == nullptr) return static_cast<int>(Fail(ENOMEM));
        std::memcpy(copy, val, len);
      }
      LockTable();
      if (UcanSocket* s = g_sockets[fd]) {
        free(s->filters);
        s->filters = copy;
        s->options.filter_count = count;
        copy = nullptr;
      }
      UnlockTable();
      free(copy);
      break;
    }
    case CAN_RAW_ERR_FILTER:
    case CAN_RAW_LOOPBACK:
    case CAN_RAW_RECV_OWN_MSGS:
    case CAN_RAW_FD_FRAMES:
    case CAN_RAW_JOIN_FILTERS: {
      if (len != sizeof(int)) return static_cast<int>(Fail(EINVAL));
      std::uint32_t v = 0;
      std::memcpy(&v, val, sizeof(v));
      LockTable();
      if (UcanSocket* s = g_sockets[fd]) {
        switch (opt) {
          case CAN_RAW_ERR_FILTER:
            s->options.err_mask = v & CAN_ERR_MASK;
            break;
          case CAN_RAW_LOOPBACK:
            s->options.loopback = v != 0;
            break;
          case CAN_RAW_RECV_OWN_MSGS:
            s->options.recv_own = v != 0;
            break;
          case CAN_RAW_FD_FRAMES:
            s->options.fd_frames = v != 0;
            break;
          default:
            s->options.join_filters = v != 0;
            break;
        }
      }
      UnlockTable();
      break;
    }
    default:
      return static_cast<int>(Fail(ENOPROTOOPT));
  }
  SyncOptions(fd);
  return 0;
}

UCAN_EXPORT int getsockopt(int fd, int level, int opt, void* val, socklen_t* len) {
  if (!IsUcan(fd) || (level != SOL_CAN_RAW && level != SOL_SOCKET)) {
    return real_getsockopt()(fd, level, opt, val, len);
  }
  if (len == nullptr) return static_cast<int>(Fail(EFAULT));
  int ival = 0;
  if (level == SOL_SOCKET) {
    LockTable();
    const UcanSocket* s = g_sockets[fd];
    bool handled = true;
    switch (opt) {
      case SO_DOMAIN:
        ival = AF_CAN;
        break;
      case SO_TYPE:
        ival = SOCK_RAW;
        break;
      case SO_PROTOCOL:
        ival = CAN_RAW;
        break;
      case kSoRxqOvfl:
        ival = s && s->rxq_ovfl;
        break;
      case kSoTimestampOld:
      case kSoTimestampNew:
        ival = s && s->timestamp_mode == 1;
        break;
      case kSoTimestampNsOld:
      case kSoTimestampNsNew:
        ival = s && s->timestamp_mode == 2;
        break;
      case kSoTimestampingOld:
      case kSoTimestampingNew: {
        // struct so_timestamping {flags, bind_phc}, cut to the caller's length (the kernel's).
        const so_timestamping v{s ? s->timestamping : 0, 0};
        UnlockTable();
        if (val == nullptr) return static_cast<int>(Fail(EFAULT));
        const socklen_t n = std::min<socklen_t>(*len, sizeof(v));
        std::memcpy(val, &v, n);
        *len = n;
        return 0;
      }
      default:
        handled = false;
        break;
    }
    UnlockTable();
    if (!handled) return real_getsockopt()(fd, level, opt, val, len);
  } else {
    LockTable();
    UcanSocket* s = g_sockets[fd];
    if (s == nullptr) {
      UnlockTable();
      return static_cast<int>(Fail(EBADF));
    }
    if (opt == CAN_RAW_FILTER) {
      const socklen_t need = s->options.filter_count * sizeof(can_filter);
      if (*len < need) {
        *len = need;
        UnlockTable();
        return static_cast<int>(Fail(ERANGE));
      }
      if (need > 0) std::memcpy(val, s->filters, need);
      *len = need;
      UnlockTable();
      return 0;
    }
    switch (opt) {
      case CAN_RAW_ERR_FILTER:
        ival = static_cast<int>(s->options.err_mask);
        break;
      case CAN_RAW_LOOPBACK:
        ival = s->options.loopback;
        break;
      case CAN_RAW_RECV_OWN_MSGS:
        ival = s->options.recv_own;
        break;
      case CAN_RAW_FD_FRAMES:
        ival = s->options.fd_frames;
        break;
      case CAN_RAW_JOIN_FILTERS:
        ival = s->options.join_filters;
        break;
      default:
        UnlockTable();
        return static_cast<int>(Fail(ENOPROTOOPT));
    }
    UnlockTable();
  }
  const socklen_t n = std::min<socklen_t>(*len, sizeof(ival));
  if (n > 0) std::memcpy(val, &ival, n);
  *len = n;
  return 0;
}

UCAN_EXPORT int getsockname(int fd, sockaddr* addr, socklen_t* len) {
  View v;
  if (!GetView(fd, &v)) return real_getsockname()(fd, addr, len);
  if (addr == nullptr || len == nullptr) return static_cast<int>(Fail(EFAULT));
  sockaddr_can sa{};
  sa.can_family = AF_CAN;
  sa.can_ifindex = v.ifindex;
  std::memcpy(addr, &sa, std::min<std::size_t>(*len, sizeof(sa)));
  *len = sizeof(sa);
  return 0;
}

UCAN_EXPORT ssize_t write(int fd, const void* buf, size_t n) {
  View v;
  if (!GetView(fd, &v)) return real_write()(fd, buf, n);
  iovec iov{const_cast<void*>(buf), n};
  return SendFrame(fd, v, &iov, 1, 0, nullptr, 0);
}

UCAN_EXPORT ssize_t send(int fd, const void* buf, size_t n, int flags) {
  View v;
  if (!GetView(fd, &v)) return real_send()(fd, buf, n, flags);
  iovec iov{const_cast<void*>(buf), n};
  return SendFrame(fd, v, &iov, 1, flags, nullptr, 0);
}

UCAN_EXPORT ssize_t sendto(int fd, const void* buf, size_t n, int flags, const sockaddr* to,
                           socklen_t to_len) {
  View v;
  if (!GetView(fd, &v)) return real_sendto()(fd, buf, n, flags, to, to_len);
  iovec iov{const_cast<void*>(buf), n};
  return SendFrame(fd, v, &iov, 1, flags, to, to_len);
}

UCAN_EXPORT ssize_t sendmsg(int fd, const msghdr* msg, int flags) {
  View v;
  if (!GetView(fd, &v)) return real_sendmsg()(fd, msg, flags);
  if (msg == nullptr) return Fail(EFAULT);
  return SendFrame(fd, v, msg->msg_iov, msg->msg_iovlen, flags, msg->msg_name, msg->msg_namelen);
}

UCAN_EXPORT ssize_t read(int fd, void* buf, size_t n) {
  View v;
  if (!GetView(fd, &v)) return real_read()(fd, buf, n);
  return RecvSimple(fd, v, buf, n, 0, nullptr, nullptr);
}

UCAN_EXPORT ssize_t recv(int fd, void* buf, size_t n, int flags) {
  View v;
  if (!GetView(fd, &v)) return real_recv()(fd, buf, n, flags);
  return RecvSimple(fd, v, buf, n, flags, nullptr, nullptr);
}

UCAN_EXPORT ssize_t recvfrom(int fd, void* buf, size_t n, int flags, sockaddr* from,
                             socklen_t* from_len) {
  View v;
  if (!GetView(fd, &v)) return real_recvfrom()(fd, buf, n, flags, from, from_len);
  return RecvSimple(fd, v, buf, n, flags, from, from_len);
}

UCAN_EXPORT ssize_t recvmsg(int fd, msghdr* msg, int flags) {
  View v;
  if (!GetView(fd, &v)) return real_recvmsg()(fd, msg, flags);
  if (msg == nullptr) return Fail(EFAULT);
  return RecvFrame(fd, v, msg, flags);
}

UCAN_EXPORT ssize_t writev(int fd, const iovec* iov, int iovcnt) {
  View v;
  if (!GetView(fd, &v)) return real_writev()(fd, iov, iovcnt);
  if (iovcnt < 0) return Fail(EINVAL);
  return SendFrame(fd, v, iov, static_cast<std::size_t>(iovcnt), 0, nullptr, 0);
}

UCAN_EXPORT ssize_t readv(int fd, const iovec* iov, int iovcnt) {
  View v;
  if (!GetView(fd, &v)) return real_readv()(fd, iov, iovcnt);
  if (iovcnt < 0) return Fail(EINVAL);
  msghdr m{};
  m.msg_iov = const_cast<iovec*>(iov);
  m.msg_iovlen = static_cast<std::size_t>(iovcnt);
  return RecvFrame(fd, v, &m, 0);
}

// The mmsg calls: one frame per entry. recvmmsg blocks for the first frame only when
// MSG_WAITFORONE is set, for each one otherwise (its timeout argument is not supported).
UCAN_EXPORT int sendmmsg(int fd, mmsghdr* vec, unsigned vlen, int flags) {
  View v;
  if (!GetView(fd, &v)) return real_sendmmsg()(fd, vec, vlen, flags);
  unsigned i = 0;
  for (; i < vlen; ++i) {
    const msghdr& m = vec[i].msg_hdr;
    const ssize_t n = SendFrame(fd, v, m.msg_iov, m.msg_iovlen, flags, m.msg_name, m.msg_namelen);
    if (n < 0) return i > 0 ? static_cast<int>(i) : -1;
    vec[i].msg_len = static_cast<unsigned>(n);
  }
  return static_cast<int>(i);
}

UCAN_EXPORT int recvmmsg(int fd, mmsghdr* vec, unsigned vlen, int flags, timespec* timeout) {
  View v;
  if (!GetView(fd, &v)) return real_recvmmsg()(fd, vec, vlen, flags, timeout);
  unsigned i = 0;
  for (; i < vlen; ++i) {
    int f = flags & ~MSG_WAITFORONE;
    if (i > 0 && (flags & MSG_WAITFORONE)) f |= MSG_DONTWAIT;
    const ssize_t n = RecvFrame(fd, v, &vec[i].msg_hdr, f);
    if (n < 0) return i > 0 ? static_cast<int>(i) : -1;
    vec[i].msg_len = static_cast<unsigned>(n);
  }
  return static_cast<int>(i);
}

// _FORTIFY_SOURCE entry points (programs built with it call these instead).
UCAN_EXPORT ssize_t __read_chk(int fd, void* buf, size_t n, size_t buflen) {
  if (n > buflen) abort();  // what glibc's __chk_fail does, minus the message
  return read(fd, buf, n);
}

UCAN_EXPORT ssize_t __recv_chk(int fd, void* buf, size_t n, size_t buflen, int flags) {
  if (n > buflen) abort();
  return recv(fd, buf, n, flags);
}

UCAN_EXPORT ssize_t __recvfrom_chk(int fd, void* buf, size_t n, size_t buflen, int flags,
                                   sockaddr* from, socklen_t* from_len) {
  if (n > buflen) abort();
  return recvfrom(fd, buf, n, flags, from, from_len);
}
