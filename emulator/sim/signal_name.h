#pragma once
/// A signal as failure reasons name it: "signal 11 (SIGSEGV)". Thread-safe.

#include <string.h>

#include <string>

namespace wheelhil::emulator::sim {

inline std::string SignalName(int sig) {
  const char* abbrev = ::sigabbrev_np(sig);
  return "signal " + std::to_string(sig) + " (" +
         (abbrev != nullptr ? "SIG" + std::string(abbrev) : std::string("unknown")) + ")";
}

}  // namespace wheelhil::emulator::sim
