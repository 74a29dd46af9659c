// Scenario YAML (emulator/scenario/scenario.h ParseScenario). The input is read as a file in
// scenarios/, so its relative references (platforms, meshes, DBC files, firmware configs)
// reach the shipped ones and the loader goes deep.
#include "emulator/scenario/scenario.h"
#include "tests/fuzz/fuzz_target.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::string file = std::string(WHEELHIL_SOURCE_DIR) + "/scenarios/fuzz.yaml";
  return wheelhil::fuzz::ExpectInputErrorsOnly(
      [&] { wheelhil::emulator::scenario::ParseScenario(wheelhil::fuzz::Text(data, size), file); });
}
