// DBC text (bus/dbc.h DbcDatabase::Parse).
#include "bus/dbc.h"
#include "tests/fuzz/fuzz_target.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return wheelhil::fuzz::ExpectInputErrorsOnly([&] {
    wheelhil::bus::DbcDatabase::Parse(
        std::string_view(reinterpret_cast<const char*>(data), size), "fuzz.dbc");
  });
}
