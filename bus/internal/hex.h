#pragma once
/// One hex digit's value, for the log readers (candump, ASC). Not installed.

namespace wheelhil::bus::internal {

/// 0..15 for 0-9, A-F, a-f; -1 for anything else.
constexpr int HexValue(char c) noexcept {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  return -1;
}

}  // namespace wheelhil::bus::internal
