#pragma once
// Checks on the text of report pages, shared by the scoring and campaign tests.

#include <cctype>
#include <cstddef>
#include <string>

namespace wheelhil::emulator::scoring::testing {

/// Where `s` holds a number in exponent notation ("1e-05"), the position of its 'e'; npos
/// when it holds none. (std::regex would do, but g++ 12 warns inside it under -O2 with ASan.)
inline std::size_t FindExponent(const std::string& s) {
  for (std::size_t i = 1; i + 2 < s.size(); ++i) {
    if (s[i] == 'e' && (s[i + 1] == '-' || s[i + 1] == '+') &&
        std::isdigit(static_cast<unsigned char>(s[i - 1])) &&
        std::isdigit(static_cast<unsigned char>(s[i + 2]))) {
      return i;
    }
  }
  return std::string::npos;
}

}  // namespace wheelhil::emulator::scoring::testing
