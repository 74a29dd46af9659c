// The DBC codec (bus/dbc_codec.h) on every message of the shipped DBC files: arbitrary
// payloads and lengths decode without reading past the frame, and what decodes encodes again.
// Input: [file][message][length][flags][payload...].
#include <memory>
#include <vector>

#include "bus/dbc.h"
#include "bus/dbc_codec.h"
#include "tests/fuzz/fuzz_target.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace wheelhil::bus;
  static const std::vector<DbcDatabase> dbs = [] {
    std::vector<DbcDatabase> out;
    for (const char* name : {"cia406_encoder.dbc", "cia402_drive.dbc", "bosch_mm5_10.dbc",
                             "wheelhil_accel4.dbc", "wheelhil_fw.dbc"}) {
      out.push_back(DbcDatabase::LoadFile(std::string(WHEELHIL_SOURCE_DIR) + "/bus/dbc/" + name));
    }
    return out;
  }();
  if (size < 4) return 0;
  const DbcDatabase& db = dbs[data[0] % dbs.size()];
  if (db.messages().empty()) return 0;
  const DbcMessage& msg = db.messages()[data[1] % db.messages().size()];
  CanFrame frame;
  frame.id = msg.id;
  frame.extended = msg.extended;
  frame.fd = (data[3] & 1) != 0;
  frame.len = static_cast<std::uint8_t>(data[2] % ((frame.fd ? CanFrame::kMaxFdLen
                                                             : CanFrame::kMaxClassicLen) + 1));
  for (std::size_t i = 0; i < frame.len && 4 + i < size; ++i) frame.data[i] = data[4 + i];
  const SignalValues values = DecodeMessage(msg, frame);
  for (const DbcSignal& sig : msg.signals) {
    double v = 0;
    DecodeSignalIfPresent(msg, sig, frame, &v);
  }
  CanFrame again;
  std::string problem;
  EncodeMessage(msg, values, again, &problem);
  return 0;
}
