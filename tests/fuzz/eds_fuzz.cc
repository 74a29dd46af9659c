// CiA 306 EDS text (bus/canopen_eds.h EdsFile::Parse), then every integer value read with the
// lowest and the highest node id, as a node built from the file reads them: a value outside its
// DataType's range, or a $NODEID sum, must be an input error, never undefined behaviour.
#include "bus/canopen_eds.h"
#include "tests/fuzz/fuzz_target.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using wheelhil::bus::EdsFile;
  return wheelhil::fuzz::ExpectInputErrorsOnly([&] {
    const EdsFile eds =
        EdsFile::Parse(std::string_view(reinterpret_cast<const char*>(data), size), "fuzz.eds");
    for (const auto& kv : eds.entries()) {
      const auto& entry = kv.second;  // a structured binding cannot be captured before C++20
      if (EdsFile::IntegerSize(entry.data_type) == 0 || entry.default_value.empty()) continue;
      for (const int node_id : {1, 127}) {
        wheelhil::fuzz::ExpectInputErrorsOnly(
            [&] { (void)eds.Integer(entry.index, entry.sub, node_id); });
      }
    }
  });
}
