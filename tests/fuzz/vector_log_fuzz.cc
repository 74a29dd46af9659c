// Vector ASC and BLF logs (bus/vector_logs.h): any bytes through ParseCanLog as either format,
// which may refuse them only with std::invalid_argument; what it reads must survive its own
// writing: formatted again and read back, the same frames.
#include <cstdlib>

#include "bus/vector_logs.h"
#include "tests/fuzz/fuzz_target.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace wheelhil::bus;
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  for (const CanLogFormat format : {CanLogFormat::kAsc, CanLogFormat::kBlf}) {
    std::vector<CandumpRecord> records;
    try {
      records = ParseCanLog(bytes, format, "input");
    } catch (const std::invalid_argument&) {
      continue;
    }
    const std::string again =
        format == CanLogFormat::kAsc ? FormatAsc(records) : FormatBlf(records);
    const auto back = ParseCanLog(again, format, "again");
    if (back.size() != records.size()) std::abort();
    for (std::size_t i = 0; i < back.size(); ++i) {
      const bool lossy_error = format == CanLogFormat::kAsc && records[i].frame.error;
      if (!lossy_error && !(back[i].frame == records[i].frame)) std::abort();
    }
  }
  return 0;
}
