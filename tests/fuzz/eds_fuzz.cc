// CiA 306 EDS text (bus/canopen_eds.h EdsFile::Parse).
#include "bus/canopen_eds.h"
#include "tests/fuzz/fuzz_target.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return wheelhil::fuzz::ExpectInputErrorsOnly([&] {
    wheelhil::bus::EdsFile::Parse(std::string_view(reinterpret_cast<const char*>(data), size),
                                  "fuzz.eds");
  });
}
