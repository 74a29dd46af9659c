#include "bus/dbc.h"

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <set>
#include <sstream>
#include <stdexcept>

#include "bus/dbc_codec.h"
#include "tests/bus/input_file_test_util.h"

namespace wheelhil::bus {
namespace {

using ::testing::DoubleNear;
using ::testing::ElementsAre;
using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

const std::string kDbcDir = std::string(WHEELHIL_SOURCE_DIR) + "/bus/dbc";

std::vector<std::uint8_t> Bytes(std::span<const std::uint8_t> s) { return {s.begin(), s.end()}; }

std::vector<std::string> ProjectDbcFiles() {
  std::vector<std::string> files;
  for (const auto& e : std::filesystem::directory_iterator(kDbcDir)) {
    if (e.path().extension() == ".dbc") files.push_back(e.path().string());
  }
  std::sort(files.begin(), files.end());
  return files;
}

// Layout of cantools' motohawk.dbc ExampleMessage (its README's hello-world example):
// Motorola signals, a signed 1-bit flag, factor/offset.
constexpr std::string_view kMotohawk = R"(VERSION ""

NS_ :
	CM_
	BA_DEF_

BS_:

BU_: PCM1 FOO

BO_ 496 ExampleMessage: 8 PCM1
 SG_ Enable : 7|1@0- (1,0) [0|0] "-" Vector__XXX
 SG_ AverageRadius : 6|6@0+ (0.1,0) [0|5] "m" Vector__XXX
 SG_ Temperature : 0|12@0- (0.01,250) [229.53|270.47] "degK" PCM1,FOO

CM_ BO_ 496 "Example message used as template in MotoHawk models.";
)";

TEST(DbcCodecTest, MotorolaMatchesCantoolsExample) {
  const auto db = DbcDatabase::Parse(kMotohawk, "motohawk.dbc");
  const DbcMessage* m = db.FindMessage(496, false);
  ASSERT_NE(m, nullptr);
  EXPECT_EQ(m->comment, "Example message used as template in MotoHawk models.");
  EXPECT_THAT(m->FindSignal("Temperature")->receivers, ElementsAre("PCM1", "FOO"));
  // cantools: encode({'Temperature': 250.1, 'AverageRadius': 3.2, 'Enable': 1}) gives
  // c0 01 40 00 00 00 00 00; Enable is a signed 1-bit signal, so raw 1 is physical -1.
  CanFrame f;
  std::string problem;
  ASSERT_TRUE(EncodeMessage(*m, {{"Temperature", 250.1}, {"AverageRadius", 3.2}, {"Enable", -1}}, f,
                            &problem))
      << problem;
  EXPECT_THAT(Bytes(f.payload()), ElementsAre(0xC0, 0x01, 0x40, 0, 0, 0, 0, 0));
  const auto v = DecodeMessage(*m, f);
  EXPECT_THAT(v.at("Temperature"), DoubleNear(250.1, 1e-9));
  EXPECT_THAT(v.at("AverageRadius"), DoubleNear(3.2, 1e-9));
  EXPECT_EQ(v.at("Enable"), -1.0);
  // Enable = +1 does not fit a signed 1-bit signal: saturated to 0 and reported.
  EXPECT_FALSE(EncodeMessage(*m, {{"Enable", 1.0}}, f, &problem));
  EXPECT_THAT(problem, HasSubstr("Enable"));
  EXPECT_EQ(f.data[0], 0x00);
}

DbcSignal MakeSignal(int start, int length, bool little_endian, bool is_signed) {
  DbcSignal s;
  s.name = "s";
  s.start_bit = start;
  s.length = length;
  s.little_endian = little_endian;
  s.is_signed = is_signed;
  return s;
}

TEST(DbcCodecTest, IntelHandComputedPatterns) {
  std::array<std::uint8_t, 8> d{};
  // 12 bits from bit 4: low nibble of raw in the high nibble of byte 0.
  const auto s = MakeSignal(4, 12, true, false);
  ASSERT_TRUE(InsertRaw(s, 0xABC, d));
  EXPECT_THAT(d, ElementsAre(0xC0, 0xAB, 0, 0, 0, 0, 0, 0));
  std::uint64_t raw = 0;
  ASSERT_TRUE(ExtractRaw(s, d, raw));
  EXPECT_EQ(raw, 0xABCu);
  // A 32-bit value across bytes 3..6 leaves its neighbours alone.
  d.fill(0x5A);
  ASSERT_TRUE(InsertRaw(MakeSignal(24, 32, true, false), 0x12345678, d));
  EXPECT_THAT(d, ElementsAre(0x5A, 0x5A, 0x5A, 0x78, 0x56, 0x34, 0x12, 0x5A));
  // 64-bit signal.
  ASSERT_TRUE(InsertRaw(MakeSignal(0, 64, true, false), 0x0102030405060708ULL, d));
  EXPECT_THAT(d, ElementsAre(8, 7, 6, 5, 4, 3, 2, 1));
}

TEST(DbcCodecTest, MotorolaHandComputedPatterns) {
  std::array<std::uint8_t, 8> d{};
  // 7|16@0: MSB is bit 7 of byte 0: plain big-endian u16 in bytes 0-1.
  ASSERT_TRUE(InsertRaw(MakeSignal(7, 16, false, false), 0x1234, d));
  EXPECT_THAT(d, ElementsAre(0x12, 0x34, 0, 0, 0, 0, 0, 0));
  // 3|12@0: top nibble in bits 3..0 of byte 0, low byte in byte 1.
  d.fill(0);
  ASSERT_TRUE(InsertRaw(MakeSignal(3, 12, false, false), 0xABC, d));
  EXPECT_THAT(d, ElementsAre(0x0A, 0xBC, 0, 0, 0, 0, 0, 0));
  // 55|32@0: big-endian u32 in bytes 6..9 does not fit 8 bytes; in bytes 4..7 it is 39|32.
  EXPECT_FALSE(InsertRaw(MakeSignal(55, 32, false, false), 1, d));
  ASSERT_TRUE(InsertRaw(MakeSignal(39, 32, false, false), 0xDEADBEEF, d));
  EXPECT_THAT(d, ElementsAre(0x0A, 0xBC, 0, 0, 0xDE, 0xAD, 0xBE, 0xEF));
  std::uint64_t raw = 0;
  ASSERT_TRUE(ExtractRaw(MakeSignal(39, 32, false, false), d, raw));
  EXPECT_EQ(raw, 0xDEADBEEFu);
  // 56|64@0 is not valid; 7|64@0 is all 8 bytes big-endian.
  ASSERT_TRUE(InsertRaw(MakeSignal(7, 64, false, false), 0x0102030405060708ULL, d));
  EXPECT_THAT(d, ElementsAre(1, 2, 3, 4, 5, 6, 7, 8));
}

TEST(DbcCodecTest, SignedValuesAndSaturation) {
  std::array<std::uint8_t, 8> d{};
  auto s = MakeSignal(0, 8, true, true);
  EXPECT_TRUE(EncodeSignal(s, -1.0, d));
  EXPECT_EQ(d[0], 0xFF);
  EXPECT_EQ(DecodeSignal(s, d), -1.0);
  EXPECT_FALSE(EncodeSignal(s, 200.0, d));  // saturates at +127
  EXPECT_EQ(d[0], 0x7F);
  EXPECT_FALSE(EncodeSignal(s, -1000.0, d));  // saturates at -128
  EXPECT_EQ(d[0], 0x80);
  EXPECT_EQ(DecodeSignal(s, d), -128.0);
  // Signed Motorola 12-bit: -2 = 0xFFE.
  auto m = MakeSignal(3, 12, false, true);
  d.fill(0);
  EXPECT_TRUE(EncodeSignal(m, -2.0, d));
  EXPECT_THAT(d, ElementsAre(0x0F, 0xFE, 0, 0, 0, 0, 0, 0));
  EXPECT_EQ(DecodeSignal(m, d), -2.0);
  // Unsigned: negative saturates to 0, NaN is reported.
  auto u = MakeSignal(8, 4, true, false);
  EXPECT_FALSE(EncodeSignal(u, -3.0, d));
  EXPECT_FALSE(EncodeSignal(u, 16.0, d));
  EXPECT_EQ(DecodeSignal(u, d), 15.0);
  EXPECT_FALSE(EncodeSignal(u, std::nan(""), d));
  // Signed 64-bit extremes.
  auto big = MakeSignal(0, 64, true, true);
  EXPECT_FALSE(EncodeSignal(big, 1e30, d));
  std::int64_t raw = 0;
  ASSERT_TRUE(ExtractRawSigned(big, d, raw));
  EXPECT_EQ(raw, std::numeric_limits<std::int64_t>::max());
}

TEST(DbcCodecTest, FactorOffsetRoundsToNearest) {
  std::array<std::uint8_t, 8> d{};
  auto s = MakeSignal(0, 16, true, false);
  s.factor = 0.005;
  s.offset = -163.84;
  EXPECT_TRUE(EncodeSignal(s, 0.0, d));
  EXPECT_THAT(d, ElementsAre(0x00, 0x80, 0, 0, 0, 0, 0, 0));  // raw 32768
  EXPECT_TRUE(EncodeSignal(s, 0.0026, d));                    // 32768.52 -> 32769
  EXPECT_EQ(d[0], 0x01);
  EXPECT_TRUE(EncodeSignal(s, 0.0024, d));  // 32768.48 -> 32768
  EXPECT_EQ(d[0], 0x00);
  EXPECT_THAT(DecodeSignal(s, d), DoubleNear(0.0, 1e-12));
  EXPECT_DOUBLE_EQ(SignalPhysicalMin(s), -163.84);
  EXPECT_THAT(SignalPhysicalMax(s), DoubleNear(163.835, 1e-9));
  // Too short a payload: decode gives NaN, encode writes nothing.
  std::array<std::uint8_t, 1> one{0x77};
  EXPECT_TRUE(std::isnan(DecodeSignal(s, one)));
  EXPECT_FALSE(EncodeSignal(s, 1.0, one));
  EXPECT_EQ(one[0], 0x77);
}

TEST(DbcCodecTest, FloatSignalsAndFdPayloads) {
  constexpr std::string_view kText = R"(VERSION ""
BU_: A
BO_ 2147484672 FdMsg: 16 A
 SG_ F32 : 0|32@1- (1,0) [0|0] "" A
 SG_ F64 : 32|64@1- (2,0) [0|0] "" A
 SG_ Tail : 103|16@0+ (1,0) [0|0] "" A
SIG_VALTYPE_ 2147484672 F32 : 1;
SIG_VALTYPE_ 2147484672 F64 : 2;
)";
  const auto db = DbcDatabase::Parse(kText, "fd.dbc");
  const DbcMessage* m = db.FindMessage(0x400, true);
  ASSERT_NE(m, nullptr);
  EXPECT_EQ(m->FindSignal("F32")->value_type, DbcValueType::kFloat32);
  CanFrame f;
  ASSERT_TRUE(EncodeMessage(*m, {{"F32", 1.5}, {"F64", -3.25}, {"Tail", 0xBEEF}}, f));
  EXPECT_TRUE(f.fd);
  EXPECT_TRUE(f.extended);
  EXPECT_EQ(f.len, 16);
  EXPECT_THAT(Bytes(f.payload()).at(3), 0x3F);  // 1.5f = 0x3FC00000, little-endian
  EXPECT_EQ(f.data[12], 0xBE);                  // bytes 12-13 via the bit-by-bit path
  EXPECT_EQ(f.data[13], 0xEF);
  std::array<std::uint8_t, 16> bytes{};
  EXPECT_FALSE(EncodeSignal(*m->FindSignal("F32"), 1e40, bytes));  // beyond float: +inf
  EXPECT_TRUE(std::isinf(DecodeSignal(*m->FindSignal("F32"), bytes)));
  const auto v = DecodeMessage(*m, f);
  EXPECT_EQ(v.at("F32"), 1.5);
  EXPECT_EQ(v.at("F64"), -3.25);
  EXPECT_EQ(v.at("Tail"), 0xBEEF);
}

