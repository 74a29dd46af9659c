// The userspace CAN bus as a hostile client sees it (bus/ucan_protocol.h): connections to a
// pumped broker that send any first message, any data messages and doorbells, and write
// anything anywhere in their shared rings. After each input the honest parties - a data
// connection and the owner's in-process port - must still exchange a frame both ways: the
// broker stayed up and kept serving the others.
//
// Input: a sequence of operations, one byte each followed by its operands:
//   0 connect + first message (a Request with the magic and an op from the input, + filters;
//     or raw bytes)   1 data message   2 ring write (offset, bytes)   3 doorbell   4 pump
//   5 close the newest connection
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

#include <linux/can.h>

#include <cstdlib>
#include <cstring>
#include <memory>
#include <vector>

#include "bus/ucan_broker.h"
#include "bus/ucan_protocol.h"
#include "bus/ucan_runtime_dir.h"
#include "tests/bus/ucan_raw_io.h"
#include "tests/fuzz/fuzz_target.h"

namespace {

using namespace wheelhil::bus;

std::int64_t MonotonicNs() {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}

int Connect(const std::string& path) {
  const int fd = ::socket(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::strncpy(addr.sun_path, path.c_str(), sizeof(addr.sun_path) - 1);
  if (fd >= 0 && ::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0) {
    ::close(fd);
    return -1;
  }
  return fd;
}

struct Connection {
  int fd = -1;
  void* rings = nullptr;
  std::size_t ring_bytes = 0;
  ~Connection() {
    if (rings != nullptr) ::munmap(rings, ring_bytes);
    if (fd >= 0) ::close(fd);
  }
  /// Takes the reply (and a ring memfd) if one is there.
  void TakeReply() {
    alignas(8) std::uint8_t buf[sizeof(ucan::Reply) + 64];
    int memfd = -1;
    if (testing::ReceiveWithFd(fd, buf, sizeof(buf), MSG_DONTWAIT, &memfd) <= 0) return;
    if (memfd < 0) return;
    if (rings == nullptr) rings = testing::MapRingMemfd(memfd, &ring_bytes);
    ::close(memfd);
  }
};

struct Harness {
  std::string dir = CreateTempUcanRuntimeDir("wheelhil-fuzz-");
  std::unique_ptr<UcanBroker> broker;
  int port = -1;
  std::unique_ptr<Connection> honest;

  Harness() {
    UcanBrokerOptions o;
    o.runtime_dir = dir;
    o.remove_runtime_dir = true;
    o.control_requests = false;
    o.client_queue_limit = 64;
    broker = std::make_unique<UcanBroker>(o);
    broker->AddBus("ucan0");
    broker->UseCallerThread();
    port = broker->OpenLocalPort("ucan0");
    honest = std::make_unique<Connection>();
    honest->fd = Connect(broker->socket_path());
    struct {
      ucan::Request req;
      can_filter all{0, 0};
    } open;
    open.req.op = ucan::Op::kOpen;
    std::strcpy(open.req.name, "ucan0");
    open.req.options.filter_count = 1;
    if (::send(honest->fd, &open, sizeof(open), MSG_NOSIGNAL) != sizeof(open)) std::abort();
    broker->Pump(0);
    honest->TakeReply();
  }

  /// The honest connection and the port exchange one frame each way; aborts when they cannot.
  void CheckHonestPartiesTalk() {
    static std::uint8_t counter = 0;
    ++counter;
    // Honest connection -> port.
    struct {
      can_frame f{};
      ucan::TxStamp stamp;
    } out;
    out.f.can_id = 0x7E0;
    out.f.can_dlc = 1;
    out.f.data[0] = counter;
    out.stamp.monotonic_ns = MonotonicNs();
    if (::send(honest->fd, &out, sizeof(out), MSG_NOSIGNAL) != sizeof(out)) std::abort();
    CanFrame f;
    bool got = false;
    for (int pass = 0; pass < 64 && !got; ++pass) {
      broker->Pump(pass == 0 ? 0 : 5);
      while (!got && broker->ReceiveLocal(port, &f)) {
        got = f.id == 0x7E0 && f.len == 1 && f.data[0] == counter;
      }
    }
    if (!got) std::abort();
    // Port -> honest connection.
    CanFrame back;
    back.id = 0x7E1;
    back.len = 1;
    back.data[0] = counter;
    if (!broker->SendLocal(port, back)) std::abort();
    got = false;
    for (int pass = 0; pass < 64 && !got; ++pass) {
      broker->Pump(pass == 0 ? 0 : 5);
      std::uint8_t buf[128];
      for (ssize_t n; !got && (n = ::recv(honest->fd, buf, sizeof(buf), MSG_DONTWAIT)) > 0;) {
        can_frame in{};
        if (n >= static_cast<ssize_t>(sizeof(in))) std::memcpy(&in, buf, sizeof(in));
        got = in.can_id == 0x7E1 && in.data[0] == counter;
      }
    }
    if (!got) std::abort();
  }
};

Harness* g_harness = nullptr;

// For the whole process (the broker outlives every input), gone at exit with its runtime
// directory, which the broker removes.
Harness* TheHarness() {
  if (g_harness == nullptr) {
    g_harness = new Harness;
    std::atexit([] {
      delete g_harness;
      g_harness = nullptr;
    });
  }
  return g_harness;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  Harness* h = TheHarness();
  std::vector<std::unique_ptr<Connection>> conns;
  std::size_t i = 0;
  auto take = [&](std::size_t n) {
    const std::size_t k = std::min(n, size - i);
    const std::uint8_t* p = data + i;
    i += k;
    return std::pair{p, k};
  };
  auto byte = [&] { return i < size ? data[i++] : std::uint8_t{0}; };
  while (i < size && conns.size() < 64) {
    const std::uint8_t op = byte() % 6;
    Connection* c = conns.empty() ? nullptr : conns.back().get();
    switch (op) {
      case 0: {
        auto conn = std::make_unique<Connection>();
        conn->fd = Connect(h->broker->socket_path());
        if (conn->fd < 0) break;
        const std::uint8_t kind = byte();
        std::vector<std::uint8_t> msg;
        if (kind & 1) {
          ucan::Request req;
          auto [p, k] = take(sizeof(req));
          std::memcpy(&req, p, k);
          req.magic = ucan::kMagic;
          req.op = static_cast<ucan::Op>(static_cast<std::uint32_t>(req.op) % 10);
          if (kind & 2) std::strcpy(req.name, "ucan0");
          const std::uint32_t filters = (kind >> 2) % 4;
          if (kind & 0x40) req.options.filter_count = filters;
          msg.resize(sizeof(req));
          std::memcpy(msg.data(), &req, sizeof(req));
          auto [fp, fk] = take(filters * sizeof(can_filter));
          msg.insert(msg.end(), fp, fp + fk);
        } else {
          auto [p, k] = take(byte());
          msg.assign(p, p + k);
        }
        ::send(conn->fd, msg.data(), msg.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
        h->broker->Pump(0);
        conn->TakeReply();
        conns.push_back(std::move(conn));
        break;
      }
      case 1:
        if (c != nullptr) {
          auto [p, k] = take(byte() % 128);
          ::send(c->fd, p, k, MSG_NOSIGNAL | MSG_DONTWAIT);
        }
        break;
      case 2:
        if (c != nullptr && c->rings != nullptr) {
          const std::size_t offset = (std::size_t{byte()} << 8 | byte()) * 8 % c->ring_bytes;
          auto [p, k] = take(byte() % 32);
          std::memcpy(static_cast<std::uint8_t*>(c->rings) + offset, p,
                      std::min(k, c->ring_bytes - offset));
        }
        break;
      case 3:
        if (c != nullptr) {
          const std::uint64_t bell = 1;
          ::send(c->fd, &bell, sizeof(bell), MSG_NOSIGNAL | MSG_DONTWAIT);
        }
        break;
      case 4:
        h->broker->Pump(0);
        break;
      case 5:
        if (c != nullptr) conns.pop_back();
        break;
    }
  }
  h->broker->Pump(0);
  conns.clear();
  h->broker->Pump(0);
  h->CheckHonestPartiesTalk();
  return 0;
}
