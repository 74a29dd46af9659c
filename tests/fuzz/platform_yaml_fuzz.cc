// Platform YAML (emulator/platforms/platform.h LoadPlatformYaml).
#include "emulator/platforms/platform.h"
#include "tests/fuzz/fuzz_target.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::string file =
      std::string(WHEELHIL_SOURCE_DIR) + "/scenarios/platforms/fuzz.yaml";
  return wheelhil::fuzz::ExpectInputErrorsOnly(
      [&] { wheelhil::emulator::platforms::LoadPlatformYaml(wheelhil::fuzz::Text(data, size), file); });
}
