#pragma once
// Raw socket I/O for test clients that speak bus/ucan_protocol.h by hand (the hostile-client
// tests and the ucan_protocol fuzz target): a reply with the ring memfd it may carry, and the
// mapping of that memfd. No gtest, so the fuzz target can use it.

#include <sys/mman.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstddef>
#include <cstring>

namespace wheelhil::bus::testing {

/// recvmsg of one message into `buf`; an SCM_RIGHTS descriptor that came with it goes to
/// `*passed_fd` (closed when `passed_fd` is nullptr or one is already there). Returns what
/// recvmsg returned.
inline ssize_t ReceiveWithFd(int fd, void* buf, std::size_t cap, int flags, int* passed_fd) {
  iovec iov{buf, cap};
  alignas(cmsghdr) char control[CMSG_SPACE(sizeof(int))] = {};
  msghdr msg{};
  msg.msg_iov = &iov;
  msg.msg_iovlen = 1;
  msg.msg_control = control;
  msg.msg_controllen = sizeof(control);
  const ssize_t n = ::recvmsg(fd, &msg, flags | MSG_CMSG_CLOEXEC);
  if (n < 0) return n;
  for (cmsghdr* c = CMSG_FIRSTHDR(&msg); c != nullptr; c = CMSG_NXTHDR(&msg, c)) {
    if (c->cmsg_level != SOL_SOCKET || c->cmsg_type != SCM_RIGHTS) continue;
    int got = -1;
    std::memcpy(&got, CMSG_DATA(c), sizeof(got));
    if (passed_fd != nullptr && *passed_fd < 0) {
      *passed_fd = got;
    } else {
      ::close(got);
    }
  }
  return n;
}

/// Maps a ring memfd read-write (its whole size into `*bytes`); nullptr when it cannot.
inline void* MapRingMemfd(int memfd, std::size_t* bytes) {
  struct stat st {};
  if (::fstat(memfd, &st) != 0 || st.st_size <= 0) return nullptr;
  void* p = ::mmap(nullptr, static_cast<std::size_t>(st.st_size), PROT_READ | PROT_WRITE,
                   MAP_SHARED, memfd, 0);
  if (p == MAP_FAILED) return nullptr;
  *bytes = static_cast<std::size_t>(st.st_size);
  return p;
}

}  // namespace wheelhil::bus::testing
