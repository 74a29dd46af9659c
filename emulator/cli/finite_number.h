#pragma once
/// A CLI11 validator for floating-point options: CLI::Range alone lets "nan" through, because
/// every comparison with NaN is false. Use it before the Range check.

#include <CLI/CLI.hpp>

#include <cmath>
#include <cstdlib>
#include <string>

namespace wheelhil::emulator {

inline CLI::Validator FiniteNumber() {
  return CLI::Validator(
      [](std::string& value) {
        return std::isfinite(std::strtod(value.c_str(), nullptr)) ? std::string()
                                                                  : "must be a finite number";
      },
      "FINITE");
}

}  // namespace wheelhil::emulator
