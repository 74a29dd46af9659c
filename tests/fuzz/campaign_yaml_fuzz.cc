// Campaign YAML (emulator/campaign/campaign_spec.h ParseCampaign), read as a file next to the
// shipped campaigns so that its base scenario can be a real one.
#include "emulator/campaign/campaign_spec.h"
#include "tests/fuzz/fuzz_target.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::string file =
      std::string(WHEELHIL_SOURCE_DIR) + "/scenarios/campaigns/fuzz.yaml";
  return wheelhil::fuzz::ExpectInputErrorsOnly(
      [&] { wheelhil::emulator::campaign::ParseCampaign(wheelhil::fuzz::Text(data, size), file); });
}
