#pragma once
/// A platform-neutral CAN / CAN FD frame. Conversion to Linux `struct can_frame` and
/// `struct canfd_frame` happens only inside the SocketCAN transport and the userspace bus.
/// A value type; thread-compatible.

#include <array>
#include <cstdint>
#include <span>
#include <string>

namespace wheelhil::bus {

struct CanFrame {
  static constexpr std::uint32_t kMaxStandardId = 0x7FF;
  static constexpr std::uint32_t kMaxExtendedId = 0x1FFFFFFF;
  static constexpr std::size_t kMaxClassicLen = 8;
  static constexpr std::size_t kMaxFdLen = 64;

  std::uint32_t id = 0;       ///< 11-bit or 29-bit identifier (no flag bits), or error class bits.
  bool extended = false;      ///< 29-bit identifier.
  bool rtr = false;           ///< Remote transmission request (classic frames only).
  bool error = false;         ///< Error frame (id holds the CAN_ERR_* class mask).
  bool fd = false;            ///< CAN FD frame.
  std::uint8_t fd_flags = 0;  ///< CANFD_BRS (0x01) / CANFD_ESI (0x02) for FD frames.
  std::uint8_t len = 0;       ///< Payload length in bytes (for RTR: the requested DLC).
  std::array<std::uint8_t, kMaxFdLen> data{};

  std::span<const std::uint8_t> payload() const { return {data.data(), len}; }

  /// Builds a classic data frame; throws std::invalid_argument on a bad id or length.
  static CanFrame Classic(std::uint32_t id, std::span<const std::uint8_t> bytes,
                          bool extended = false);

  /// True when id, length and flags form a frame a controller could send.
  bool IsValid() const noexcept;

  bool operator==(const CanFrame& other) const noexcept;
};

/// Valid CAN FD payload lengths are 0..8, 12, 16, 20, 24, 32, 48, 64.
bool IsValidFdLength(std::size_t len) noexcept;
/// DLC code (0..15) for a payload length (rounded up to the next valid FD length).
std::uint8_t LengthToDlc(std::size_t len) noexcept;
/// Payload length for a DLC code; classic frames cap at 8.
std::size_t DlcToLength(std::uint8_t dlc, bool fd) noexcept;

/// can-utils `ID#DATA` notation: `123#DEADBEEF`, `12345678#00`, `123#R`, `123##1AABB` (FD).
std::string ToCanUtilsString(const CanFrame& frame);

}  // namespace wheelhil::bus
