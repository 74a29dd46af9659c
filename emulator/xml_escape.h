#pragma once
/// Escaping text for XML and HTML (element text and quoted attribute values): & < > " ' become
/// entity references; C0 controls other than tab/CR/LF are dropped. Used by report.html,
/// campaign.html and JUnit XML. Header-only: the scenario and campaign libraries share it without a
/// link dependency.

#include <string>
#include <string_view>

namespace wheelhil::emulator {

inline std::string EscapeXml(std::string_view s) {
  std::string out;
  out.reserve(s.size());
  for (const char c : s) {
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
