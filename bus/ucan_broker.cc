// One file on purpose (~1300 lines): the broker is one event loop whose parts (client
// connections, per-client filters, shared-memory rings and their doorbells, the in-process port
// of a pumped run) share its locks and its fd table; split across files they would need a
// shared internal header exposing every field.
#include "bus/ucan_broker.h"

#include <fcntl.h>
#include <linux/can.h>
#include <linux/can/raw.h>
#include <poll.h>
#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/file.h>
#include <sys/mman.h>
#include <sys/random.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <deque>
#include <cerrno>
#include <condition_variable>
#include <cstring>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <system_error>
#include <thread>
#include <unordered_map>
#include <utility>

#include "bus/internal/passed_fd.h"
#include "bus/internal/socketcan_convert.h"
#include "bus/internal/unique_fd.h"
#include "bus/ucan_protocol.h"
#include "bus/ucan_runtime_dir.h"

namespace wheelhil::bus {
namespace {

using ucan::BusInfo;
using ucan::Op;
using ucan::RawOptions;
using ucan::Reply;
using ucan::Request;
using ucan::RxTrailer;
using ucan::TxAddress;
using ucan::TxStamp;

constexpr std::uint64_t kListenTag = 0;
constexpr std::uint64_t kWakeTag = 1;
constexpr std::uint32_t kFirstClientId = 2;  // ids 0 and 1 are the tags above
constexpr int kBatch = 64;
// Per pass and connection. Honest clients never reach it (a pass reads each connection only up
// to its first frame stamped after the pass began); it bounds a client that forges old stamps.
constexpr int kReadBatchesPerPass = 64;
// Connections accepted per pass: a connect flood cannot keep one pass (and the lock) forever.
constexpr int kAcceptsPerPass = 64;
// File descriptors the broker's process keeps for itself beyond its connections.
constexpr rlim_t kReservedFds = 64;
constexpr std::size_t kMaxRequest = sizeof(Request) + ucan::kMaxFilters * sizeof(can_filter);
constexpr std::size_t kClientMsgBuf = 128;  // > 80, so a larger message shows as MSG_TRUNC

using Fd = internal::UniqueFd;

std::system_error SysError(int err, const std::string& what) {
  return std::system_error(err, std::generic_category(), what);
}

struct Msg {
  std::uint16_t len = 0;
  std::array<std::uint8_t, ucan::kMaxRxMessage> bytes{};
};

/// FIFO of messages with a hard capacity; grows by doubling up to it.
class MsgRing {
 public:
  bool empty() const { return size_ == 0; }
  std::size_t size() const { return size_; }
  Msg& PushBack() {
    if (size_ == buf_.size()) Grow();
    Msg& m = buf_[(head_ + size_) & (buf_.size() - 1)];
    ++size_;
    return m;
  }
  const Msg& At(std::size_t i) const { return buf_[(head_ + i) & (buf_.size() - 1)]; }
  void PopFront(std::size_t n) {
    head_ = (head_ + n) & (buf_.size() - 1);
    size_ -= n;
    if (size_ == 0) head_ = 0;
  }

 private:
  void Grow() {
    std::vector<Msg> next(buf_.empty() ? 64 : buf_.size() * 2);
    for (std::size_t i = 0; i < size_; ++i) next[i] = At(i);
    buf_ = std::move(next);
    head_ = 0;
  }
  std::vector<Msg> buf_;
  std::size_t head_ = 0;
  std::size_t size_ = 0;
};

/// One CAN_RAW filter after the kernel's normalisation (net/can/af_can.c: can_rcv_list_find).
struct Filter {
  enum Kind { kAll, kMatch, kInverse, kError } kind = kAll;
  std::uint32_t id = 0;
  std::uint32_t mask = 0;
};

Filter Normalize(can_filter f) {
  Filter out;
  std::uint32_t id = f.can_id;
  std::uint32_t mask = f.can_mask;
  const bool inverse = (id & CAN_INV_FILTER) != 0;
  if (mask & CAN_ERR_FLAG) {
    out.kind = Filter::kError;
    out.mask = mask & CAN_ERR_MASK;
    return out;
  }
  if ((mask & CAN_EFF_FLAG) && !(id & CAN_EFF_FLAG)) {
    mask &= (CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG);
  }
  id &= mask;
  out.id = id;
  out.mask = mask;
  if (inverse) {
    out.kind = Filter::kInverse;
  } else if (mask == 0) {
    out.kind = Filter::kAll;
  } else {
    out.kind = Filter::kMatch;
  }
  return out;
}

struct Bus;

/// The shared-memory rings of a data connection (bus/ucan_protocol.h, "Rings"): mapped here,
/// the memfd passed to the client at kOpen. The client can write all of it: the geometry and
/// the broker's own indexes (rx tail, tx head) are kept here and only published there; the
/// client's indexes are checked against them.
struct Rings {
  ucan::RingHeader* header = nullptr;
  std::size_t bytes = 0;
  std::uint32_t slots = 0;
  std::uint64_t rx_tail = 0;  // next rx slot the broker writes
  std::uint64_t prepared_tail = 0;  // runahead: rx slots written ahead up to here (>= rx_tail)
  std::uint64_t tx_head = 0;  // next tx slot the broker reads
  bool corrupt = false;       // impossible client indexes seen: never read again
  Rings() = default;
  Rings(const Rings&) = delete;
  Rings& operator=(const Rings&) = delete;
  ~Rings() {
    if (header != nullptr) ::munmap(header, bytes);
  }
};

/// Creates the sealed memfd and maps it; -1 on failure (the client then uses plain messages).
int CreateRings(std::uint32_t slots, bool tx_drained_every_pass, Rings* out) {
  const std::size_t bytes = ucan::RingBytes(slots);
  const int fd = ::memfd_create("ucan-rings", MFD_CLOEXEC | MFD_ALLOW_SEALING);
  if (fd < 0) return -1;
  if (::ftruncate(fd, static_cast<off_t>(bytes)) != 0 ||
      ::fcntl(fd, F_ADD_SEALS, F_SEAL_SHRINK | F_SEAL_GROW | F_SEAL_SEAL) != 0) {
    ::close(fd);
    return -1;
  }
  void* p = ::mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  if (p == MAP_FAILED) {
    ::close(fd);
    return -1;
  }
  auto* h = new (p) ucan::RingHeader;
  h->slots = slots;
  h->tx_drained_every_pass.store(tx_drained_every_pass ? 1 : 0);
  pthread_mutexattr_t a;
  pthread_mutexattr_init(&a);
  pthread_mutexattr_setpshared(&a, PTHREAD_PROCESS_SHARED);
  pthread_mutexattr_setrobust(&a, PTHREAD_MUTEX_ROBUST);
  pthread_mutex_init(&h->rx.lock, &a);
  pthread_mutex_init(&h->tx.lock, &a);
  pthread_mutexattr_destroy(&a);
  out->header = h;
  out->bytes = bytes;
  out->slots = slots;
  return fd;
}

struct Client {
  Fd fd;
  std::uint32_t id = 0;
  std::uint64_t token = 0;  // kOpen: quoted by requests about this client
  pid_t pid = 0;
  std::int64_t accepted_ns = 0;  // CLOCK_MONOTONIC
  bool data = false;  // kOpen done
  bool any = false;   // bound to ifindex 0
  bool dead = false;
  bool dirty = false;
  bool want_out = false;
  bool local = false;  // an in-process port (OpenLocalPort): no fd, the owner pops `queue`
  Bus* bus = nullptr;
  RawOptions options;
  std::vector<Filter> filters;
  MsgRing queue;
  std::uint32_t drops = 0;
  std::unique_ptr<Rings> rings;  // kOpenRings: frames go through shared memory
  bool own_bell = false;         // kOpenOwnBell: the client holds a copy of fd