constexpr std::string_view kMultiplexed = R"(VERSION ""
BU_: ECU
BO_ 291 Mux: 8 ECU
 SG_ Sel M : 0|8@1+ (1,0) [0|255] "" ECU
 SG_ Common : 8|8@1+ (1,0) [0|255] "" ECU
 SG_ A m1 : 16|16@1- (0.5,0) [0|0] "" ECU
 SG_ B m2 : 16|16@1+ (1,100) [0|0] "" ECU
 SG_ C m2 : 39|8@0+ (1,0) [0|0] "" ECU
VAL_ 291 Sel 1 "ModeA" 2 "ModeB" ;
)";

TEST(DbcCodecTest, MultiplexedMessages) {
  const auto db = DbcDatabase::Parse(kMultiplexed, "mux.dbc");
  const DbcMessage* m = db.FindMessage("Mux");
  ASSERT_NE(m, nullptr);
  ASSERT_NE(m->multiplexer(), nullptr);
  EXPECT_EQ(m->multiplexer()->name, "Sel");
  EXPECT_EQ(m->FindSignal("B")->multiplex_value, 2);
  EXPECT_EQ(m->FindSignal("Sel")->value_names.at(2), "ModeB");

  CanFrame f;
  ASSERT_TRUE(EncodeMessage(*m, {{"Sel", 1}, {"Common", 7}, {"A", -1.5}}, f));
  EXPECT_THAT(Bytes(f.payload()), ElementsAre(1, 7, 0xFD, 0xFF, 0, 0, 0, 0));
  auto v = DecodeMessage(*m, f);
  EXPECT_EQ(v.size(), 3u);
  EXPECT_EQ(v.at("A"), -1.5);
  EXPECT_EQ(v.count("B"), 0u);

  ASSERT_TRUE(EncodeMessage(*m, {{"Sel", 2}, {"B", 101}, {"C", 9}}, f));
  EXPECT_THAT(Bytes(f.payload()), ElementsAre(2, 0, 1, 0, 9, 0, 0, 0));
  v = DecodeMessage(*m, f);
  EXPECT_EQ(v.at("B"), 101.0);
  EXPECT_EQ(v.at("C"), 9.0);
  EXPECT_EQ(v.count("A"), 0u);

  // A signal of another multiplexer value is refused (and not written).
  std::string problem;
  EXPECT_FALSE(EncodeMessage(*m, {{"Sel", 1}, {"B", 5}}, f, &problem));
  EXPECT_THAT(problem, HasSubstr("multiplexer value 2"));
  EXPECT_FALSE(EncodeMessage(*m, {{"Nope", 5}}, f, &problem));
  EXPECT_THAT(problem, HasSubstr("Nope"));
}

