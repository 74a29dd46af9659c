#pragma once
// What SO_TIMESTAMPING delivers on a CAN socket, as the kernel does it: shared by the userspace
// bus's test and its twin on a kernel vcan (ucan_broker_test.cc, socketcan_transport_test.cc),
// so the two check the same thing.
#include <linux/can.h>
#include <linux/net_tstamp.h>
#include <sys/socket.h>
#include <time.h>

#include <gtest/gtest.h>

#include <cstring>

namespace wheelhil::bus::testing {

/// The flags that ask for software receive stamps and their report.
inline constexpr int kSoftwareRxStamps = SOF_TIMESTAMPING_RX_SOFTWARE | SOF_TIMESTAMPING_SOFTWARE;

/// Receives one classic frame on `reporting` (SO_TIMESTAMPNS and SO_TIMESTAMPING with
/// kSoftwareRxStamps) and one on `silent` (SO_TIMESTAMPING with SOF_TIMESTAMPING_RX_SOFTWARE
/// only), both readable: the first carries SCM_TIMESTAMPNS, then SCM_TIMESTAMPING whose
/// software stamp is the same instant and whose other two stamps are zero (no hardware clock);
/// the second carries no control message. Returns the frame's stamp in ns.
inline std::int64_t ExpectSoftwareTimestamping(int reporting, int silent) {
  can_frame f{};
  iovec iov{&f, sizeof(f)};
  auto receive = [&](int fd, char* control, std::size_t size) {
    msghdr msg{};
    msg.msg_iov = &iov;
    msg.msg_iovlen = 1;
    msg.msg_control = control;
    msg.msg_controllen = size;
    EXPECT_EQ(::recvmsg(fd, &msg, 0), static_cast<ssize_t>(sizeof(f)));
    return msg;
  };
  alignas(cmsghdr) char control[CMSG_SPACE(sizeof(timespec)) + CMSG_SPACE(3 * sizeof(timespec))];
  msghdr msg = receive(reporting, control, sizeof(control));
  EXPECT_EQ(msg.msg_flags & MSG_CTRUNC, 0);
  cmsghdr* c = CMSG_FIRSTHDR(&msg);
  if (c == nullptr || c->cmsg_type != SCM_TIMESTAMPNS) {
    ADD_FAILURE() << "no SCM_TIMESTAMPNS first";
    return -1;
  }
  timespec ns{};
  std::memcpy(&ns, CMSG_DATA(c), sizeof(ns));
  c = CMSG_NXTHDR(&msg, c);
  if (c == nullptr || c->cmsg_level != SOL_SOCKET || c->cmsg_type != SCM_TIMESTAMPING ||
      c->cmsg_len != CMSG_LEN(3 * sizeof(timespec))) {
    ADD_FAILURE() << "no SCM_TIMESTAMPING of three timespecs after it";
    return -1;
  }
  timespec ts[3]{};
  std::memcpy(ts, CMSG_DATA(c), sizeof(ts));
  EXPECT_EQ(ts[0].tv_sec, ns.tv_sec);
  EXPECT_EQ(ts[0].tv_nsec, ns.tv_nsec);
  for (int k : {1, 2}) EXPECT_EQ(ts[k].tv_sec + ts[k].tv_nsec, 0) << k;
  EXPECT_EQ(CMSG_NXTHDR(&msg, c), nullptr);
  alignas(cmsghdr) char none[CMSG_SPACE(3 * sizeof(timespec))];
  EXPECT_EQ(receive(silent, none, sizeof(none)).msg_controllen, 0u);
  return ts[0].tv_sec * 1000000000LL + ts[0].tv_nsec;
}

}  // namespace wheelhil::bus::testing
