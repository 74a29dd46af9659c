#pragma once
/// Internals of SocketCanTransport, exposed for its unit tests only (no AF_CAN needed):
/// CanFrame <-> `struct can_frame` / `struct canfd_frame`, filter conversion, and the texts of
/// the setup errors Open() throws. Not for other modules. Pure functions; thread-safe.

#include <linux/can.h>

#include <cstddef>
#include <cstdint>
#include <string>
#include <system_error>
#include <vector>

#include "bus/can_frame.h"
#include "bus/socketcan_transport.h"

namespace wheelhil::bus::internal {

/// Encodes `frame` for write(2): fills `buf` (a can_frame for classic and error frames, a
/// canfd_frame for FD frames) and returns the byte count to write (CAN_MTU or CANFD_MTU), or 0
/// when the frame is not IsValid().
std::size_t EncodeFrame(const CanFrame& frame, canfd_frame& buf) noexcept;

/// Decodes a datagram read from a CAN_RAW socket: `size` must be CAN_MTU or CANFD_MTU and the
/// content a valid frame. Returns std::errc::bad_message otherwise (out is then unspecified).
std::error_code DecodeFrame(const void* data, std::size_t size, CanFrame& out) noexcept;

/// The CAN_RAW_FILTER array for `filters`.
std::vector<can_filter> ToKernelFilters(const std::vector<CanFilter>& filters);

/// Message for socket(PF_CAN, SOCK_RAW, CAN_RAW) failing with errno `err`.
std::string NoSocketCanMessage(const std::string& iface, int err);
/// Message for an interface name the kernel does not know (ENODEV).
std::string InterfaceNotFoundMessage(const std::string& iface);
/// Message for an interface that exists but is administratively down.
std::string InterfaceDownMessage(const std::string& iface);
/// Message for an interface that exists but is not a CAN device (bind gives ENODEV).
std::string NotCanInterfaceMessage(const std::string& iface);

}  // namespace wheelhil::bus::internal
