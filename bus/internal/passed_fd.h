#pragma once
/// One descriptor passed with a message on an AF_UNIX socket (SCM_RIGHTS), for the ucan broker
/// and its clients. Not installed.

#include <sys/socket.h>

#include <cstring>

namespace wheelhil::bus::internal {

/// Room for one passed descriptor's control message.
struct PassedFdControl {
  alignas(cmsghdr) char bytes[CMSG_SPACE(sizeof(int))] = {};
};

/// `msg` passes `fd` (control: its storage, alive until the message is sent).
inline void AttachFd(msghdr& msg, PassedFdControl& control, int fd) {
  msg.msg_control = control.bytes;
  msg.msg_controllen = sizeof(control.bytes);
  cmsghdr* cm = CMSG_FIRSTHDR(&msg);
  cm->cmsg_level = SOL_SOCKET;
  cm->cmsg_type = SCM_RIGHTS;
  cm->cmsg_len = CMSG_LEN(sizeof(int));
  std::memcpy(CMSG_DATA(cm), &fd, sizeof(int));
}

/// `msg` (received into `control`) may carry a descriptor: before the receive.
inline void ExpectFd(msghdr& msg, PassedFdControl& control) {
  msg.msg_control = control.bytes;
  msg.msg_controllen = sizeof(control.bytes);
}

/// The descriptor `msg` received (-1: none).
inline int ReceivedFd(msghdr& msg) {
  int fd = -1;
  for (cmsghdr* cm = CMSG_FIRSTHDR(&msg); cm != nullptr; cm = CMSG_NXTHDR(&msg, cm)) {
    if (cm->cmsg_level == SOL_SOCKET && cm->cmsg_type == SCM_RIGHTS &&
        cm->cmsg_len >= CMSG_LEN(sizeof(int))) {
      std::memcpy(&fd, CMSG_DATA(cm), sizeof(fd));
    }
  }
  return fd;
}

}  // namespace wheelhil::bus::internal
