// candump -L logs (bus/candump_log.h): every line through ParseCandumpLine, which never throws;
// a record must format back to a line that parses to the same frame.
#include <cstdlib>

#include "bus/candump_log.h"
#include "tests/fuzz/fuzz_target.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace wheelhil::bus;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  std::size_t line_number = 0;
  for (std::size_t pos = 0; pos <= text.size();) {
    const std::size_t end = std::min(text.find('\n', pos), text.size());
    const std::string_view line = text.substr(pos, end - pos);
    ++line_number;
    CandumpRecord rec;
    std::string error;
    if (ParseCandumpLine(line, line_number, rec, &error) == CandumpLineStatus::kRecord) {
      const std::string again = FormatCandumpLine(rec.timestamp_ns, rec.interface, rec.frame);
      CandumpRecord back;
      if (ParseCandumpLine(again, 1, back) != CandumpLineStatus::kRecord ||
          !(back.frame == rec.frame)) {
        std::abort();  // a record that does not survive its own formatting
      }
    }
    pos = end + 1;
  }
  CanFrame frame;
  ParseCanUtilsFrame(text, frame);
  return 0;
}
