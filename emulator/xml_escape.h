#pragma once
/// Escaping text for XML and HTML (element text and quoted attribute values): & < > " ' become
/// entity references; C0 controls other than tab/CR/LF are dropped; bytes that are not UTF-8
/// (a firmware's or a runner's message can hold any) and the non-characters U+FFFE, U+FFFF
/// become U+FFFD, so the document stays well-formed. Used by report.html, campaign.html and
/// JUnit XML. Header-only: the scenario and campaign libraries share it without a link
/// dependency.

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "bus/internal/utf8.h"

namespace wheelhil::emulator {

inline std::string EscapeXml(std::string_view s) {
  std::string out;
  out.reserve(s.size());
  for (std::size_t i = 0; i < s.size();) {
    const char c = s[i];
    if (static_cast<unsigned char>(c) >= 0x80) {
      std::uint32_t cp = 0;
      const std::size_t n = bus::internal::Utf8Sequence(s, i, cp);
      if (n == 0 || cp == 0xFFFE || cp == 0xFFFF) {
        out += "\xEF\xBF\xBD";  // U+FFFD REPLACEMENT CHARACTER, for one byte or character
        i += n == 0 ? 1 : n;
      } else {
        out.append(s.substr(i, n));
        i += n;
      }
      continue;
    }
    ++i;
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&apos;";
        break;
      default:
        // XML 1.0 forbids most C0 controls even as references (and HTML has no use for them).
        if (static_cast<unsigned char>(c) < 0x20 && c != '\n' && c != '\t' && c != '\r') break;
        out += c;
    }
  }
  return out;
}

}  // namespace wheelhil::emulator
