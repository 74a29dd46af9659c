// Cost of the DBC codec (per-signal and whole-message) and of candump line formatting/parsing.
#include <benchmark/benchmark.h>

#include <array>
#include <sstream>
#include <string>

#include "bus/candump_log.h"
#include "bus/dbc.h"
#include "bus/dbc_codec.h"

namespace {

using namespace wheelhil::bus;

// An 8-byte message with 4 signals: two Intel, two Motorola, signed and unsigned, scaled.
constexpr std::string_view kDbc = R"(VERSION ""
BU_: A
BO_ 372 Bench: 8 A
 SG_ Rate : 0|16@1+ (0.005,-163.84) [0|0] "deg/s" A
 SG_ Accel : 16|14@1- (0.0047884033203125,0) [0|0] "m/s^2" A
 SG_ Pos : 39|20@0- (0.0005,0) [0|0] "m" A
 SG_ Count : 51|4@0+ (1,0) [0|0] "" A
)";

const DbcDatabase& Db() {
  static const DbcDatabase db = DbcDatabase::Parse(kDbc, "bench.dbc");
  return db;
}

void BM_EncodeSignals4(benchmark::State& state) {
  const DbcMessage& m = *Db().FindMessage(372, false);
  std::array<std::uint8_t, 8> payload{};
  double x = 0.0;
  for (auto _ : state) {
    x += 1e-3;
    bool ok = EncodeSignal(m.signals[0], 12.5 + x, payload);
    ok &= EncodeSignal(m.signals[1], -3.2 + x, payload);
    ok &= EncodeSignal(m.signals[2], 101.25 + x, payload);
    ok &= EncodeSignal(m.signals[3], 7, payload);
    benchmark::DoNotOptimize(ok);
    benchmark::DoNotOptimize(payload);
    if (x > 1.0) x = 0.0;
  }
}
BENCHMARK(BM_EncodeSignals4);

void BM_DecodeSignals4(benchmark::State& state) {
  const DbcMessage& m = *Db().FindMessage(372, false);
  std::array<std::uint8_t, 8> payload = {0x12, 0x34, 0x56, 0x78, 0x9A, 0xBC, 0xDE, 0xF0};
  for (auto _ : state) {
    benchmark::DoNotOptimize(payload);
    double sum = 0.0;
    for (const auto& s : m.signals) sum += DecodeSignal(s, payload);
    benchmark::DoNotOptimize(sum);
  }
}
BENCHMARK(BM_DecodeSignals4);

void BM_EncodeMessageMap(benchmark::State& state) {
  const DbcMessage& m = *Db().FindMessage(372, false);
  const SignalValues values = {{"Rate", 12.5}, {"Accel", -3.2}, {"Pos", 101.25}, {"Count", 7}};
  CanFrame f;
  for (auto _ : state) {
    benchmark::DoNotOptimize(EncodeMessage(m, values, f));
    benchmark::DoNotOptimize(f);
  }
}
BENCHMARK(BM_EncodeMessageMap);

void BM_DecodeMessageMap(benchmark::State& state) {
  const DbcMessage& m = *Db().FindMessage(372, false);
  const CanFrame f = CanFrame::Classic(372, std::array<std::uint8_t, 8>{1, 2, 3, 4, 5, 6, 7, 8});
  for (auto _ : state) {
    auto v = DecodeMessage(m, f);
    benchmark::DoNotOptimize(v);
  }
}
BENCHMARK(BM_DecodeMessageMap);

void BM_CandumpFormatLine(benchmark::State& state) {
  const CanFrame f = CanFrame::Classic(0x123, std::array<std::uint8_t, 8>{1, 2, 3, 4, 5, 6, 7, 8});
  std::int64_t t = 1'700'000'000'000'000'000LL;
  for (auto _ : state) {
    t += 1000;
    auto line = FormatCandumpLine(t, "vcan0", f);
    benchmark::DoNotOptimize(line);
  }
}
BENCHMARK(BM_CandumpFormatLine);

void BM_CandumpParseLine(benchmark::State& state) {
  const std::string line = "(1700000000.123456) vcan0 123#0102030405060708";
  CandumpRecord r;
  for (auto _ : state) {
    benchmark::DoNotOptimize(ParseCandumpLine(line, 1, r));
    benchmark::DoNotOptimize(r);
  }
}
BENCHMARK(BM_CandumpParseLine);

void BM_CandumpWriterToStream(benchmark::State& state) {
  const CanFrame f = CanFrame::Classic(0x123, std::array<std::uint8_t, 8>{1, 2, 3, 4, 5, 6, 7, 8});
  std::ostringstream out;
  CandumpWriter writer(out);
  std::int64_t t = 0;
  for (auto _ : state) {
    t += 1000;
    benchmark::DoNotOptimize(writer.Write(t, "vcan0", f));
    if (out.tellp() > (1 << 20)) out.str("");
  }
}
BENCHMARK(BM_CandumpWriterToStream);

// A generated database of N extended-id messages: 8 signals each (every 10th multiplexed), a
// comment, a cycle time and value descriptions per message, about 740 bytes a message (135 000
// messages are 100 MB). Loading must stay linear in the messages.
std::string GeneratedDbc(int messages) {
  std::string t = "VERSION \"generated\"\nBU_: A B C\n";
  for (int i = 0; i < messages; ++i) {
    const std::uint32_t id = 0x80000000u | static_cast<std::uint32_t>(i);
    t += "BO_ " + std::to_string(id) + " Message_" + std::to_string(i) + ": 8 A\n";
    for (int k = 0; k < 8; ++k) {
      const bool mux = i % 10 == 0;
      const std::string indicator = !mux ? "" : k == 0 ? " M" : k % 2 == 0 ? " m0" : " m1";
      t += " SG_ Signal_" + std::to_string(i) + "_" + std::to_string(k) + indicator + " : " +
           std::to_string(k * 8) + "|8@1+ (0.1,-12.5) [-12.5|13] \"rpm\" B,C\n";
    }
  }
  t += "BA_DEF_ BO_ \"GenMsgCycleTime\" INT 0 65535;\nBA_DEF_DEF_ \"GenMsgCycleTime\" 0;\n";
  for (int i = 0; i < messages; ++i) {
    const std::string id = std::to_string(0x80000000u | static_cast<std::uint32_t>(i));
    const std::string n = std::to_string(i);
    t += "CM_ BO_ " + id + " \"Message " + n + " of the generated database\";\n";
    t += "CM_ SG_ " + id + " Signal_" + n + "_1 \"the first signal of message " + n + "\";\n";
    t += "BA_ \"GenMsgCycleTime\" BO_ " + id + " " + std::to_string(10 + i % 90) + ";\n";
    t += "VAL_ " + id + " Signal_" + n + "_3 0 \"zero\" 1 \"one\" 255 \"invalid\";\n";
  }
  return t;
}

void BM_DbcParseGenerated(benchmark::State& state) {
  const std::string text = GeneratedDbc(static_cast<int>(state.range(0)));
  for (auto _ : state) {
    const DbcDatabase db = DbcDatabase::Parse(text, "generated.dbc");
    benchmark::DoNotOptimize(db.messages().data());
  }
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations() * text.size()));
}
BENCHMARK(BM_DbcParseGenerated)->Arg(1000)->Arg(10000)->Unit(benchmark::kMillisecond);
// About 100 MB: `bus_codec_bench --benchmark_filter=DbcParseGenerated/135000` (one parse).
BENCHMARK(BM_DbcParseGenerated)->Arg(135000)->Iterations(1)->Unit(benchmark::kSecond);

}  // namespace

BENCHMARK_MAIN();
