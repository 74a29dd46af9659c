#include "bus/can_frame.h"

#include <fmt/format.h>

#include <algorithm>
#include <stdexcept>

namespace wheelhil::bus {
namespace {
constexpr std::array<std::uint8_t, 16> kDlcToLen = {0, 1,  2,  3,  4,  5,  6,  7,
                                                    8, 12, 16, 20, 24, 32, 48, 64};
constexpr char kHex[] = "0123456789ABCDEF";
constexpr std::uint32_t kMaxExtendedIdMask = CanFrame::kMaxExtendedId;
}  // namespace

CanFrame CanFrame::Classic(std::uint32_t id, std::span<const std::uint8_t> bytes, bool extended) {
  if (bytes.size() > kMaxClassicLen) {
    throw std::invalid_argument(fmt::format(
        "CAN frame 0x{:X}: {} data bytes (classic CAN carries at most 8)", id, bytes.size()));
  }
  if (id > (extended ? kMaxExtendedId : kMaxStandardId)) {
    throw std::invalid_argument(fmt::format("CAN id 0x{:X} does not fit a {} identifier", id,
                                            extended ? "29-bit" : "11-bit"));
  }
  CanFrame f;
  f.id = id;
  f.extended = extended;
  f.len = static_cast<std::uint8_t>(bytes.size());
  std::copy(bytes.begin(), bytes.end(), f.data.begin());
  return f;
}

bool CanFrame::IsValid() const noexcept {
  if (error) return len <= kMaxClassicLen && !fd;
  if (id > (extended ? kMaxExtendedId : kMaxStandardId)) return false;
  if (fd) return !rtr && IsValidFdLength(len);
  return len <= kMaxClassicLen;
}

bool CanFrame::operator==(const CanFrame& o) const noexcept {
  return id == o.id && extended == o.extended && rtr == o.rtr && error == o.error && fd == o.fd &&
         (!fd || fd_flags == o.fd_flags) && len == o.len &&
         (rtr || std::equal(data.begin(), data.begin() + len, o.data.begin()));
}

bool IsValidFdLength(std::size_t len) noexcept {
  return std::find(kDlcToLen.begin(), kDlcToLen.end(), len) != kDlcToLen.end();
}

std::uint8_t LengthToDlc(std::size_t len) noexcept {
  for (std::uint8_t dlc = 0; dlc < kDlcToLen.size(); ++dlc) {
    if (kDlcToLen[dlc] >= len) return dlc;
  }
  return 15;
}

std::size_t DlcToLength(std::uint8_t dlc, bool fd) noexcept {
  dlc &= 0x0F;
  if (!fd) return std::min<std::size_t>(dlc, 8);
  return kDlcToLen[dlc];
}

std::string ToCanUtilsString(const CanFrame& f) {
  std::string s;
  if (f.error) {
    // lib.c sprint_canframe: can_id & (CAN_ERR_MASK | CAN_ERR_FLAG)
    s = fmt::format("{:08X}#", (f.id & kMaxExtendedIdMask) | 0x20000000u);
  } else if (f.extended) {
    s = fmt::format("{:08X}#", f.id);
  } else {
    s = fmt::format("{:03X}#", f.id);
  }
  if (f.rtr) {
    s += 'R';
    // lib.c prints the requested DLC only when it is 1..8.
    if (f.len > 0 && f.len <= CanFrame::kMaxClassicLen) s += static_cast<char>('0' + f.len);
    return s;
  }
  if (f.fd) {
    s += '#';
    s += kHex[f.fd_flags & 0x0F];
  }
  for (std::uint8_t i = 0; i < f.len; ++i) {
    s += kHex[f.data[i] >> 4];
    s += kHex[f.data[i] & 0x0F];
  }
  return s;
}

}  // namespace wheelhil::bus
