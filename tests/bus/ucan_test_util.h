#pragma once
// Test helpers for the userspace CAN bus: a broker in a private temp runtime dir, and plain
// SocketCAN calls (this test binary links libwheelhil_ucan.so, so they go to the broker).

#include <linux/can.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <poll.h>
#include <stdlib.h>
#include <sys/socket.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <cstring>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "bus/ucan_broker.h"

namespace wheelhil::bus::testing {

/// A fresh runtime dir (mkdtemp, 0700) exported as WHEELHIL_UCAN_DIR, removed at the end.
class TempRuntimeDir {
 public:
  TempRuntimeDir() {
    char tmpl[] = "/tmp/wheelhil-ucan-test-XXXXXX";
    const char* dir = ::mkdtemp(tmpl);
    if (dir == nullptr) throw std::runtime_error("mkdtemp failed");
    path_ = dir;
    ::setenv("WHEELHIL_UCAN_DIR", path_.c_str(), 1);
  }
  ~TempRuntimeDir() {
    const std::string cmd = "rm -rf '" + path_ + "'";
    [[maybe_unused]] int rc = std::system(cmd.c_str());
  }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

/// Broker options for a test broker in `dir` with a per-client queue of `limit` frames.
inline UcanBrokerOptions TestBrokerOptions(const std::string& dir, std::size_t limit) {
  UcanBrokerOptions o;
  o.runtime_dir = dir;
  o.client_queue_limit = limit;
  return o;
}

/// Receives one classic frame into `f` with the SO_RXQ_OVFL drop count the socket reports with
/// it; nullopt when the receive fails or no such control message comes.
inline std::optional<std::uint32_t> ReceiveDropCount(int fd, can_frame* f) {
  iovec iov{f, sizeof(*f)};
  alignas(cmsghdr) char control[CMSG_SPACE(sizeof(std::uint32_t))];
  msghdr msg{};
  msg.msg_iov = &iov;
  msg.msg_iovlen = 1;
  msg.msg_control = control;
  msg.msg_controllen = sizeof(control);
  if (::recvmsg(fd, &msg, 0) != static_cast<ssize_t>(sizeof(*f))) return std::nullopt;
  const cmsghdr* c = CMSG_FIRSTHDR(&msg);
  if (c == nullptr || c->cmsg_level != SOL_SOCKET || c->cmsg_type != SO_RXQ_OVFL) {
    return std::nullopt;
  }
  std::uint32_t drops = 0;
  std::memcpy(&drops, CMSG_DATA(c), sizeof(drops));
  return drops;
}

inline can_frame Frame(canid_t id, std::vector<std::uint8_t> data = {}) {
  can_frame f{};
  f.can_id = id;
  f.can_dlc = static_cast<std::uint8_t>(data.size());
  if (!data.empty()) std::memcpy(f.data, data.data(), data.size());  // nullptr when empty
  return f;
}

/// socket + bind to `name` ("" = any); -1 on failure (errno kept).
inline int OpenCan(const std::string& name, int type_flags = 0) {
  const int fd = ::socket(PF_CAN, SOCK_RAW | type_flags, CAN_RAW);
  if (fd < 0) return -1;
  sockaddr_can addr{};
  addr.can_family = AF_CAN;
  addr.can_ifindex = name.empty() ? 0 : static_cast<int>(::if_nametoindex(name.c_str()));
  if ((!name.empty() && addr.can_ifindex == 0) ||
      ::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0) {
    const int err = errno;
    ::close(fd);
    errno = err;
    return -1;
  }
  return fd;
}

inline bool SetInt(int fd, int level, int opt, int value) {
  return ::setsockopt(fd, level, opt, &value, sizeof(value)) == 0;
}

inline bool Send(int fd, const can_frame& f) {
  return ::write(fd, &f, sizeof(f)) == static_cast<ssize_t>(sizeof(f));
}

inline bool Readable(int fd, int timeout_ms) {
  pollfd p{fd, POLLIN, 0};
  return ::poll(&p, 1, timeout_ms) == 1 && (p.revents & POLLIN);
}

/// Waits (2 s at most) for one classic frame; can_id 0xFFFFFFFF when nothing came.
inline can_frame Receive(int fd) {
  can_frame f{};
  f.can_id = 0xFFFFFFFFu;
  if (!Readable(fd, 2000)) return f;
  if (::read(fd, &f, sizeof(f)) != static_cast<ssize_t>(sizeof(f))) f.can_id = 0xFFFFFFFFu;
  return f;
}

/// Nothing pending right now (no waiting: use a sentinel frame before calling this).
inline bool NothingPending(int fd) { return !Readable(fd, 0); }

}  // namespace wheelhil::bus::testing