  /// net/can/raw.c raw_rcv(): filter match counting incl. CAN_RAW_JOIN_FILTERS.
  bool Accepts(std::uint32_t can_id) const {
    std::size_t matches = 0;
    if (can_id & CAN_ERR_FLAG) {
      if (can_id & options.err_mask & CAN_ERR_MASK) ++matches;
      for (const Filter& f : filters) {
        if (f.kind == Filter::kError && (can_id & f.mask)) ++matches;
      }
    } else {
      for (const Filter& f : filters) {
        switch (f.kind) {
          case Filter::kAll:
            ++matches;
            break;
          case Filter::kMatch:
            matches += (can_id & f.mask) == f.id;
            break;
          case Filter::kInverse:
            matches += (can_id & f.mask) != f.id;
            break;
          case Filter::kError:
            break;
        }
      }
    }
    if (matches == 0) return false;
    if (options.join_filters && filters.size() > 1) return matches >= filters.size();
    return true;
  }
};

struct Bus {
  std::string name;
  int ifindex = 0;
  std::vector<Client*> members;
  std::uint64_t binds = 0;  // sockets ever bound, in-process ports included
  std::uint64_t frames = 0;
  std::uint64_t drops = 0;
  std::uint64_t bad_messages = 0;
  std::int64_t last_ts_ns = 0;
};

std::int64_t MonotonicNs() {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}

/// A frame read from a client, waiting for its turn (dispatch is in TxStamp order). The
/// sender's options are captured at read time: a later setsockopt does not apply to it.
struct Pending {
  std::int64_t stamp_ns = 0;
  Bus* bus = nullptr;
  std::uint32_t sender_id = 0;
  pid_t sender_pid = 0;
  bool loopback = true;
  bool recv_own = false;
  std::uint32_t can_id = 0;
  std::uint8_t frame_len = 0;
  std::array<std::uint8_t, ucan::kCanFdMtu> frame{};
};

std::int64_t RealtimeNs() {
  timespec ts{};
  ::clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}

void CopyName(char (&dst)[ucan::kNameSize], const std::string& src) {
  std::memset(dst, 0, sizeof(dst));
  std::memcpy(dst, src.data(), std::min(src.size(), sizeof(dst) - 1));
}

std::string NameOf(const char (&src)[ucan::kNameSize]) {
  return std::string(src, strnlen(src, sizeof(src)));
}

}  // namespace

bool IsValidUcanBusName(const std::string& name) noexcept {
  if (name.empty() || name.size() >= ucan::kNameSize) return false;
  for (char c : name) {
    if (c == '/' || c == ':' || c <= ' ' || c == 0x7F) return false;
  }
  return name != "any" && name != "." && name != "..";
}

struct UcanBroker::Impl {
  UcanBrokerOptions options;
  std::string dir;
  std::string sock_path;
  Fd lock_fd;
  Fd listen_fd;
  Fd epoll_fd;
  Fd wake_fd;
  Fd spare_fd;  // released to refuse a connection when the process is out of fds
  bool accept_paused = false;  // out of fds and no spare: the listen fd is off epoll for now
  std::size_t max_connections = 0;
  std::size_t connections = 0;                  // socket clients not yet reaped
  std::unordered_map<pid_t, std::size_t> connections_of;  // per client pid
  std::deque<std::pair<std::uint32_t, std::int64_t>> awaiting_request;  // id, accepted_ns
  UcanBrokerHealth health;
  std::uint64_t client_progress = 0;  // see UcanBroker::client_progress
  UcanWokenClients woken;             // see UcanBroker::TakeWokenClients
  std::function<std::int64_t()> receive_clock;  // empty: CLOCK_REALTIME

  mutable std::mutex mu;
  std::condition_variable stopped_cv;
  bool stop_requested = false;
  bool stopped = false;

  std::unordered_map<std::uint32_t, std::unique_ptr<Client>> clients;
  std::map<std::string, std::unique_ptr<Bus>> buses;
  std::map<std::string, int> index_of;  // every name ever added -> its ifindex
  int next_named_index = ucan::kFirstNamedIfindex;
  std::vector<Client*> any_clients;
  std::vector<Client*> ring_clients;  // drained every pass (TxStamp order needs every ring)
  std::vector<Client*> dirty;
  std::vector<Pending> pending;  // read, not yet routed (see Dispatch)
  struct DeferredOptions {
    std::uint32_t request_id = 0;  // the kSetOptions connection, answered after the pass
    Request req;
    std::vector<std::uint8_t> extra;
  };
  std::vector<DeferredOptions> deferred_options;
  std::int64_t pass_start_ns = 0;  // T0 of the current pass
  std::uint32_t next_id = kFirstClientId;
  std::uint64_t orphan_bad_messages = 0;

  std::thread thread;
  bool handover_requested = false;  // UseCallerThread(): the thread leaves its loop
  std::vector<epoll_event> pump_events;

  /// ReadData's recvmmsg vectors, set up once: recvmmsg only writes msg_len and the header's
  /// msg_flags / msg_namelen / msg_controllen (no name, no control: they stay 0), so no batch
  /// needs them cleared again. Used under `mu` by the one thread that runs passes.
  struct ReadBuffers {
    std::array<std::array<std::uint8_t, kClientMsgBuf>, kBatch> bufs;
    std::array<iovec, kBatch> iovs;
    std::array<mmsghdr, kBatch> msgs;
    ReadBuffers() {
      for (int i = 0; i < kBatch; ++i) {
        iovs[i] = {bufs[i].data(), bufs[i].size()};
        msgs[i] = {};
        msgs[i].msg_hdr.msg_iov = &iovs[i];
        msgs[i].msg_hdr.msg_iovlen = 1;
      }
    }
    ReadBuffers(const ReadBuffers&) = delete;
    ReadBuffers& operator=(const ReadBuffers&) = delete;
  };
  std::unique_ptr<ReadBuffers> read_buffers = std::make_unique<ReadBuffers>();

  explicit Impl(UcanBrokerOptions opts) : options(std::move(opts)) {
    dir = options.runtime_dir.empty() ? ResolveUcanRuntimeDir() : options.runtime_dir;
    if (auto ec = EnsureUcanRuntimeDir(dir)) {
      throw SysError(ec.value(), "ucan runtime directory " + dir +
                                     " (must be a directory owned by you with mode 0700)");
    }
    sock_path = UcanSocketPath(dir);
    sockaddr_un addr{};
    if (sock_path.size() >= sizeof(addr.sun_path)) {
      throw SysError(ENAMETOOLONG, "ucan socket path " + sock_path);
    }
    const std::string lock_path = dir + "/" + ucan::kLockName;
    lock_fd = Fd(::open(lock_path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0600));
    if (lock_fd.get() < 0) throw SysError(errno, "ucan lock " + lock_path);
    if (::flock(lock_fd.get(), LOCK_EX | LOCK_NB) != 0) {
      const int err = errno == EWOULDBLOCK ? EBUSY : errno;
      throw SysError(err, "another ucan broker serves " + dir);
    }
    ::unlink(sock_path.c_str());  // stale: we hold the lock, so nobody serves it
    listen_fd = Fd(::socket(AF_UNIX, SOCK_SEQPACKET | SOCK_NONBLOCK | SOCK_CLOEXEC, 0));
    if (listen_fd.get() < 0) throw SysError(errno, "ucan socket");
    addr.sun_family = AF_UNIX;
    std::memcpy(addr.sun_path, sock_path.c_str(), sock_path.size() + 1);
    if (::bind(listen_fd.get(), reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0) {
      throw SysError(errno, "bind " + sock_path);
    }
    if (::listen(listen_fd.get(), 256) != 0) throw SysError(errno, "listen " + sock_path);
    epoll_fd = Fd(::epoll_create1(EPOLL_CLOEXEC));
    wake_fd = Fd(::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC));
    if (epoll_fd.get() < 0 || wake_fd.get() < 0) throw SysError(errno, "epoll/eventfd");
    epoll_event ev{};
    ev.events = EPOLLIN;
    ev.data.u64 = kListenTag;
    ::epoll_ctl(epoll_fd.get(), EPOLL_CTL_ADD, listen_fd.get(), &ev);
    ev.data.u64 = kWakeTag;
    ::epoll_ctl(epoll_fd.get(), EPOLL_CTL_ADD, wake_fd.get(), &ev);
    spare_fd = Fd(::open("/dev/null", O_RDONLY | O_CLOEXEC));
    max_connections = options.max_connections;
    rlimit fds{};
    if (::getrlimit(RLIMIT_NOFILE, &fds) == 0 && fds.rlim_cur != RLIM_INFINITY) {
      const rlim_t usable = fds.rlim_cur > 2 * kReservedFds ? fds.rlim_cur - kReservedFds
                                                            : fds.rlim_cur / 2;
      max_connections = std::min<std::size_t>(max_connections, usable);
    }
    thread = std::thread([this] { Loop(); });
  }

  ~Impl() {
    RequestStop();
    if (thread.joinable()) thread.join();
    std::lock_guard lk(mu);
    for (auto& [id, c] : clients) c->fd.Reset();
    clients.clear();
    if (!sock_path.empty() && listen_fd.get() >= 0) ::unlink(sock_path.c_str());
    if (options.remove_runtime_dir && lock_fd.get() >= 0) {
      ::unlink((dir + "/" + ucan::kLockName).c_str());
      ::rmdir(dir.c_str());  // only when empty
    }
  }

