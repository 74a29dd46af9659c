// The reference firmware's config YAML (firmware_stub/fw_config.h ParseFwConfig).
#include "firmware_stub/fw_config.h"
#include "tests/fuzz/fuzz_target.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return wheelhil::fuzz::ExpectInputErrorsOnly(
      [&] { wheelhil::fw::ParseFwConfig(wheelhil::fuzz::Text(data, size), "fuzz.yaml"); });
}