TEST(DbcParseTest, AttributesCommentsValueTables) {
  constexpr std::string_view kText = R"(VERSION "1.2"

NS_ :
	NS_DESC_
	CM_
	BA_DEF_
	BA_
	VAL_
	BA_DEF_DEF_

BS_:

BU_: Sender Receiver
VAL_TABLE_ OnOff 1 "On" 0 "Off" ;

BO_ 100 Fast: 2 Sender
 SG_ Flag : 0|1@1+ (1,0) [0|1] "" Receiver

BO_ 101 Slow: 1 Sender
 SG_ Level : 0|8@1+ (1,0) [0|255] "%" Receiver

BO_ 102 Other: 1 Sender
 SG_ X : 0|8@1+ (1,0) [0|255] "" Receiver

BO_TX_BU_ 100 : Sender;
CM_ "Network
comment over two lines";
CM_ BU_ Sender "the sender";
CM_ BO_ 100 "fast one";
CM_ SG_ 100 Flag "a flag with \"escapes\"";
BA_DEF_ BO_ "GenMsgCycleTime" INT 0 65535;
BA_DEF_ BO_ "GenMsgSendType" ENUM "Cyclic","Event";
BA_DEF_ SG_ "GenSigStartValue" INT 0 100000;
BA_DEF_ "BusType" STRING ;
BA_DEF_DEF_ "GenMsgCycleTime" 100;
BA_DEF_DEF_ "GenMsgSendType" "Cyclic";
BA_DEF_DEF_ "GenSigStartValue" 0;
BA_DEF_DEF_ "BusType" "CAN";
BA_ "BusType" "CAN";
BA_ "GenMsgCycleTime" BO_ 100 10;
BA_ "GenMsgSendType" BO_ 101 1;
BA_ "GenSigStartValue" SG_ 100 Flag 1;
VAL_ 100 Flag 1 "Set" 0 "Clear" ;
)";
  const auto db = DbcDatabase::Parse(kText, "attr.dbc");
  EXPECT_EQ(db.version(), "1.2");
  EXPECT_EQ(db.comment(), "Network\ncomment over two lines");
  EXPECT_THAT(db.nodes(), ElementsAre("Sender", "Receiver"));
  EXPECT_EQ(db.value_tables().at("OnOff").at(1), "On");
  EXPECT_EQ(db.FindMessage(100, false)->cycle_time_ms, 10);
  EXPECT_EQ(db.FindMessage(101, false)->cycle_time_ms, 100);  // BA_DEF_DEF_ default
  // An ENUM attribute is its string, not the index the file wrote; defaults fill the rest.
  EXPECT_EQ(db.FindMessage(101, false)->attributes.at("GenMsgSendType"), "Event");
  EXPECT_EQ(db.FindMessage(100, false)->attributes.at("GenMsgSendType"), "Cyclic");
  EXPECT_EQ(db.FindMessage(100, false)->FindSignal("Flag")->attributes.at("GenSigStartValue"), "1");
  EXPECT_EQ(db.FindMessage(102, false)->FindSignal("X")->attributes.at("GenSigStartValue"), "0");
  EXPECT_EQ(db.FindMessage(100, false)->comment, "fast one");
  EXPECT_EQ(db.FindMessage(100, false)->FindSignal("Flag")->comment, "a flag with \"escapes\"");
  EXPECT_EQ(db.FindMessage(100, false)->FindSignal("Flag")->value_names.at(1), "Set");
  EXPECT_EQ(db.FindMessage(101, false)->FindSignal("Level")->unit, "%");
  EXPECT_EQ(db.FindMessage(100, true), nullptr);
  EXPECT_EQ(db.FindMessage("Nope"), nullptr);
}