  void RequestStop() {
    {
      std::lock_guard lk(mu);
      stop_requested = true;
    }
    Wake();
  }

  void Wake() const {
    const std::uint64_t one = 1;
    [[maybe_unused]] ssize_t n = ::write(wake_fd.get(), &one, sizeof(one));
  }

  // ---- buses (mu held) ----

  int IndexFor(const std::string& name) {
    if (auto it = index_of.find(name); it != index_of.end()) return it->second;
    int index = 0;
    if (name.size() > 4 && name.size() <= 7 && name.compare(0, 4, "ucan") == 0 &&
        std::all_of(name.begin() + 4, name.end(), [](char c) { return c >= '0' && c <= '9'; }) &&
        !(name.size() > 5 && name[4] == '0')) {
      index = ucan::kFirstIfindex + std::stoi(name.substr(4));
    } else {
      index = next_named_index++;
    }
    index_of[name] = index;
    return index;
  }

  int AddBusLocked(const std::string& name) {
    if (auto it = buses.find(name); it != buses.end()) return it->second->ifindex;
    auto bus = std::make_unique<Bus>();
    bus->name = name;
    bus->ifindex = IndexFor(name);
    const int index = bus->ifindex;
    buses[name] = std::move(bus);
    return index;
  }

  bool RemoveBusLocked(const std::string& name) {
    auto it = buses.find(name);
    if (it == buses.end()) return false;
    for (Client* c : it->second->members) {
      c->bus = nullptr;
      Kill(c);
    }
    it->second->members.clear();
    Bus* gone = it->second.get();
    pending.erase(std::remove_if(pending.begin(), pending.end(),
                                 [gone](const Pending& f) { return f.bus == gone; }),
                  pending.end());
    buses.erase(it);
    ReapDead();
    return true;
  }

  Bus* BusByIndex(int ifindex) {
    for (auto& [name, bus] : buses) {
      if (bus->ifindex == ifindex) return bus.get();
    }
    return nullptr;
  }

  // ---- clients (mu held) ----

  // Bounded (a broker nobody asks, on its own thread, would grow it forever): past
  // kMaxWokenIds the record says only that something was woken.
  void NoteWoken(const Client* c) {
    if (woken.other || (!woken.ids.empty() && woken.ids.back() == c->id)) return;
    if (woken.ids.size() >= kMaxWokenIds) {
      woken.ids.clear();
      woken.other = true;
      return;
    }
    woken.ids.push_back(c->id);
  }
  static constexpr std::size_t kMaxWokenIds = 64;

  void Kill(Client* c) {
    if (c->dead) return;
    c->dead = true;
    ++client_progress;
    woken.other = true;
    if (c->rings) c->rings->header->closed.store(1);
    if (c->own_bell && !c->local) {
      // The client holds a copy of this end (kOpenOwnBell): closing it is no end of the
      // connection there. A doorbell makes the socket readable; its reader finds `closed`.
      const std::uint64_t bell = 1;
      (void)::send(c->fd.get(), &bell, sizeof(bell), MSG_DONTWAIT | MSG_NOSIGNAL);
    }
    if (!c->local) ::epoll_ctl(epoll_fd.get(), EPOLL_CTL_DEL, c->fd.get(), nullptr);
  }

  void ReapDead() {
    for (auto it = clients.begin(); it != clients.end();) {
      Client* c = it->second.get();
      if (!c->dead) {
        ++it;
        continue;
      }
      if (c->bus != nullptr) {
        auto& m = c->bus->members;
        m.erase(std::remove(m.begin(), m.end(), c), m.end());
      }
      if (c->any) {
        any_clients.erase(std::remove(any_clients.begin(), any_clients.end(), c),
                          any_clients.end());
      }
      dirty.erase(std::remove(dirty.begin(), dirty.end(), c), dirty.end());
      if (c->rings) {
        ring_clients.erase(std::remove(ring_clients.begin(), ring_clients.end(), c),
                           ring_clients.end());
      }
      if (!c->local) {
        --connections;
        if (auto n = connections_of.find(c->pid); n != connections_of.end() && --n->second == 0) {
          connections_of.erase(n);
        }
      }
      it = clients.erase(it);
    }
    if (accept_paused) ResumeAccepting();
  }

  std::uint32_t NewClientId() {
    for (;;) {
      const std::uint32_t id = next_id++;
      if (next_id < kFirstClientId) next_id = kFirstClientId;  // wrapped
      if (id >= kFirstClientId && clients.find(id) == clients.end()) return id;
    }
  }

  /// Answers a connection's (coming) request with EMFILE and closes it.
  void Refuse(int fd, std::string why) {
    Reply reply;
    reply.error = EMFILE;
    [[maybe_unused]] ssize_t n =
        ::send(fd, &reply, sizeof(reply), MSG_DONTWAIT | MSG_NOSIGNAL);
    // The request, if it came already: closing with it unread would report ECONNRESET to the
    // client ahead of the reply.
    char request[sizeof(Request)];
    for (int i = 0; i < 4 && ::recv(fd, request, sizeof(request), MSG_DONTWAIT) > 0; ++i) {
    }
    ::close(fd);
    ++health.refused_connections;
    health.last_refusal = std::move(why);
    ++client_progress;
    woken.other = true;
  }

  void ResumeAccepting() {
    if (spare_fd.get() < 0) spare_fd = Fd(::open("/dev/null", O_RDONLY | O_CLOEXEC));
    if (spare_fd.get() < 0) return;
    epoll_event ev{};
    ev.events = EPOLLIN;
    ev.data.u64 = kListenTag;
    if (::epoll_ctl(epoll_fd.get(), EPOLL_CTL_ADD, listen_fd.get(), &ev) == 0) {
      accept_paused = false;
    }
  }

  /// Connections that sent no request in time are closed (they hold an fd and a slot).
  void ExpireSilentConnections() {
    const std::int64_t deadline =
        MonotonicNs() - std::int64_t{options.request_timeout_ms} * 1000000;
    while (!awaiting_request.empty()) {
      const auto [id, accepted_ns] = awaiting_request.front();
      Client* c = Find(id);
      if (c != nullptr && !c->data && c->accepted_ns == accepted_ns) {
        if (accepted_ns > deadline) return;
        ++health.silent_connections;
        Kill(c);
      }
      awaiting_request.pop_front();
    }
  }

