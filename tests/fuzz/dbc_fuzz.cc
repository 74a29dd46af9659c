// DBC text (bus/dbc.h DbcDatabase::Parse), then one frame per multiplexer value of every
// multiplexed message, encoded and decoded, as the `dbc` device sends them: the parser's
// checks (switch, m<n> signals, overlaps) must leave nothing the codec reads past its frame.
#include <set>

#include "bus/dbc.h"
#include "bus/dbc_codec.h"
#include "tests/fuzz/fuzz_target.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace wheelhil::bus;
  return wheelhil::fuzz::ExpectInputErrorsOnly([&] {
    const DbcDatabase db =
        DbcDatabase::Parse(std::string_view(reinterpret_cast<const char*>(data), size), "fuzz.dbc");
    for (const DbcMessage& m : db.messages()) {
      const DbcSignal* mux = m.multiplexer();
      if (mux == nullptr) continue;
      std::set<int> values;
      for (const DbcSignal& s : m.signals) {
        if (s.multiplex_value) values.insert(*s.multiplex_value);
      }
      for (const int v : values) {
        SignalValues in = {{mux->name, static_cast<double>(v)}};
        for (const DbcSignal& s : m.signals) {
          if (s.multiplex_value == v) in[s.name] = s.maximum;
        }
        const CanFrame f = EncodeMessage(m, in);
        (void)DecodeMessage(m, f);
      }
    }
  });
}