// Signals that can be in one frame must not share a bit (Intel and Motorola alike); signals of
// different multiplexer values may.
TEST(DbcParseTest, OverlappingSignalsAreRefusedWithTheMessageLine) {
  const std::string head = "VERSION \"\"\nBU_: A\n";
  EXPECT_THAT([&] {
    (void)DbcDatabase::Parse(head + "BO_ 1 M: 2 A\n SG_ P : 0|8@1+ (1,0) [0|0] \"\" A\n"
                                    " SG_ Q : 4|8@1+ (1,0) [0|0] \"\" A\n", "o.dbc");
  }, ThrowsMessage<std::invalid_argument>(
         HasSubstr("o.dbc:3: message M: signals P and Q overlap (both use bit 4, 4 bits")));
  // Motorola: P is bits 7..0 of byte 0; Q from bit 1 runs 1, 0, then 15..: overlaps P at 1, 0.
  EXPECT_THAT([&] {
    (void)DbcDatabase::Parse(head + "BO_ 1 M: 2 A\n SG_ P : 7|8@0+ (1,0) [0|0] \"\" A\n"
                                    " SG_ Q : 1|4@0+ (1,0) [0|0] \"\" A\n", "o.dbc");
  }, ThrowsMessage<std::invalid_argument>(HasSubstr("signals P and Q overlap")));
  // Motorola neighbours that do not touch, and multiplexed signals sharing their bits.
  EXPECT_NO_THROW((void)DbcDatabase::Parse(
      head + "BO_ 1 M: 2 A\n SG_ P : 7|8@0+ (1,0) [0|0] \"\" A\n"
             " SG_ Q : 15|8@0+ (1,0) [0|0] \"\" A\n", "o.dbc"));
  EXPECT_NO_THROW((void)DbcDatabase::Parse(
      head + "BO_ 1 M: 3 A\n SG_ S M : 0|8@1+ (1,0) [0|0] \"\" A\n"
             " SG_ P m0 : 8|16@1+ (1,0) [0|0] \"\" A\n SG_ Q m1 : 8|8@1+ (1,0) [0|0] \"\" A\n",
      "o.dbc"));
  EXPECT_THAT([&] {
    (void)DbcDatabase::Parse(head + "BO_ 1 M: 3 A\n SG_ S M : 0|8@1+ (1,0) [0|0] \"\" A\n"
                                    " SG_ P m0 : 4|8@1+ (1,0) [0|0] \"\" A\n", "o.dbc");
  }, ThrowsMessage<std::invalid_argument>(HasSubstr("signals S and P overlap")));
}

TEST(DbcParseTest, NamespaceBlockWithoutIndentation) {
  const auto db = DbcDatabase::Parse(
      "VERSION \"\"\nNS_ :\nCM_\nBA_DEF_\nVAL_TABLE_\nBS_:\nBU_: A\n"
      "BO_ 1 M: 1 A\n SG_ S : 0|8@1+ (1,0) [0|0] \"\" A\n",
      "ns.dbc");
  EXPECT_THAT(db.nodes(), ElementsAre("A"));
  ASSERT_NE(db.FindMessage("M"), nullptr);
}

TEST(DbcParseTest, ExtendedIdsAndIndependentSignals) {
  constexpr std::string_view kText = R"(VERSION ""
BU_: A
BO_ 2566844926 J1939: 8 A
 SG_ S : 0|8@1+ (1,0) [0|0] "" A
BO_ 3221225472 VECTOR__INDEPENDENT_SIG_MSG: 0 Vector__XXX
 SG_ Orphan : 0|8@1+ (1,0) [0|0] "" Vector__XXX
CM_ SG_ 3221225472 Orphan "dropped";
)";
  const auto db = DbcDatabase::Parse(kText, "ext.dbc");
  ASSERT_EQ(db.messages().size(), 1u);
  const DbcMessage* m = db.FindMessage(0x18FEF1FE, true);
  ASSERT_NE(m, nullptr);
  EXPECT_TRUE(m->extended);
  EXPECT_EQ(db.FindMessage(0x18FEF1FE, false), nullptr);
}

