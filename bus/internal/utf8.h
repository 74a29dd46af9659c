#pragma once
/// Decoding UTF-8 one sequence at a time, as RFC 3629 defines it: no overlong forms, no
/// surrogates, nothing past U+10FFFF. Header-only. Used by the YAML reader (which refuses text
/// that is not UTF-8) and the XML/HTML escaper (which replaces it).

#include <cstddef>
#include <cstdint>
#include <string_view>

namespace wheelhil::bus::internal {

/// Length of the well-formed UTF-8 sequence at s[i] (1 to 4), 0 when there is none; `cp` its
/// code point.
inline std::size_t Utf8Sequence(std::string_view s, std::size_t i, std::uint32_t& cp) {
  const auto b = [&](std::size_t k) { return static_cast<unsigned char>(s[i + k]); };
  const unsigned char c = b(0);
  std::size_t n = 0;
  std::uint32_t min = 0;
  if (c < 0x80) {
    cp = c;
    return 1;
  }
  if ((c & 0xE0) == 0xC0) {
    n = 2;
    cp = c & 0x1Fu;
    min = 0x80;
  } else if ((c & 0xF0) == 0xE0) {
    n = 3;
    cp = c & 0x0Fu;
    min = 0x800;
  } else if ((c & 0xF8) == 0xF0) {
    n = 4;
    cp = c & 0x07u;
    min = 0x10000;
  } else {
    return 0;
  }
  if (i + n > s.size()) return 0;
  for (std::size_t k = 1; k < n; ++k) {
    if ((b(k) & 0xC0) != 0x80) return 0;
    cp = (cp << 6) | (b(k) & 0x3F);
  }
  if (cp < min || cp > 0x10FFFF || (cp >= 0xD800 && cp <= 0xDFFF)) return 0;
  return n;
}

}  // namespace wheelhil::bus::internal
