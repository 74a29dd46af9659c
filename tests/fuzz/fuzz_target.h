#pragma once
// Shared by the fuzz targets in this folder. Each target is one file defining
// LLVMFuzzerTestOneInput; built twice (tests/CMakeLists.txt): with libFuzzer under clang
// (`./hil fuzz`, WHEELHIL_FUZZ=ON) and with replay_main.cc under any compiler, which CI runs
// over the committed corpus (FuzzRegression.<target>). A target returns 0 for every input; a
// crash, a sanitizer report, an abort or an exception it does not expect is the finding.

#include <yaml-cpp/yaml.h>

#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <string_view>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

namespace wheelhil::fuzz {

inline std::string Text(const std::uint8_t* data, std::size_t size) {
  return std::string(reinterpret_cast<const char*>(data), size);
}

/// Runs a loader on the input. The input errors wheelhil's CLI turns into exit 2
/// (std::invalid_argument and yaml-cpp's exceptions, emulator/cli/wheelhil_main.cc) are
/// expected; anything else escapes, and libFuzzer reports it as a crash.
template <typename Load>
int ExpectInputErrorsOnly(Load load) {
  try {
    load();
  } catch (const std::invalid_argument&) {
  } catch (const YAML::Exception&) {
  }
  return 0;
}

}  // namespace wheelhil::fuzz