TEST(DbcParseTest, ErrorsNameFileAndLine) {
  auto parse = [](std::string_view text) { return DbcDatabase::Parse(text, "bad.dbc"); };
  EXPECT_THAT(
      [&] { parse("VERSION \"\"\nBU_: A\nBO_ 1 M: 8 A\n SG_ S : 60|8@1+ (1,0) [0|0] \"\" A\n"); },
      ThrowsMessage<std::invalid_argument>(HasSubstr("bad.dbc:4: signal S: 60|8@1")));
  EXPECT_THAT([&] { parse("BU_: A\nBO_ 1 M: 8 A\n SG_ S : 0|8@2+ (1,0) [0|0] \"\" A\n"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("bad.dbc:3: signal S: byte order")));
  EXPECT_THAT([&] { parse("BU_: A\nBO_ 1 M: 8 A\n SG_ S : 0|8@1+ (0,0) [0|0] \"\" A\n"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("bad.dbc:3: signal S: factor")));
  EXPECT_THAT([&] { parse("BU_: A\n\nBO_ 4096 M: 8 A\n"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("bad.dbc:3: message M: id 0x1000")));
  EXPECT_THAT(
      [&] { parse("BU_: A\nBO_ 1 M: 8 A\nBO_ 1 N: 8 A\n"); },
      ThrowsMessage<std::invalid_argument>(HasSubstr("bad.dbc:3: message N: id 1 defined twice")));
  EXPECT_THAT([&] { parse("BU_: A\nBO_ 1 M: 8 A\n SG_ S m1 : 0|8@1+ (1,0) [0|0] \"\" A\n"); },
              ThrowsMessage<std::invalid_argument>(
                  HasSubstr("bad.dbc:2: message M: signal S is multiplexed")));
  EXPECT_THAT([&] { parse("BU_: A\nBO_ 1 M: 8 A\n SG_ S m1M : 0|8@1+ (1,0) [0|0] \"\" A\n"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("extended multiplexing")));
  EXPECT_THAT(
      [&] { parse("BU_: A\nBO_ 1 M: 8 A\nCM_ SG_ 1 T \"x\";\n"); },
      ThrowsMessage<std::invalid_argument>(HasSubstr("bad.dbc:3: message M has no signal 'T'")));
  EXPECT_THAT([&] { parse("BU_: A\nBO_ 1 M: 8 A\nCM_ BO_ 1 \"never closed;\n\n"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("bad.dbc:3: unterminated string")));
  EXPECT_THAT([&] { parse("BU_: A\nFOO_ 1;\n"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("bad.dbc:2: unknown keyword 'FOO_'")));
  EXPECT_THAT(
      [&] {
        parse("BU_: A\nBO_ 1 M: 4 A\n SG_ F : 0|16@1- (1,0) [0|0] \"\" A\nSIG_VALTYPE_ 1 F : 1;\n");
      },
      ThrowsMessage<std::invalid_argument>(
          HasSubstr("bad.dbc:4: signal F: SIG_VALTYPE_ 1 needs a 32-bit")));
  EXPECT_THAT([&] { DbcDatabase::LoadFile("/nonexistent/x.dbc"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("/nonexistent/x.dbc")));
}

// The index of messages and signals that made loading linear: every lookup finds its own, and
// each name or id given twice is still refused.
TEST(DbcParseTest, ManyMessagesAreFoundByIdAndNameAndDuplicatesRefused) {
  std::string text = "BU_: A\n";
  for (int i = 0; i < 3000; ++i) {
    text += fmt::format("BO_ {} M{}: 8 A\n SG_ S{} : 0|8@1+ (1,0) [0|0] \"\" A\n",
                        0x80000000u + static_cast<unsigned>(i) * 7, i, i);
  }
  for (int i = 2999; i >= 0; --i) {
    text += fmt::format("CM_ SG_ {} S{} \"signal {}\";\n",
                        0x80000000u + static_cast<unsigned>(i) * 7, i, i);
  }
  const auto db = DbcDatabase::Parse(text, "many.dbc");
  ASSERT_EQ(db.messages().size(), 3000u);
  for (int i = 0; i < 3000; i += 499) {
    const DbcMessage* m = db.FindMessage(static_cast<std::uint32_t>(i) * 7, true);
    ASSERT_NE(m, nullptr) << i;
    EXPECT_EQ(m->name, fmt::format("M{}", i));
    EXPECT_EQ(m->signals[0].comment, fmt::format("signal {}", i));
    EXPECT_EQ(db.FindMessage(m->name), m);
  }
  auto throws = [&](const std::string& more, const std::string& what) {
    EXPECT_THAT([&] { (void)DbcDatabase::Parse(text + more, "many.dbc"); },
                ThrowsMessage<std::invalid_argument>(HasSubstr(what)));
  };
  throws("BO_ 5 M17: 1 A\n", "many.dbc:9002: message name 'M17' defined twice");
  throws("BO_ 2147483662 X: 1 A\n", "many.dbc:9002: message X: id 2147483662 defined twice");
  throws("BO_ 5 X: 1 A\n SG_ T : 0|1@1+ (1,0) [0|0] \"\" A\n SG_ T : 1|1@1+ (1,0) [0|0] \"\" A\n",
         "many.dbc:9004: signal T defined twice in message X");
  throws(
      "BO_ 5 X: 2 A\n SG_ T M : 0|1@1+ (1,0) [0|0] \"\" A\n SG_ U M : 8|1@1+ (1,0) [0|0] \"\" A\n",
      "many.dbc:9004: message X: second multiplexer switch U");
  throws("CM_ SG_ 2147483662 S3 \"x\";\n", "many.dbc:9002: message M2 has no signal 'S3'");
  throws("CM_ BO_ 2147483663 \"x\";\n", "many.dbc:9002: message id 2147483663 is not defined");
}

// Many multiplexed signals in one message are checked for overlaps value by value: the bits of
// one value's signals may repeat another value's, never the switch's or their own value's.
TEST(DbcParseTest, OverlapsAmongManyMultiplexedSignals) {
  std::string text = "BU_: A\nBO_ 1 M: 8 A\n SG_ S M : 0|16@1+ (1,0) [0|0] \"\" A\n";
  for (int v = 0; v < 2000; ++v) {
    text += fmt::format(" SG_ P{} m{} : 16|16@1+ (1,0) [0|0] \"\" A\n", v, v);
    text += fmt::format(" SG_ Q{} m{} : 32|32@1+ (1,0) [0|0] \"\" A\n", v, v);
  }
  EXPECT_EQ(DbcDatabase::Parse(text, "mux.dbc").messages()[0].signals.size(), 4001u);
  EXPECT_THAT(
      [&] {
        (void)DbcDatabase::Parse(text + " SG_ R m7 : 40|4@1+ (1,0) [0|0] \"\" A\n", "mux.dbc");
      },
      ThrowsMessage<std::invalid_argument>(
          HasSubstr("mux.dbc:2: message M: signals Q7 and R overlap (both use bit 40, 4 bits")));
  EXPECT_THAT(
      [&] {
        (void)DbcDatabase::Parse(text + " SG_ R m9 : 12|8@1+ (1,0) [0|0] \"\" A\n", "mux.dbc");
      },
      ThrowsMessage<std::invalid_argument>(
          HasSubstr("mux.dbc:2: message M: signals S and R overlap (both use bit 12, 4 bits")));
  EXPECT_NO_THROW(
      (void)DbcDatabase::Parse(text + " SG_ R m2000 : 16|48@1+ (1,0) [0|0] \"\" A\n", "mux.dbc"));
}

// LoadFile reads regular files only, says why not, and a byte-order mark is no syntax error.
TEST(DbcLoadFileTest, OnlyRegularFilesOfAtMostTheLimitAndABomIsSkipped) {
  using testing::ScratchDir;
  const ScratchDir dir;
  auto error = [](const std::string& path) -> std::string {
    try {
      (void)DbcDatabase::LoadFile(path);
    } catch (const std::invalid_argument& e) {
      return e.what();
    }
    return "(loaded without an error)";
  };
  // It waited for a writer forever.
  const std::string fifo = dir.Fifo("fifo.dbc");
  EXPECT_EQ(testing::LoadErrorOfFifo(fifo, [&] { (void)DbcDatabase::LoadFile(fifo); }),
            fifo + ":0: is not a regular file (a device or a pipe?)");
  EXPECT_EQ(error(dir.Path("")), dir.Path("") + ":0: is a directory, not a DBC file");
  EXPECT_EQ(error("/dev/zero"), "/dev/zero:0: is not a regular file (a device or a pipe?)");
  EXPECT_EQ(error(dir.Path("none.dbc")),
            dir.Path("none.dbc") + ":0: cannot open DBC file (No such file or directory)");
  const std::string big = dir.Sparse("big.dbc", DbcDatabase::kMaxFileBytes + 1);
  EXPECT_EQ(error(big), big +
                            ":0: is larger than 128 MiB, the limit for a DBC file; the largest "
                            "real ones are tens of MiB");
  // Written by a Windows tool: EF BB BF before VERSION.
  const auto db = DbcDatabase::LoadFile(std::string(WHEELHIL_SOURCE_DIR) +
                                        "/tests/data/dbc/utf8_bom_motor_controller.dbc");
  ASSERT_NE(db.FindMessage("MC_Command"), nullptr);
  EXPECT_EQ(db.version(), "1.0");
  // Only at the start.
  EXPECT_THAT([] { (void)DbcDatabase::Parse("BU_: A\n\xEF\xBB\xBF", "bom.dbc"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("bom.dbc:2: unexpected character")));
}

// Random truncations and byte mutations of every project file must parse or throw
// std::invalid_argument; anything else (crash, other exception) fails the test.
TEST(DbcParseTest, TruncatedAndMutatedFilesNeverCrash) {
  std::mt19937 rng(20261123);
  for (const auto& path : ProjectDbcFiles()) {
    std::ifstream in(path);
    std::stringstream ss;
    ss << in.rdbuf();
    const std::string text = ss.str();
    int parsed = 0, rejected = 0;
    for (int i = 0; i < 200; ++i) {
      std::string t =
          text.substr(0, std::uniform_int_distribution<std::size_t>(0, text.size())(rng));
      if (i % 2 == 1 && !t.empty()) {
        for (int k = 0; k < 3; ++k) {
          t[std::uniform_int_distribution<std::size_t>(0, t.size() - 1)(rng)] =
              static_cast<char>(std::uniform_int_distribution<int>(0, 255)(rng));
        }
      }
      try {
        (void)DbcDatabase::Parse(t, "fuzz.dbc");
        ++parsed;
      } catch (const std::invalid_argument& e) {
        EXPECT_THAT(e.what(), HasSubstr("fuzz.dbc:"));
        ++rejected;
      }
    }
    EXPECT_GT(rejected, 0) << path;
    EXPECT_EQ(parsed + rejected, 200) << path;
  }
}

// --- the project's DBC files ---------------------------------------------------------------

TEST(ProjectDbcTest, EveryFileLoadsAndIdsAreUniqueOnTheBus) {
  const auto files = ProjectDbcFiles();
  ASSERT_EQ(files.size(), 5u);
  std::set<std::pair<std::uint32_t, bool>> ids;
  for (const auto& path : files) {
    const auto db = DbcDatabase::LoadFile(path);
    EXPECT_FALSE(db.messages().empty()) << path;
    for (const auto& m : db.messages()) {
      EXPECT_TRUE(ids.insert({m.id, m.extended}).second)
          << path << ": id 0x" << std::hex << m.id << " also used by another file";
      EXPECT_LE(m.length, 8) << m.name << ": the wheelhil bus is classic CAN";
      // No two signals share a bit (the project files are not multiplexed).
      std::array<std::uint8_t, 8> used{};
      for (const auto& sig : m.signals) {
        std::array<std::uint8_t, 8> bits{};
        ASSERT_TRUE(InsertRaw(sig, ~std::uint64_t{0}, std::span(bits).first(m.length)));
        for (int b = 0; b < 8; ++b) {
          EXPECT_EQ(used[b] & bits[b], 0) << m.name << "." << sig.name << " overlaps in byte " << b;
          used[b] |= bits[b];
        }
      }
      EXPECT_FALSE(m.comment.empty() && m.name.rfind("Enc", 0) != 0 && m.name != "SYNC")
          << m.name << " has no comment";
    }
  }
}

TEST(ProjectDbcTest, EverySignalRoundTripsRandomRawValues) {
  std::mt19937_64 rng(7);
  for (const auto& path : ProjectDbcFiles()) {
    const auto db = DbcDatabase::LoadFile(path);
    for (const auto& m : db.messages()) {
      for (int i = 0; i < 50; ++i) {
        CanFrame f = CanFrame{};
        f.len = static_cast<std::uint8_t>(m.length);
        for (int b = 0; b < m.length; ++b) f.data[b] = static_cast<std::uint8_t>(rng());
        const auto values = DecodeMessage(m, f);
        CanFrame g;
        std::string problem;
        ASSERT_TRUE(EncodeMessage(m, values, g, &problem)) << m.name << ": " << problem;
        // Bits not covered by any signal are zero in g; covered bits must match.
        for (const auto& sig : m.signals) {
          std::uint64_t a = 0, b = 0;
          ASSERT_TRUE(ExtractRaw(sig, f.payload(), a));
          ASSERT_TRUE(ExtractRaw(sig, g.payload(), b));
          EXPECT_EQ(a, b) << m.name << "." << sig.name;
        }
      }
    }
  }
}

// DecodeSignalIfPresent lists exactly what DecodeMessage lists, with the same values: checked
// on every project message with random payloads of every length (short frames leave signals
// out) and on the multiplexed fixture for both multiplexer values and a frame too short for it.
void ExpectSameAsDecodeMessage(const DbcMessage& m, const CanFrame& f) {
  const auto values = DecodeMessage(m, f);
  std::size_t present = 0;
  for (const auto& sig : m.signals) {
    double v = -12345.0;
    const bool ok = DecodeSignalIfPresent(m, sig, f, &v);
    const auto it = values.find(sig.name);
    ASSERT_EQ(ok, it != values.end()) << m.name << "." << sig.name << " len " << int{f.len};
    if (!ok) {
      EXPECT_EQ(v, -12345.0) << m.name << "." << sig.name << ": out written although absent";
      continue;
    }
    ++present;
    // Bit-identical, NaN included.
    EXPECT_EQ(std::memcmp(&v, &it->second, sizeof v), 0) << m.name << "." << sig.name;
  }
  EXPECT_EQ(present, values.size()) << m.name;
}

TEST(DbcCodecTest, DecodeSignalIfPresentAgreesWithDecodeMessage) {
  std::mt19937_64 rng(11);
  for (const auto& path : ProjectDbcFiles()) {
    const auto db = DbcDatabase::LoadFile(path);
    for (const auto& m : db.messages()) {
      for (int len = 0; len <= m.length; ++len) {
        for (int i = 0; i < 8; ++i) {
          CanFrame f = CanFrame{};
          f.id = m.id;
          f.len = static_cast<std::uint8_t>(len);
          for (int b = 0; b < len; ++b) f.data[b] = static_cast<std::uint8_t>(rng());
          ExpectSameAsDecodeMessage(m, f);
        }
      }
    }
  }
  const auto mux = DbcDatabase::Parse(kMultiplexed, "mux.dbc");
  const DbcMessage* m = mux.FindMessage("Mux");
  ASSERT_NE(m, nullptr);
  CanFrame f;
  ASSERT_TRUE(EncodeMessage(*m, {{"Sel", 1}, {"Common", 7}, {"A", -1.5}}, f));
  ExpectSameAsDecodeMessage(*m, f);
  double a = 0;
  EXPECT_TRUE(DecodeSignalIfPresent(*m, *m->FindSignal("A"), f, &a));
  EXPECT_EQ(a, -1.5);
  EXPECT_FALSE(DecodeSignalIfPresent(*m, *m->FindSignal("B"), f, &a));
  ASSERT_TRUE(EncodeMessage(*m, {{"Sel", 2}, {"B", 101}, {"C", 9}}, f));
  ExpectSameAsDecodeMessage(*m, f);
  EXPECT_FALSE(DecodeSignalIfPresent(*m, *m->FindSignal("A"), f, &a));
  f.len = 0;  // no multiplexer value at all: only plain signals could be present (none fit)
  ExpectSameAsDecodeMessage(*m, f);
  EXPECT_FALSE(DecodeSignalIfPresent(*m, *m->FindSignal("B"), f, &a));
}

const DbcMessage& Msg(const DbcDatabase& db, std::string_view name) {
  const DbcMessage* m = db.FindMessage(name);
  if (!m) throw std::runtime_error("no message " + std::string(name));
  return *m;
}

CanFrame Frame(std::uint32_t id, std::vector<std::uint8_t> bytes) {
  return CanFrame::Classic(id, bytes);
}

TEST(ProjectDbcTest, Cia406GoldenFrames) {
  const auto db = DbcDatabase::LoadFile(kDbcDir + "/cia406_encoder.dbc");
  // From tests/data/golden/cia406_sync_tpdo.log: 181#785634129CFF
  auto v = DecodeMessage(*db.FindMessage(0x181, false),
                         Frame(0x181, {0x78, 0x56, 0x34, 0x12, 0x9C, 0xFF}));
  EXPECT_EQ(v.at("PositionValue"), 0x12345678);
  EXPECT_EQ(v.at("SpeedValue"), -100);
  // 085#0573010000000000: EMCY 0x7305 incremental sensor 1 fault, error register 1.
  const auto& emcy = Msg(db, "Enc5_EMCY");
  EXPECT_EQ(emcy.id, 0x85u);
  v = DecodeMessage(emcy, Frame(0x85, {0x05, 0x73, 0x01, 0, 0, 0, 0, 0}));
  EXPECT_EQ(v.at("EMCY_ErrorCode"), 0x7305);
  EXPECT_EQ(emcy.FindSignal("EMCY_ErrorCode")->value_names.at(0x7305), "IncrementalSensor1Fault");
  EXPECT_EQ(v.at("EMCY_ErrorRegister"), 1);
  // 000#0105: start node 5. 705#7F: pre-operational heartbeat.
  v = DecodeMessage(Msg(db, "NMT_Command"), Frame(0, {0x01, 0x05}));
  EXPECT_EQ(v.at("NMT_CommandSpecifier"), 1);
  EXPECT_EQ(v.at("NMT_NodeId"), 5);
  const auto& hb = Msg(db, "Enc5_Heartbeat");
  EXPECT_EQ(hb.id, 0x705u);
  EXPECT_EQ(hb.cycle_time_ms, 100);
  EXPECT_EQ(hb.FindSignal("NMT_State")->value_names.at(127), "PreOperational");
  EXPECT_EQ(hb.FindSignal("NMT_State")->value_names.at(5), "Operational");
  // 583#4318100178563412: SDO upload response 0x1018:1 = 0x12345678.
  v = DecodeMessage(Msg(db, "Enc3_SDO_Tx"),
                    Frame(0x583, {0x43, 0x18, 0x10, 0x01, 0x78, 0x56, 0x34, 0x12}));
  EXPECT_EQ(v.at("SDO_Command"), 0x43);
  EXPECT_EQ(v.at("SDO_Index"), 0x1018);
  EXPECT_EQ(v.at("SDO_SubIndex"), 1);
  EXPECT_EQ(v.at("SDO_Data"), 0x12345678);
  EXPECT_EQ(Msg(db, "Enc3_SDO_Rx").id, 0x603u);
  EXPECT_EQ(Msg(db, "SYNC").length, 0);
  for (int n = 1; n <= 8; ++n) {
    EXPECT_NE(db.FindMessage(0x180 + n, false), nullptr) << n;
    EXPECT_NE(db.FindMessage(0x700 + n, false), nullptr) << n;
  }
}

TEST(ProjectDbcTest, BoschMm510Scaling) {
  const auto db = DbcDatabase::LoadFile(kDbcDir + "/bosch_mm5_10.dbc");
  const auto& yaw = Msg(db, "MM5_YawRate_AccelY");
  EXPECT_EQ(yaw.id, 0x174u);
  EXPECT_EQ(yaw.cycle_time_ms, 10);
  EXPECT_EQ(Msg(db, "MM5_RollRate_AccelX").id, 0x178u);
  EXPECT_EQ(Msg(db, "MM5_PitchRate_AccelZ").id, 0x17Cu);
  CanFrame f;
  ASSERT_TRUE(EncodeMessage(yaw, {{"MM5_YawRate", 10.0}, {"MM5_AccelY", 1.0}}, f));
  // 10 deg/s: raw (10 + 163.84) / 0.005 = 34768 = 0x87D0; 1 g: (1 + 4.1768) / 0.0001274 =
  // 40634.2 -> 40634 = 0x9EBA.
  EXPECT_THAT(Bytes(f.payload()), ElementsAre(0xD0, 0x87, 0, 0, 0xBA, 0x9E, 0, 0));
  const auto v = DecodeMessage(yaw, f);
  EXPECT_THAT(v.at("MM5_YawRate"), DoubleNear(10.0, 1e-9));
  EXPECT_THAT(v.at("MM5_AccelY"), DoubleNear(1.0, 0.0001274 / 2));
}

TEST(ProjectDbcTest, Accel4AndFirmwareLayouts) {
  const auto acc = DbcDatabase::LoadFile(kDbcDir + "/wheelhil_accel4.dbc");
  const auto& a = Msg(acc, "ACC4_Data");
  EXPECT_EQ(a.cycle_time_ms, 1);
  CanFrame f;
  const double g = 9.80665;
  ASSERT_TRUE(EncodeMessage(a,
                            {{"ACC4_A1", g},
                             {"ACC4_A2", -g},
                             {"ACC4_A3", 0.5 * g},
                             {"ACC4_A4", -4 * g},
                             {"ACC4_Counter", 9},
                             {"ACC4_Checksum", 3}},
                            f));
  auto v = DecodeMessage(a, f);
  EXPECT_THAT(v.at("ACC4_A1"), DoubleNear(g, 1e-9));  // 1 g = 2048 LSB exactly
  EXPECT_THAT(v.at("ACC4_A4"), DoubleNear(-4 * g, 1e-9));
  EXPECT_FALSE(EncodeMessage(a, {{"ACC4_A1", 4 * g}}, f));  // +4 g saturates to 8191 LSB
  EXPECT_EQ(f.data[7] >> 4, 0);

  const auto fw = DbcDatabase::LoadFile(kDbcDir + "/wheelhil_fw.dbc");
  const auto& pose = Msg(fw, "FW_Pose");
  ASSERT_TRUE(EncodeMessage(
      pose,
      {{"Pose_Cycle", 200}, {"Pose_X", -12.3455}, {"Pose_Y", 250.0}, {"Pose_Theta", -3.14159}}, f));
  v = DecodeMessage(pose, f);
  EXPECT_THAT(v.at("Pose_X"), DoubleNear(-12.3455, 0.00025 + 1e-12));
  EXPECT_THAT(v.at("Pose_Y"), DoubleNear(250.0, 1e-9));
  EXPECT_THAT(v.at("Pose_Theta"), DoubleNear(-3.14159, 0.00005 + 1e-12));
  EXPECT_EQ(v.at("Pose_Cycle"), 200);
  const auto& slip = Msg(fw, "FW_SlipStatus");
  ASSERT_TRUE(EncodeMessage(slip,
                            {{"Slip_Residual", -0.004321},
                             {"Slip_BandLower", -0.00335},
                             {"Slip_OutOfBand", 1},
                             {"Slip_BandUpper", 0.00328},
                             {"Slip_Left", 1}},
                            f));
  v = DecodeMessage(slip, f);
  EXPECT_THAT(v.at("Slip_Residual"), DoubleNear(-0.004321, 1e-12));
  EXPECT_THAT(v.at("Slip_BandLower"), DoubleNear(-0.00335, 1e-12));
  EXPECT_EQ(v.at("Slip_Left"), 1);
  EXPECT_EQ(v.at("Slip_Right"), 0);
  EXPECT_EQ(v.at("Slip_OutOfBand"), 1);
  EXPECT_EQ(v.at("Slip_Calibrated"), 0);
  EXPECT_FALSE(EncodeMessage(slip, {{"Slip_Residual", 0.3}}, f));  // beyond +-0.262143 rad
  for (const char* name : {"FW_Velocity", "FW_VelocityOdom", "FW_VelocityAccel"}) {
    const auto& vel = Msg(fw, name);
    EXPECT_EQ(vel.signals.size(), 4u) << name;
    EXPECT_DOUBLE_EQ(vel.signals[1].factor, 1e-4) << name;
  }
  EXPECT_NE(Msg(fw, "FW_Status").FindSignal("Status_NodeLostEnc8"), nullptr);
}

// --- independent check: canmatrix (Debian python3-canmatrix) decodes the same values --------

std::string FindPythonWith(const char* module) {
  for (const char* py : {"/usr/bin/python3", "python3"}) {
    const std::string cmd = std::string(py) + " -c 'import " + module + "' >/dev/null 2>&1";
    if (std::system(cmd.c_str()) == 0) return py;
  }
  return "";
}

TEST(ProjectDbcTest, CanmatrixDecodesTheSameValues) {
  const std::string python = FindPythonWith("canmatrix");
  if (python.empty())
    GTEST_SKIP() << "python3-canmatrix is not installed (./hil setup installs it)";
  const std::string dir = ::testing::TempDir();
  const std::string in_path = dir + "/wheelhil_bus_codec_canmatrix_in.txt";
  const std::string out_path = dir + "/wheelhil_bus_codec_canmatrix_out.txt";
  std::mt19937_64 rng(99);
  std::vector<SignalValues> ours;
  {
    std::ofstream in(in_path);
    for (const auto& path : ProjectDbcFiles()) {
      const auto db = DbcDatabase::LoadFile(path);
      for (const auto& m : db.messages()) {
        for (int i = 0; i < 5; ++i) {
          CanFrame f{};
          f.len = static_cast<std::uint8_t>(m.length);
          std::string hex;
          for (int b = 0; b < m.length; ++b) {
            f.data[b] = static_cast<std::uint8_t>(rng());
            char buf[3];
            std::snprintf(buf, sizeof buf, "%02X", f.data[b]);
            hex += buf;
          }
          in << path << ' ' << std::hex << m.id << std::dec << ' ' << hex << '\n';
          ours.push_back(DecodeMessage(m, f));
        }
      }
    }
  }
  const std::string cmd = python + " " + WHEELHIL_SOURCE_DIR +
                          "/tests/bus/scripts/dbc_canmatrix_decode.py < " + in_path + " > " +
                          out_path + " 2>/dev/null";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  std::ifstream out(out_path);
  std::size_t index = 0;
  SignalValues theirs;
  for (std::string line; std::getline(out, line);) {
    if (line == "--") {
      ASSERT_LT(index, ours.size());
      EXPECT_EQ(theirs.size(), ours[index].size()) << "frame " << index;
      for (const auto& [name, value] : ours[index]) {
        ASSERT_EQ(theirs.count(name), 1u) << name;
        EXPECT_NEAR(theirs.at(name), value, 1e-9 * std::max(1.0, std::abs(value))) << name;
      }
      theirs.clear();
      ++index;
      continue;
    }
    const auto eq = line.find('=');
    ASSERT_NE(eq, std::string::npos) << line;
    theirs[line.substr(0, eq)] = std::stod(line.substr(eq + 1));
  }
  EXPECT_EQ(index, ours.size());
}

}  // namespace
}  // namespace wheelhil::bus