  /// Accepts up to kAcceptsPerPass connections (the rest wait for the next pass: the listen
  /// fd stays ready). Over a limit or out of fds, the newest connection is refused. Returns the
  /// connections accepted.
  int AcceptSome() {
    int accepted = 0;
    for (int i = 0; i < kAcceptsPerPass; ++i) {
      const int fd = ::accept4(listen_fd.get(), nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
      if (fd < 0 && (errno == EMFILE || errno == ENFILE)) {
        const int err = errno;
        if (spare_fd.get() < 0) spare_fd = Fd(::open("/dev/null", O_RDONLY | O_CLOEXEC));
        if (spare_fd.get() < 0) {
          // Nothing to refuse with: stop watching the listen fd (else every pass finds it
          // ready and the loop spins) until a connection is closed.
          ::epoll_ctl(epoll_fd.get(), EPOLL_CTL_DEL, listen_fd.get(), nullptr);
          accept_paused = true;
          return accepted;
        }
        spare_fd.Reset();
        const int refused = ::accept4(listen_fd.get(), nullptr, nullptr, SOCK_CLOEXEC);
        if (refused >= 0) {
          Refuse(refused, std::string("the broker's process is out of file descriptors (") +
                              (err == EMFILE ? "EMFILE" : "ENFILE") + ")");
        }
        spare_fd = Fd(::open("/dev/null", O_RDONLY | O_CLOEXEC));
        continue;
      }
      if (fd < 0) return accepted;  // EAGAIN
      ucred cred{};
      socklen_t len = sizeof(cred);
      const pid_t pid =
          ::getsockopt(fd, SOL_SOCKET, SO_PEERCRED, &cred, &len) == 0 ? cred.pid : 0;
      if (connections >= max_connections) {
        Refuse(fd, "the bus serves " + std::to_string(connections) +
                       " connections, its limit (process " + std::to_string(pid) +
                       " asked for one more)");
        continue;
      }
      std::size_t& of_pid = connections_of[pid];
      if (of_pid >= options.max_connections_per_process) {
        Refuse(fd, "process " + std::to_string(pid) + " has " + std::to_string(of_pid) +
                       " connections to the bus open, the limit per process");
        continue;
      }
      ++client_progress;  // its request is read and answered by this pass's second look or later
      woken.other = true;
      ++accepted;
      auto c = std::make_unique<Client>();
      c->fd = Fd(fd);
      c->id = NewClientId();
      c->pid = pid;
      c->accepted_ns = MonotonicNs();
      const int sndbuf = 1 << 20;
      ::setsockopt(fd, SOL_SOCKET, SO_SNDBUF, &sndbuf, sizeof(sndbuf));
      epoll_event ev{};
      ev.events = EPOLLIN;
      ev.data.u64 = c->id;
      if (::epoll_ctl(epoll_fd.get(), EPOLL_CTL_ADD, fd, &ev) != 0) continue;
      ++of_pid;
      ++connections;
      awaiting_request.emplace_back(c->id, c->accepted_ns);
      clients[c->id] = std::move(c);
    }
    return accepted;
  }

  Client* Find(std::uint32_t id) {
    auto it = clients.find(id);
    return it == clients.end() || it->second->dead ? nullptr : it->second.get();
  }

  /// The local port `port` that may send `frame` (encoded into `buf`, its length into `len`),
  /// lock held; nullptr for an invalid frame or a closed port.
  Client* LocalSender(int port, const CanFrame& frame, canfd_frame& buf, std::size_t& len) {
    len = internal::EncodeFrame(frame, buf);
    if (len == 0) return nullptr;
    Client* c = Find(static_cast<std::uint32_t>(port));
    if (c == nullptr || !c->local || c->bus == nullptr) return nullptr;
    if (len == ucan::kCanFdMtu && !c->options.fd_frames) return nullptr;
    return c;
  }

  void SendReply(Client* c, const Reply& reply, const void* extra = nullptr,
                 std::size_t extra_len = 0, int pass_fd = -1) {
    iovec iov[2] = {{const_cast<Reply*>(&reply), sizeof(reply)},
                    {const_cast<void*>(extra), extra_len}};
    msghdr msg{};
    msg.msg_iov = iov;
    msg.msg_iovlen = extra_len ? 2 : 1;
    internal::PassedFdControl control;
    if (pass_fd >= 0) internal::AttachFd(msg, control, pass_fd);
    [[maybe_unused]] ssize_t n = ::sendmsg(c->fd.get(), &msg, MSG_DONTWAIT | MSG_NOSIGNAL);
    ++client_progress;
    woken.other = true;
  }

  bool SetOptions(Client* c, const Request& req, const std::uint8_t* filters_bytes,
                  std::size_t filters_len) {
    const std::uint32_t count = req.options.filter_count;
    if (count > ucan::kMaxFilters || filters_len != count * sizeof(can_filter)) return false;
    std::vector<Filter> filters(count);
    for (std::uint32_t i = 0; i < count; ++i) {
      can_filter f{};
      std::memcpy(&f, filters_bytes + i * sizeof(can_filter), sizeof(f));
      filters[i] = Normalize(f);
    }
    c->options = req.options;
    c->filters = std::move(filters);
    return true;
  }

  static bool IsSeqpacketSocket(int fd) {
    int type = 0;
    socklen_t len = sizeof(type);
    return ::getsockopt(fd, SOL_SOCKET, SO_TYPE, &type, &len) == 0 && type == SOCK_SEQPACKET;
  }

  /// The client's data connection goes on through `fd` (kOpenOwnBell); the connection its
  /// request came on closes.
  void SwapDataConnection(Client* c, Fd fd) {
    (void)::epoll_ctl(epoll_fd.get(), EPOLL_CTL_DEL, c->fd.get(), nullptr);
    const int sndbuf = 1 << 20;
    ::setsockopt(fd.get(), SOL_SOCKET, SO_SNDBUF, &sndbuf, sizeof(sndbuf));
    epoll_event ev{};
    ev.events = EPOLLIN;
    ev.data.u64 = c->id;
    c->fd = std::move(fd);
    if (::epoll_ctl(epoll_fd.get(), EPOLL_CTL_ADD, c->fd.get(), &ev) != 0) Kill(c);
  }

  /// First message of a connection.
  void HandleRequest(Client* c) {
    std::vector<std::uint8_t> buf(kMaxRequest + 1);
    iovec iov{buf.data(), buf.size()};
    msghdr msg{};
    msg.msg_iov = &iov;
    msg.msg_iovlen = 1;
    internal::PassedFdControl control;
    internal::ExpectFd(msg, control);
    const ssize_t n = ::recvmsg(c->fd.get(), &msg, MSG_DONTWAIT | MSG_CMSG_CLOEXEC);
    if (n < 0 && (errno == EAGAIN || errno == EINTR)) return;
    // kOpenOwnBell: the client's end of its own socket pair (closed unless taken below).
    Fd passed(n >= 0 ? internal::ReceivedFd(msg) : -1);
    Request req;
    if (n < static_cast<ssize_t>(sizeof(Request))) {
      ++orphan_bad_messages;
      Kill(c);
      return;
    }
    std::memcpy(&req, buf.data(), sizeof(req));
    if (req.magic != ucan::kMagic) {
      ++orphan_bad_messages;
      Kill(c);
      return;
    }
    req.name[ucan::kNameSize - 1] = '\0';
    const std::string name = NameOf(req.name);
    const std::uint8_t* extra = buf.data() + sizeof(Request);
    const std::size_t extra_len = static_cast<std::size_t>(n) - sizeof(Request);
    Reply reply;
    switch (req.op) {
      case Op::kOpen: {
        Bus* bus = nullptr;
        if (!name.empty()) {
          auto it = buses.find(name);
          if (it == buses.end()) {
            reply.error = ENODEV;
            break;
          }
          bus = it->second.get();
        }
        if (!SetOptions(c, req, extra, extra_len)) {
          reply.error = EINVAL;
          break;
        }
        c->data = true;
        if (bus != nullptr) {
          c->bus = bus;
          bus->members.push_back(c);
          ++bus->binds;
          reply.ifindex = bus->ifindex;
          CopyName(reply.name, bus->name);
        } else {
          c->any = true;
          any_clients.push_back(c);
        }
        reply.client_id = c->id;
        c->token = NewToken(c->id);
        reply.token = c->token;
        int ring_fd = -1;
        if (req.flags & ucan::kOpenRings) {
          auto rings = std::make_unique<Rings>();
          ring_fd = CreateRings(RingSlotsFor(options.client_queue_limit),
                                options.tx_rings_drained_every_pass, rings.get());
          if (ring_fd >= 0) {
            c->rings = std::move(rings);
            ring_clients.push_back(c);
          }
        }
        // The client's own end of a socket pair: from now on the data connection.
        const bool own_bell = (req.flags & ucan::kOpenOwnBell) != 0 && c->rings != nullptr &&
                              passed.get() >= 0 && IsSeqpacketSocket(passed.get());
        if (own_bell) reply.flags |= ucan::kOpenOwnBell;
        SendReply(c, reply, nullptr, 0, ring_fd);
        if (ring_fd >= 0) ::close(ring_fd);
        if (own_bell) {
          SwapDataConnection(c, std::move(passed));
          c->own_bell = true;
        }
        return;  // stays connected
      }
      case Op::kSetOptions: {
        if (OptionsTarget(req) == nullptr) {
          ++health.refused_requests;
          reply.error = ENOTCONN;
          break;
        }
        // Applied after this pass's dispatch, once the target's earlier frames are read
        // (ApplyDeferredOptions); the reply waits until then.
        deferred_options.push_back(
            {c->id, req, std::vector<std::uint8_t>(extra, extra + extra_len)});
        return;
      }
      case Op::kResolveName: {
        auto it = buses.find(name);
        if (it == buses.end()) {
          reply.error = ENODEV;
        } else {
          reply.ifindex = it->second->ifindex;
          CopyName(reply.name, name);
        }
        break;
      }
      case Op::kResolveIndex: {
        Bus* bus = BusByIndex(req.ifindex);
        if (bus == nullptr) {
          reply.error = ENODEV;
        } else {
          reply.ifindex = bus->ifindex;
          CopyName(reply.name, bus->name);
        }
        break;
      }
      case Op::kAddBus:
      case Op::kRemoveBus:
      case Op::kShutdown:
        if (!options.control_requests) {
          ++health.refused_requests;
          reply.error = EPERM;
          break;
        }
        ControlRequest(req.op, name, &reply);
        break;
      case Op::kList: {
        std::vector<BusInfo> infos;
        for (const UcanBusStats& s : StatsLocked()) {
          BusInfo info;
          CopyName(info.name, s.name);
          info.ifindex = s.ifindex;
          info.clients = static_cast<std::uint32_t>(s.clients);
          info.frames = s.frames;
          info.drops = s.drops;
          info.bad_messages = s.bad_messages;
          infos.push_back(info);
        }
        reply.count = static_cast<std::uint32_t>(infos.size());
        SendReply(c, reply, infos.data(), infos.size() * sizeof(BusInfo));
        Kill(c);
        return;
      }
      default:
        reply.error = EOPNOTSUPP;
        break;
    }
    SendReply(c, reply);
    Kill(c);
  }

  void ControlRequest(Op op, const std::string& name, Reply* reply) {
    if (op == Op::kAddBus) {
      if (!IsValidUcanBusName(name)) {
        reply->error = EINVAL;
      } else {
        reply->ifindex = AddBusLocked(name);
        CopyName(reply->name, name);
      }
    } else if (op == Op::kRemoveBus) {
      if (!RemoveBusLocked(name)) reply->error = ENODEV;
      if (options.exit_when_empty && buses.empty()) stop_requested = true;
    } else {
      stop_requested = true;
    }
  }

  /// The data connection a kSetOptions request may change: a socket client (never an
  /// in-process port) whose token the request quotes.
  Client* OptionsTarget(const Request& req) {
    Client* target = Find(req.client_id);
    if (target == nullptr || !target->data || target->local || target->token != req.token) {
      return nullptr;
    }
    return target;
  }

  /// A secret per data connection: getrandom, else (no entropy yet) a mix of time and id that
  /// a client cannot read from anywhere.
  static std::uint64_t NewToken(std::uint32_t id) {
    std::uint64_t token = 0;
    if (::getrandom(&token, sizeof(token), GRND_NONBLOCK) != sizeof(token)) {
      token = static_cast<std::uint64_t>(MonotonicNs()) * 0x9E3779B97F4A7C15ull ^
              (std::uint64_t{id} << 32) ^ reinterpret_cast<std::uintptr_t>(&token);
    }
    return token == 0 ? 1 : token;
  }

  static std::uint32_t RingSlotsFor(std::size_t queue_limit) {
    std::uint32_t slots = 64;
    while (slots < queue_limit && slots < 8192) slots *= 2;
    return slots;
  }

  /// Takes every frame in `c`'s tx ring into `pending` (after the doorbells were read: a push
  /// that saw `pending` set before the clear below is visible to the drain after it).
  /// A dead client's ring is drained too: what it wrote before closing is on the bus, as the
  /// messages queued in a closed socket are.
  void DrainRing(Client* c) {
    if (!c->rings || c->rings->corrupt) return;
    Rings& rings = *c->rings;
    ucan::RingIndex& r = rings.header->tx;
    r.bell.fetch_and(~std::uint64_t{1});  // seq_cst
    std::uint64_t head = rings.tx_head;
    const std::uint64_t tail = r.tail.load(std::memory_order_acquire);
    if (tail - head > rings.slots) {  // the client wrote an impossible tail
      CorruptRing(c);
      return;
    }
    const std::int64_t read_ns = MonotonicNs();
    ucan::RingSlot* slots = ucan::TxSlots(rings.header, rings.slots);
    std::array<std::uint8_t, ucan::kSlotBytes> copy;
    for (; head != tail; ++head) {
      const ucan::RingSlot& slot = slots[head & (rings.slots - 1)];
      const std::uint32_t len = std::min<std::uint32_t>(slot.len, ucan::kSlotBytes);
      std::memcpy(copy.data(), slot.bytes, len);  // copied once: the client may scribble
      HandleFrame(c, copy.data(), len, false, read_ns);
    }
    rings.tx_head = head;
    r.head.store(head, std::memory_order_release);
  }

  void CorruptRing(Client* c) {
    if (c->rings->corrupt) return;
    c->rings->corrupt = true;
    ++health.corrupt_rings;
    CountBad(c);
    Kill(c);
  }

  /// Reads `c`'s frames into `pending`, up to and including the first batch holding a frame
  /// stamped at or after `stop_ns` (later frames wait in the socket for the next pass).
  void ReadData(Client* c, int max_batches, std::int64_t stop_ns) {
    auto& bufs = read_buffers->bufs;
    auto& msgs = read_buffers->msgs;
    for (int batch = 0; batch < max_batches && !c->dead; ++batch) {
      const int n = ::recvmmsg(c->fd.get(), msgs.data(), kBatch, MSG_DONTWAIT, nullptr);
      if (n < 0) {
        if (errno != EAGAIN && errno != EINTR) Kill(c);
        break;
      }
      if (n == 0) {
        Kill(c);
        return;
      }
      // Every message of this batch was sent before now: an honest stamp is not larger.
      const std::int64_t read_ns = MonotonicNs();
      bool reached_stop = false;
      for (int i = 0; i < n; ++i) {
        const std::size_t len = msgs[i].msg_len;
        if (len == 0) {  // end of stream
          Kill(c);
          return;
        }
        if (c->rings && len == ucan::kDoorbellSize) continue;  // DrainRing reads the ring
        const std::int64_t stamp = HandleFrame(
            c, bufs[i].data(), len, (msgs[i].msg_hdr.msg_flags & MSG_TRUNC) != 0, read_ns);
        reached_stop = reached_stop || stamp >= stop_ns;
      }
      if (n < kBatch || reached_stop) break;
    }
    DrainRing(c);
  }

  void CountBad(Client* c) {
    if (c->bus != nullptr) {
      ++c->bus->bad_messages;
    } else {
      ++orphan_bad_messages;
    }
  }

  /// Validates one client message and appends its frame to `pending`. Returns the frame's
  /// stamp (clamped to `read_ns`), or INT64_MIN for a rejected message.
  std::int64_t HandleFrame(Client* c, const std::uint8_t* p, std::size_t len, bool truncated,
                           std::int64_t read_ns) {
    constexpr std::int64_t kRejected = INT64_MIN;
    Bus* bus = c->bus;
    std::size_t frame_len = 0;
    bool addressed = false;
    if (!truncated) {
      if (len == ucan::kCanMtu + sizeof(TxStamp) || len == ucan::kCanFdMtu + sizeof(TxStamp)) {
        frame_len = len - sizeof(TxStamp);
      } else if (len == ucan::kCanMtu + sizeof(TxStamp) + sizeof(TxAddress) ||
                 len == ucan::kCanFdMtu + sizeof(TxStamp) + sizeof(TxAddress)) {
        frame_len = len - sizeof(TxStamp) - sizeof(TxAddress);
        addressed = true;
      }
    }
    if (addressed) {
      TxAddress to;
      std::memcpy(&to, p + frame_len + sizeof(TxStamp), sizeof(to));
      bus = to.magic == ucan::kMagic ? BusByIndex(to.ifindex) : nullptr;
    }
    if (frame_len == 0 || bus == nullptr ||
        (frame_len == ucan::kCanFdMtu && !c->options.fd_frames)) {
      CountBad(c);
      return kRejected;
    }
    const std::uint8_t payload_len = p[4];
    if (payload_len > (frame_len == ucan::kCanMtu ? CAN_MAX_DLEN : CANFD_MAX_DLEN)) {
      ++bus->bad_messages;
      return kRejected;
    }
    TxStamp stamp;
    std::memcpy(&stamp, p + frame_len, sizeof(stamp));
    Pending& f = pending.emplace_back();
    f.stamp_ns = std::min(stamp.monotonic_ns, read_ns);  // a future stamp would stall it
    f.bus = bus;
    f.sender_id = c->id;
    f.sender_pid = c->pid;
    f.loopback = c->options.loopback != 0;
    f.recv_own = c->options.recv_own != 0;
    std::memcpy(&f.can_id, p, sizeof(f.can_id));
    f.frame_len = static_cast<std::uint8_t>(frame_len);
    std::memcpy(f.frame.data(), p, frame_len);
    return f.stamp_ns;
  }

  /// Routes, in stamp order (ties: read order), every pending frame stamped before `before_ns`;
  /// later ones stay pending for the next pass, which starts without blocking.
  /// At most `max_frames` of them (PumpFirstSent).
  void Dispatch(std::int64_t before_ns, std::size_t max_frames = SIZE_MAX) {
    auto by_stamp = [](const Pending& a, const Pending& b) { return a.stamp_ns < b.stamp_ns; };
    if (!std::is_sorted(pending.begin(), pending.end(), by_stamp)) {
      std::stable_sort(pending.begin(), pending.end(), by_stamp);
    }
    auto end = pending.begin();
    while (end != pending.end() && end->stamp_ns < before_ns &&
           static_cast<std::size_t>(end - pending.begin()) < max_frames) {
      Route(*end);
      ++end;
    }
    pending.erase(pending.begin(), end);
  }

  void Route(const Pending& f) {
    Bus* bus = f.bus;
    const std::uint32_t can_id = f.can_id;
    const std::uint8_t* frame = f.frame.data();
    const std::size_t frame_len = f.frame_len;
    const std::int64_t ts =
        std::max(receive_clock ? receive_clock() : RealtimeNs(), bus->last_ts_ns);
    bus->last_ts_ns = ts;
    ++bus->frames;
    const bool is_fd = frame_len == ucan::kCanFdMtu;
    auto deliver = [&](Client* r) {
      if (r->dead) return;
      std::uint32_t flags = 0;
      if (r->id == f.sender_id) {
        if (!f.recv_own || !f.loopback) return;
        flags = ucan::kRxOwn;
      } else if (!f.loopback && r->pid == f.sender_pid) {
        return;
      }
      if (is_fd && !r->options.fd_frames) return;
      if (!r->Accepts(can_id)) return;
      if (r->rings) {
        PushRx(r, bus, frame, frame_len, flags, ts);
        return;
      }
      if (r->queue.size() >= options.client_queue_limit) {
        ++r->drops;
        ++bus->drops;
        return;
      }
      Msg& m = r->queue.PushBack();
      std::memcpy(m.bytes.data(), frame, frame_len);
      RxTrailer t;
      t.ifindex = bus->ifindex;
      t.flags = flags;
      t.timestamp_ns = ts;
      t.drops = r->drops;
      std::memcpy(m.bytes.data() + frame_len, &t, sizeof(t));
      m.len = static_cast<std::uint16_t>(frame_len + sizeof(t));
      if (!r->dirty) {
        r->dirty = true;
        dirty.push_back(r);
      }
    };
    for (Client* r : bus->members) deliver(r);
    for (Client* r : any_clients) deliver(r);
  }

  /// Runahead: the recipients of a frame from `sender` (Route's rules), into `out`; false when
  /// one cannot take it ahead.
  bool PreparedRecipients(Client* sender, std::uint32_t can_id, bool is_fd,
                          std::vector<std::pair<Client*, std::uint32_t>>& out) {
    out.clear();
    bool ok = true;
    auto consider = [&](Client* r) {
      if (r->dead) return;
      std::uint32_t flags = 0;
      if (r->id == sender->id) {
        if (!sender->options.recv_own || !sender->options.loopback) return;
        flags = ucan::kRxOwn;
      } else if (!sender->options.loopback && r->pid == sender->pid) {
        return;
      }
      if (is_fd && !r->options.fd_frames) return;
      if (!r->Accepts(can_id)) return;
      if (!r->rings || !r->own_bell || r->rings->corrupt ||
          r->rings->prepared_tail - r->rings->header->rx.head.load() >= r->rings->slots) {
        ok = false;
        return;
      }
      out.emplace_back(r, flags);
    };
    for (Client* r : sender->bus->members) consider(r);
    for (Client* r : any_clients) consider(r);
    return ok;
  }

  bool PrepareFrame(Client* sender, const std::uint8_t* frame, std::size_t frame_len,
                    std::uint32_t can_id, std::int64_t instant_ns) {
    std::vector<std::pair<Client*, std::uint32_t>> to;
    if (!PreparedRecipients(sender, can_id, frame_len == ucan::kCanFdMtu, to)) return false;
    for (const auto& [r, flags] : to) {
      Rings& rings = *r->rings;
      const std::uint64_t at = rings.prepared_tail;
      ucan::RingSlot& slot = ucan::RxSlots(rings.header)[at & (rings.slots - 1)];
      std::memcpy(slot.bytes, frame, frame_len);
      RxTrailer t;
      t.ifindex = sender->bus->ifindex;
      t.flags = flags;
      t.timestamp_ns = 0;  // the client stamps it with its own clock when it publishes it
      t.drops = r->drops;
      std::memcpy(slot.bytes + frame_len, &t, sizeof(t));
      slot.len = static_cast<std::uint32_t>(frame_len + sizeof(t));
      ucan::RxInstants(rings.header, rings.slots)[at & (rings.slots - 1)] = instant_ns;
      rings.prepared_tail = at + 1;
      rings.header->rx_prepared_tail.store(at + 1, std::memory_order_release);
    }
    return true;
  }

  /// Runahead over for `r`: the slots its library published are delivered; the rest go.
  std::uint64_t SettlePreparedOf(Client* r) {
    Rings& rings = *r->rings;
    if (rings.prepared_tail == rings.rx_tail) return 0;
    const std::uint64_t published = rings.header->rx.tail.load(std::memory_order_acquire);
    std::uint64_t delivered = 0;
    if (published < rings.rx_tail || published > rings.prepared_tail) {
      rings.header->rx.tail.store(rings.rx_tail);
      CorruptRing(r);
    } else {
      delivered = published - rings.rx_tail;
      rings.rx_tail = published;
    }
    rings.prepared_tail = rings.rx_tail;
    rings.header->rx_prepared_tail.store(rings.rx_tail, std::memory_order_release);
    if (r->bus != nullptr) r->bus->frames += delivered;
    return delivered;
  }

  /// Route() to a ring client: a full ring is a drop (counted as a full queue is).
  void PushRx(Client* r, Bus* bus, const std::uint8_t* frame, std::size_t frame_len,
              std::uint32_t flags, std::int64_t ts) {
    Rings& rings = *r->rings;
    if (rings.corrupt) return;
    if (rings.prepared_tail != rings.rx_tail) (void)SettlePreparedOf(r);
    ucan::RingIndex& ring = rings.header->rx;
    const std::uint64_t tail = rings.rx_tail;
    const std::uint64_t used = tail - ring.head.load(std::memory_order_acquire);
    if (used > rings.slots) {  // the client wrote an impossible head
      CorruptRing(r);
      return;
    }
    if (used == rings.slots) {
      ++r->drops;
      ++bus->drops;
      return;
    }
    ucan::RingSlot& slot = ucan::RxSlots(rings.header)[tail & (rings.slots - 1)];
    std::memcpy(slot.bytes, frame, frame_len);
    RxTrailer t;
    t.ifindex = bus->ifindex;
    t.flags = flags;
    t.timestamp_ns = ts;
    t.drops = r->drops;
    std::memcpy(slot.bytes + frame_len, &t, sizeof(t));
    slot.len = static_cast<std::uint32_t>(frame_len + sizeof(t));
    rings.rx_tail = tail + 1;
    rings.prepared_tail = tail + 1;  // nothing ahead (settled above)
    rings.header->rx_prepared_tail.store(tail + 1, std::memory_order_relaxed);
    ring.tail.store(tail + 1, std::memory_order_release);
    if (!r->dirty) {
      r->dirty = true;
      dirty.push_back(r);
    }
  }

  void Flush(Client* c) {
    std::array<iovec, kBatch> iovs;
    std::array<mmsghdr, kBatch> msgs;
    while (!c->queue.empty() && !c->dead) {
      const int n = static_cast<int>(std::min<std::size_t>(c->queue.size(), kBatch));
      for (int i = 0; i < n; ++i) {
        const Msg& m = c->queue.At(i);
        iovs[i] = {const_cast<std::uint8_t*>(m.bytes.data()), m.len};
        msgs[i] = {};
        msgs[i].msg_hdr.msg_iov = &iovs[i];
        msgs[i].msg_hdr.msg_iovlen = 1;
      }
      const int sent = ::sendmmsg(c->fd.get(), msgs.data(), n, MSG_DONTWAIT | MSG_NOSIGNAL);
      if (sent < 0) {
        if (errno == EAGAIN || errno == ENOBUFS) break;
        if (errno == EINTR) continue;
        Kill(c);
        return;
      }
      c->queue.PopFront(static_cast<std::size_t>(sent));
      if (sent > 0) {
        ++client_progress;
        NoteWoken(c);
      }
      if (sent < n) break;
    }
    const bool want_out = !c->queue.empty();
    if (want_out != c->want_out && !c->dead) {
      c->want_out = want_out;
      epoll_event ev{};
      ev.events = EPOLLIN | (want_out ? EPOLLOUT : 0u);
      ev.data.u64 = c->id;
      ::epoll_ctl(epoll_fd.get(), EPOLL_CTL_MOD, c->fd.get(), &ev);
    }
  }

  void FlushDirty() {
    for (std::size_t i = 0; i < dirty.size(); ++i) {
      Client* c = dirty[i];
      c->dirty = false;
      if (c->rings) {
        // One doorbell per pass at most, none while the client has not consumed the last one.
        if (c->dead) continue;
        const int rung = ucan::RingTakeDoorbell(c->rings->header->rx, ucan::kDoorbellTries);
        if (rung < 0) {
          CorruptRing(c);
        } else if (rung > 0) {
          const std::uint64_t bell = 1;
          [[maybe_unused]] ssize_t n =
              ::send(c->fd.get(), &bell, sizeof(bell), MSG_DONTWAIT | MSG_NOSIGNAL);
          ++client_progress;
          NoteWoken(c);
        }
        continue;
      }
      if (!c->want_out && !c->local) Flush(c);  // a blocked reader is flushed on EPOLLOUT
    }
    dirty.clear();
  }

  /// Answers the kSetOptions requests of this pass: the target's frames sent before the
  /// request are read first (and routed with the options they were sent under).
  void ApplyDeferredOptions() {
    std::vector<DeferredOptions> todo;
    todo.swap(deferred_options);
    for (DeferredOptions& d : todo) {
      Client* c = Find(d.request_id);
      if (c == nullptr || c->dead) continue;
      Reply reply;
      Client* target = OptionsTarget(d.req);
      if (target == nullptr) {
        reply.error = ENOTCONN;
      } else {
        ReadData(target, kReadBatchesPerPass, INT64_MAX);
        if (!SetOptions(target, d.req, d.extra.data(), d.extra.size())) reply.error = EINVAL;
      }
      SendReply(c, reply);
      Kill(c);
    }
  }

  /// One pass: T0 = now; take the whole ready set (epoll after T0, room for every fd); read each
  /// ready connection up to its first frame stamped >= T0; route the frames stamped < T0 in
  /// stamp order. A write that returned before T0 is then either routed already or read in this
  /// pass, so a frame is never routed before one whose write() returned before it was sent.
  /// Waits up to `timeout_ms` (-1: forever) for traffic first. False once the broker must stop.
  bool Pass(std::vector<epoll_event>& events, int timeout_ms, bool look_at_sockets = true,
            std::size_t max_frames = SIZE_MAX) {
    bool more_pending = false;
    {
      std::lock_guard lk(mu);
      if (stop_requested) return false;
      more_pending = !pending.empty();
    }
    events.resize(std::max<std::size_t>(events.size(), kBatch));
    // The wait only waits: its set is taken again after T0, so with nothing to wait for
    // (local frames pending, or a zero timeout) it is skipped.
    if (!more_pending && timeout_ms != 0) {
      const int n =
          ::epoll_wait(epoll_fd.get(), events.data(), static_cast<int>(events.size()), timeout_ms);
      if (n < 0 && errno != EINTR) return false;
    }
    std::lock_guard lk(mu);
    if (stop_requested) return false;
    pass_start_ns = MonotonicNs();
    // The wait above may predate T0; the level-triggered set is taken again after it.
    // The connections accepted.
    auto serve_ready = [&] {
      int accepted = 0;
      events.resize(std::max<std::size_t>(kBatch, clients.size() + 8));
      int n = ::epoll_wait(epoll_fd.get(), events.data(), static_cast<int>(events.size()), 0);
      if (n < 0) n = 0;
      for (int i = 0; i < n; ++i) {
        const std::uint64_t tag = events[i].data.u64;
        if (tag == kListenTag) {
          accepted += AcceptSome();
          continue;
        }
        if (tag == kWakeTag) {
          std::uint64_t v = 0;
          [[maybe_unused]] ssize_t r = ::read(wake_fd.get(), &v, sizeof(v));
          continue;
        }
        Client* c = Find(static_cast<std::uint32_t>(tag));
        if (c == nullptr) continue;
        if (events[i].events & EPOLLOUT) Flush(c);
        if (events[i].events & (EPOLLIN | EPOLLHUP | EPOLLERR)) {
          if (c->data) {
            ReadData(c, kReadBatchesPerPass, pass_start_ns);
          } else {
            HandleRequest(c);
          }
        }
      }
      return accepted;
    };
    // A client sends its request right after connecting: a second look answers it in this pass
    // (a pumped broker's owner would otherwise wait for a pass that nothing asks for).
    if (look_at_sockets && serve_ready() > 0) serve_ready();
    // Every ring, ready or not: a push that returned before T0 may have found its doorbell
    // already pending (one rung in an earlier pass, not yet read), so readiness says nothing.
    for (std::size_t i = 0; i < ring_clients.size(); ++i) DrainRing(ring_clients[i]);
    // PumpFirstSent: the frames already sent, whatever this host's clock says.
    Dispatch(max_frames == SIZE_MAX ? pass_start_ns : INT64_MAX, max_frames);
    ApplyDeferredOptions();
    FlushDirty();
    ExpireSilentConnections();
    ReapDead();
    return !stop_requested;
  }

  int WaitTimeoutMs() {
    std::lock_guard lk(mu);
    if (accept_paused) return 100;
    return awaiting_request.empty() ? -1 : std::max(1, options.request_timeout_ms / 4);
  }

  /// After the last pass: every client disconnected, Wait() released.
  void Finish() {
    std::lock_guard lk(mu);
    stop_requested = true;
    stopped = true;
    for (auto& [id, c] : clients) Kill(c.get());
    ReapDead();
    stopped_cv.notify_all();
  }

  void Loop() {
    std::vector<epoll_event> events(kBatch);
    // Wakes up for the request deadline of connections that have not sent one.
    while (Pass(events, WaitTimeoutMs())) {
      std::lock_guard lk(mu);
      if (handover_requested) return;  // the owner pumps from now on; clients stay connected
    }
    Finish();
  }

  std::vector<UcanBusStats> StatsLocked() const {
    std::vector<UcanBusStats> out;
    for (const auto& [name, bus] : buses) {
      UcanBusStats s;
      s.name = name;
      s.ifindex = bus->ifindex;
      s.clients = static_cast<std::size_t>(std::count_if(bus->members.begin(), bus->members.end(),
                                                         [](const Client* c) { return !c->dead; }));
      s.binds = bus->binds;
      s.frames = bus->frames;
      s.drops = bus->drops;
      s.bad_messages = bus->bad_messages;
      out.push_back(s);
    }
    return out;
  }
};

UcanBroker::UcanBroker(UcanBrokerOptions options)
    : impl_(std::make_unique<Impl>(std::move(options))) {}

UcanBroker::~UcanBroker() = default;

int UcanBroker::AddBus(const std::string& name) {
  if (!IsValidUcanBusName(name)) {
    throw std::invalid_argument("ucan bus name '" + name +
                                "': must be 1..15 characters without '/', ':' or spaces");
  }
  std::lock_guard lk(impl_->mu);
  return impl_->AddBusLocked(name);
}

bool UcanBroker::RemoveBus(const std::string& name) {
  std::lock_guard lk(impl_->mu);
  return impl_->RemoveBusLocked(name);
}

std::vector<UcanBusStats> UcanBroker::Stats() const {
  std::lock_guard lk(impl_->mu);
  return impl_->StatsLocked();
}

UcanBrokerHealth UcanBroker::Health() const {
  std::lock_guard lk(impl_->mu);
  return impl_->health;
}

void UcanBroker::Wait() {
  std::unique_lock lk(impl_->mu);
  impl_->stopped_cv.wait(lk, [this] { return impl_->stopped; });
}

void UcanBroker::Stop() { impl_->RequestStop(); }

void UcanBroker::UseCallerThread() {
  if (!impl_->thread.joinable()) return;
  {
    std::lock_guard lk(impl_->mu);
    impl_->handover_requested = true;
  }
  impl_->Wake();
  impl_->thread.join();
}

int UcanBroker::OpenLocalPort(const std::string& bus_name) {
  std::lock_guard lk(impl_->mu);
  auto it = impl_->buses.find(bus_name);
  if (it == impl_->buses.end()) {
    throw std::invalid_argument("ucan: no bus '" + bus_name + "' for a local port");
  }
  auto c = std::make_unique<Client>();
  c->local = true;
  c->data = true;
  c->id = impl_->NewClientId();
  c->pid = ::getpid();
  c->filters.push_back(Normalize(can_filter{0, 0}));  // a new socket receives everything
  c->bus = it->second.get();
  c->bus->members.push_back(c.get());
  ++c->bus->binds;
  const int id = static_cast<int>(c->id);
  impl_->clients[c->id] = std::move(c);
  return id;
}

bool UcanBroker::SendLocal(int port, const CanFrame& frame) {
  canfd_frame buf;
  std::size_t frame_len = 0;
  std::lock_guard lk(impl_->mu);
  Client* c = impl_->LocalSender(port, frame, buf, frame_len);
  if (c == nullptr) return false;
  Pending& f = impl_->pending.emplace_back();
  f.stamp_ns = MonotonicNs();  // as a socket's TxStamp: its place in the bus order
  f.bus = c->bus;
  f.sender_id = c->id;
  f.sender_pid = c->pid;
  f.loopback = c->options.loopback != 0;
  f.recv_own = c->options.recv_own != 0;
  f.can_id = buf.can_id;
  f.frame_len = static_cast<std::uint8_t>(frame_len);
  std::memcpy(f.frame.data(), &buf, frame_len);
  return true;
}

bool UcanBroker::PrepareLocal(int port, const CanFrame& frame, std::int64_t instant_ns) {
  canfd_frame buf;
  std::size_t frame_len = 0;
  std::lock_guard lk(impl_->mu);
  Client* c = impl_->LocalSender(port, frame, buf, frame_len);
  if (c == nullptr) return false;
  return impl_->PrepareFrame(c, reinterpret_cast<const std::uint8_t*>(&buf), frame_len, buf.can_id,
                             instant_ns);
}

std::uint64_t UcanBroker::SettlePrepared() {
  std::lock_guard lk(impl_->mu);
  std::uint64_t delivered = 0;
  for (auto& [id, c] : impl_->clients) {
    if (c->rings && !c->dead) delivered += impl_->SettlePreparedOf(c.get());
  }
  return delivered;
}

bool UcanBroker::ReceiveLocal(int port, CanFrame* frame) {
  std::lock_guard lk(impl_->mu);
  Client* c = impl_->Find(static_cast<std::uint32_t>(port));
  if (c == nullptr || !c->local) return false;
  while (!c->queue.empty()) {
    const Msg& m = c->queue.At(0);
    const std::size_t frame_len = m.len - sizeof(RxTrailer);
    const bool ok = !internal::DecodeFrame(m.bytes.data(), frame_len, *frame);
    c->queue.PopFront(1);
    if (ok) return true;
  }
  return false;
}

bool UcanBroker::PumpQuiet() {
  if (impl_->thread.joinable()) {
    throw std::logic_error("UcanBroker::PumpQuiet: the broker thread still runs (UseCallerThread)");
  }
  {
    std::lock_guard lk(impl_->mu);
    if (impl_->stopped) return false;
  }
  if (impl_->Pass(impl_->pump_events, 0, false)) return true;
  impl_->Finish();
  return false;
}

bool UcanBroker::PumpFirstSent(std::size_t frames) {
  if (impl_->thread.joinable()) {
    throw std::logic_error(
        "UcanBroker::PumpFirstSent: the broker thread still runs (UseCallerThread)");
  }
  {
    std::lock_guard lk(impl_->mu);
    if (impl_->stopped) return false;
  }
  if (frames == 0) return true;
  if (impl_->Pass(impl_->pump_events, 0, false, frames)) return true;
  impl_->Finish();
  return false;
}

bool UcanBroker::FramesReachOnlyPorts() const {
  std::lock_guard lk(impl_->mu);
  int clients = 0;
  for (const auto& [id, c] : impl_->clients) {
    if (c->dead || c->local || !c->data) continue;
    if (++clients > 1 || (c->options.recv_own && c->options.loopback)) return false;
  }
  return true;
}

bool UcanBroker::Pump(int timeout_ms) {
  if (impl_->thread.joinable()) {
    throw std::logic_error("UcanBroker::Pump: the broker thread still runs (UseCallerThread)");
  }
  {
    std::lock_guard lk(impl_->mu);
    if (impl_->stopped) return false;
  }
  if (impl_->Pass(impl_->pump_events, timeout_ms)) return true;
  impl_->Finish();
  return false;
}

void UcanBroker::TakeWokenClients(UcanWokenClients* out) {
  std::lock_guard lk(impl_->mu);
  out->ids.clear();
  std::swap(out->ids, impl_->woken.ids);
  out->other = std::exchange(impl_->woken.other, false);
}

std::uint64_t UcanBroker::client_progress() const {
  std::lock_guard lk(impl_->mu);
  return impl_->client_progress;
}

void UcanBroker::SetReceiveClock(std::function<std::int64_t()> clock_ns) {
  std::lock_guard lk(impl_->mu);
  impl_->receive_clock = std::move(clock_ns);
}

const std::string& UcanBroker::runtime_dir() const noexcept { return impl_->dir; }

std::string UcanBroker::socket_path() const { return impl_->sock_path; }

namespace {

std::error_code Request(const std::string& dir, Op op, const std::string& name, Reply* reply,
                        std::vector<BusInfo>* infos) noexcept {
  try {
    if (auto ec = VerifyUcanRuntimeDir(dir)) return ec;
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    const std::string path = UcanSocketPath(dir);
    if (path.size() >= sizeof(addr.sun_path)) {
      return std::make_error_code(std::errc::filename_too_long);
    }
    std::memcpy(addr.sun_path, path.c_str(), path.size() + 1);
    Fd s(::socket(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0));
    if (s.get() < 0) return {errno, std::generic_category()};
    if (::connect(s.get(), reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0) {
      return {errno, std::generic_category()};
    }
    ucan::Request req;
    req.op = op;
    CopyName(req.name, name);
    if (::send(s.get(), &req, sizeof(req), MSG_NOSIGNAL) != sizeof(req)) {
      return {errno, std::generic_category()};
    }
    pollfd p{s.get(), POLLIN, 0};
    int rc = 0;
    do {
      rc = ::poll(&p, 1, ucan::kRequestTimeoutMs);
    } while (rc < 0 && errno == EINTR);
    if (rc == 0) return std::make_error_code(std::errc::timed_out);
    std::vector<std::uint8_t> buf(sizeof(Reply) + 4096 * sizeof(BusInfo));
    const ssize_t n = ::recv(s.get(), buf.data(), buf.size(), MSG_DONTWAIT);
    if (n < static_cast<ssize_t>(sizeof(Reply))) return std::make_error_code(std::errc::io_error);
    std::memcpy(reply, buf.data(), sizeof(Reply));
    if (reply->magic != ucan::kMagic) return std::make_error_code(std::errc::io_error);
    if (reply->error != 0) return {reply->error, std::generic_category()};
    if (infos != nullptr) {
      const std::size_t count =
          std::min<std::size_t>(reply->count, (n - sizeof(Reply)) / sizeof(BusInfo));
      infos->resize(count);
      if (count > 0)
        std::memcpy(infos->data(), buf.data() + sizeof(Reply), count * sizeof(BusInfo));
    }
    return {};
  } catch (const std::bad_alloc&) {
    return std::make_error_code(std::errc::not_enough_memory);
  }
}

}  // namespace

std::error_code UcanAddBus(const std::string& runtime_dir, const std::string& name,
                           int* ifindex) noexcept {
  if (!IsValidUcanBusName(name)) return std::make_error_code(std::errc::invalid_argument);
  Reply reply;
  auto ec = Request(runtime_dir, Op::kAddBus, name, &reply, nullptr);
  if (!ec && ifindex != nullptr) *ifindex = reply.ifindex;
  return ec;
}

std::error_code UcanRemoveBus(const std::string& runtime_dir, const std::string& name) noexcept {
  Reply reply;
  return Request(runtime_dir, Op::kRemoveBus, name, &reply, nullptr);
}

std::error_code UcanListBuses(const std::string& runtime_dir,
                              std::vector<UcanBusStats>* out) noexcept {
  Reply reply;
  std::vector<BusInfo> infos;
  auto ec = Request(runtime_dir, Op::kList, "", &reply, &infos);
  if (ec || out == nullptr) return ec;
  try {
    out->clear();
    for (const BusInfo& info : infos) {
      UcanBusStats s;
      s.name = NameOf(info.name);
      s.ifindex = info.ifindex;
      s.clients = info.clients;
      s.frames = info.frames;
      s.drops = info.drops;
      s.bad_messages = info.bad_messages;
      out->push_back(std::move(s));
    }
  } catch (const std::bad_alloc&) {
    return std::make_error_code(std::errc::not_enough_memory);
  }
  return {};
}

std::error_code UcanShutdown(const std::string& runtime_dir) noexcept {
  Reply reply;
  return Request(runtime_dir, Op::kShutdown, "", &reply, nullptr);
}

}  // namespace wheelhil::bus
