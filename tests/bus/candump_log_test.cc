#include "bus/candump_log.h"
#include "tests/command_output.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <random>
#include <sstream>

namespace wheelhil::bus {
namespace {

using ::testing::ElementsAre;
using ::testing::HasSubstr;
using ::testing::StartsWith;

const std::string kDataDir = std::string(WHEELHIL_SOURCE_DIR) + "/tests/data/candump";

CanFrame Classic(std::uint32_t id, std::vector<std::uint8_t> bytes, bool extended = false) {
  return CanFrame::Classic(id, bytes, extended);
}
CanFrame Rtr(std::uint32_t id, std::uint8_t len, bool extended = false) {
  CanFrame f;
  f.id = id;
  f.extended = extended;
  f.rtr = true;
  f.len = len;
  return f;
}
CanFrame Error(std::uint32_t err_class, std::vector<std::uint8_t> bytes) {
  CanFrame f = Classic(0, bytes);
  f.error = true;
  f.id = err_class;
  return f;
}
CanFrame Fd(std::uint32_t id, std::uint8_t flags, std::size_t len, bool extended = false) {
  CanFrame f;
  f.id = id;
  f.extended = extended;
  f.fd = true;
  f.fd_flags = flags;
  f.len = static_cast<std::uint8_t>(len);
  for (std::size_t i = 0; i < len; ++i) f.data[i] = static_cast<std::uint8_t>(i);
  return f;
}

// A set of frames that covers every notation of the format.
std::vector<CanFrame> AllKinds() {
  return {Classic(0x123, {0xDE, 0xAD, 0xBE, 0xEF}),
          Classic(0x000, {}),
          Classic(0x7FF, {1, 2, 3, 4, 5, 6, 7, 8}),
          Classic(0x12345678, {0x00}, true),
          Classic(0x1FFFFFFF, {0xFF}, true),
          Classic(0x5, {0xAA}, true),  // extended id with leading zeros: 00000005#
          Rtr(0x7FF, 0),
          Rtr(0x123, 8),
          Rtr(0x1ABCDE, 3, true),
          Error(0x004, {0, 0, 0x08, 0, 0, 0, 0, 0}),
          Fd(0x123, 0x1, 2),
          Fd(0x181, 0x0, 0),
          Fd(0x1ABCDEF0, 0x3, 12, true),
          Fd(0x7FF, 0x2, 64)};
}

TEST(CandumpFormatTest, MatchesCandumpDashL) {
  EXPECT_EQ(FormatCandumpLine(1'700'000'000'000'000'000LL, "ucan0",
                              Classic(0x123, {0xDE, 0xAD, 0xBE, 0xEF})),
            "(1700000000.000000) ucan0 123#DEADBEEF");
  // candump pads seconds to 10 digits (as the golden traces in tests/data/golden do).
  EXPECT_EQ(FormatCandumpLine(10'000'000, "vcan0", Classic(0x703, {0x00})),
            "(0000000000.010000) vcan0 703#00");
  // Sub-microsecond parts are truncated like the kernel's timeval; negative clamps to 0.
  EXPECT_EQ(FormatCandumpLine(1'999'999'999, "can0", Classic(0x80, {})),
            "(0000000001.999999) can0 080#");
  EXPECT_EQ(FormatCandumpLine(-5, "can0", Classic(0x80, {})), "(0000000000.000000) can0 080#");
  EXPECT_EQ(FormatCandumpLine(0, "can0", Classic(0x5, {0xAA}, true)),
            "(0000000000.000000) can0 00000005#AA");
  EXPECT_EQ(FormatCandumpLine(0, "can0", Rtr(0x123, 8)), "(0000000000.000000) can0 123#R8");
  EXPECT_EQ(FormatCandumpLine(0, "can0", Error(0x80, {0, 0, 0, 0, 0, 0, 0, 0})),
            "(0000000000.000000) can0 20000080#0000000000000000");
  EXPECT_EQ(FormatCandumpLine(0, "can0", Fd(0x123, 0x1, 2)), "(0000000000.000000) can0 123##10001");
}

TEST(CandumpFormatTest, BufferFormIsBoundedAndAllocationFree) {
  const CanFrame f = Fd(0x1FFFFFFF, 3, 64, true);
  std::string buf(MaxCandumpLineLength(6), '\0');
  const std::size_t n =
      FormatCandumpLine(9'223'372'036'854'775'807LL, "vcan10", f, buf.data(), buf.size());
  EXPECT_EQ(n, buf.size() - 1);  // 10-digit seconds: one char under the bound
  EXPECT_THAT(buf.substr(0, n), StartsWith("(9223372036.854775) vcan10 1FFFFFFF##3000102"));
  EXPECT_EQ(FormatCandumpLine(0, "vcan10", f, buf.data(), buf.size() - 1), 0u);
}

TEST(CandumpFormatTest, CanUtilsStringFollowsLibC) {
  // lib.c sprint_canframe prints an RTR length digit only for 1..8 and masks error ids.
  EXPECT_EQ(ToCanUtilsString(Rtr(0x123, 0)), "123#R");
  EXPECT_EQ(ToCanUtilsString(Rtr(0x123, 12)), "123#R");
  CanFrame e = Error(0xFFFFFFFF, {});
  EXPECT_EQ(ToCanUtilsString(e), "3FFFFFFF#");
}

TEST(CandumpRoundTripTest, WriterThenReaderGivesTheSameRecords) {
  std::stringstream log;
  CandumpWriter writer(log);
  std::vector<CandumpRecord> written;
  std::int64_t t_ns = 1'700'000'000'000'000'000LL;
  for (const auto& f : AllKinds()) {
    t_ns += 1'234'000;
    written.push_back({t_ns, written.size() % 2 ? "vcan10" : "ucan0", f, 0});
    ASSERT_TRUE(writer.Write(written.back())) << ToCanUtilsString(f);
  }
  ASSERT_TRUE(writer.Flush());
  EXPECT_EQ(writer.lines_written(), written.size());
  CandumpReader reader(log);
  CandumpRecord r;
  for (const auto& w : written) {
    ASSERT_EQ(reader.Next(r), CandumpReader::Status::kRecord) << reader.error();
    EXPECT_EQ(r, w) << ToCanUtilsString(w.frame);
  }
  EXPECT_EQ(reader.Next(r), CandumpReader::Status::kEnd);
}

TEST(CandumpRoundTripTest, RandomFramesRoundTrip) {
  std::mt19937 rng(42);
  std::stringstream log;
  CandumpWriter writer(log, CandumpWriter::FlushPolicy::kEveryLine);
  std::vector<CandumpRecord> written;
  for (int i = 0; i < 500; ++i) {
    CanFrame f;
    f.extended = rng() % 2;
    f.id = static_cast<std::uint32_t>(rng()) & (f.extended ? 0x1FFFFFFF : 0x7FF);
    f.fd = rng() % 3 == 0;
    if (f.fd) {
      f.fd_flags = rng() % 4;
      f.len = static_cast<std::uint8_t>(DlcToLength(rng() % 16, true));
    } else {
      f.rtr = rng() % 8 == 0;
      f.len = rng() % 9;
    }
    for (int b = 0; b < f.len; ++b) f.data[b] = static_cast<std::uint8_t>(rng());
    if (f.rtr) f.data.fill(0);
    const std::int64_t t = static_cast<std::int64_t>(rng() % 4'000'000'000u) * 1000;
    written.push_back({t, "can0", f, 0});
    // The allocation-free formatter writes the frame exactly as ToCanUtilsString does.
    const std::string line = FormatCandumpLine(t, "can0", f);
    ASSERT_EQ(line.substr(line.find(" can0 ") + 6), ToCanUtilsString(f));
    ASSERT_TRUE(writer.Write(written.back()));
  }
  CandumpReader reader(log);
  CandumpRecord r;
  for (const auto& w : written) {
    ASSERT_EQ(reader.Next(r), CandumpReader::Status::kRecord) << reader.error();
    ASSERT_EQ(r, w) << FormatCandumpLine(w.timestamp_ns, w.interface, w.frame);
  }
}

TEST(CandumpParseTest, AcceptsWhatOtherWritersProduce) {
  CandumpRecord r;
  std::string err;
  // python-can's CanutilsLogWriter: unpadded seconds, direction flag.
  ASSERT_EQ(ParseCandumpLine("(1700000000.123456) can0 123#11 R\n", 1, r, &err),
            CandumpLineStatus::kRecord)
      << err;
  EXPECT_EQ(r.timestamp_ns, 1'700'000'000'123'456'000LL);
  EXPECT_EQ(r.direction, 'R');
  // Fewer fraction digits, nanosecond precision (candump -N style), CRLF.
  ASSERT_EQ(ParseCandumpLine("(0.5) vcan0 123#\r\n", 2, r, &err), CandumpLineStatus::kRecord);
  EXPECT_EQ(r.timestamp_ns, 500'000'000);
  ASSERT_EQ(ParseCandumpLine("(12.000000001) vcan0 123#", 3, r, &err), CandumpLineStatus::kRecord);
  EXPECT_EQ(r.timestamp_ns, 12'000'000'001LL);
  // Lower-case hex, '.' separators, lower-case r, padded interface column, t flag.
  ASSERT_EQ(ParseCandumpLine("(1.000000)   can0 1ab#de.ad.be.ef t", 4, r, &err),
            CandumpLineStatus::kRecord)
      << err;
  EXPECT_EQ(r.frame, Classic(0x1AB, {0xDE, 0xAD, 0xBE, 0xEF}));
  EXPECT_EQ(r.interface, "can0");
  EXPECT_EQ(r.direction, 'T');
  ASSERT_EQ(ParseCandumpLine("(1.000000) can0 123#r", 5, r, &err), CandumpLineStatus::kRecord);
  EXPECT_TRUE(r.frame.rtr);
  // Raw DLC suffix of newer can-utils on an 8-byte classic frame.
  ASSERT_EQ(ParseCandumpLine("(1.0) can0 123#0011223344556677_C", 6, r, &err),
            CandumpLineStatus::kRecord)
      << err;
  EXPECT_EQ(r.frame.len, 8);
  // Comments and blank lines.
  EXPECT_EQ(ParseCandumpLine("", 7, r, &err), CandumpLineStatus::kSkipped);
  EXPECT_EQ(ParseCandumpLine("   \r\n", 8, r, &err), CandumpLineStatus::kSkipped);
  EXPECT_EQ(ParseCandumpLine("# a comment (1.0) can0 123#", 9, r, &err),
            CandumpLineStatus::kSkipped);
}

TEST(CandumpParseTest, RejectsMalformedLinesWithLineNumber) {
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"(1.0 can0 123#00", "closing ')'"},
      {"(.5) can0 123#00", "timestamp must be"},
      {"(1.) can0 123#00", "fraction is empty"},
      {"(1,5) can0 123#00", "lacks the '.'"},
      {"(1.0000000001) can0 123#00", "more than 9 digits"},
      {"(99999999999999999999.0) can0 123#00", "out of range"},
      {"(9223372036.0) can0 123#00", "out of range"},
      {"(1.0)", "missing interface"},
      {"(1.0) can0", "missing frame"},
      {"(1.0)can0 123#00", "missing interface"},
      {"(1.0) can0 123#00 X", "trailing field 'X'"},
      {"(1.0) can0 123#00 R junk", "after the direction flag"},
      {"(1.0) can0 12#00", "3 (standard) or 8 (extended)"},
      {"(1.0) can0 1234#00", "3 (standard) or 8 (extended)"},
      {"(1.0) can0 12G#00", "not hex"},
      {"(1.0) can0 800#00", "exceeds 0x7FF"},
      {"(1.0) can0 40000000#00", "exceeds 0x1FFFFFFF"},
      {"(1.0) can0 123", "no '#'"},
      {"(1.0) can0 123#0", "odd number"},
      {"(1.0) can0 123#0G", "not a hex digit"},
      {"(1.0) can0 123#001122334455667788", "more than 8 data bytes"},
      {"(1.0) can0 123#R9", "bad remote frame length"},
      {"(1.0) can0 123#R12", "bad remote frame length"},
      {"(1.0) can0 123##", "flags nibble"},
      {"(1.0) can0 123##0001122334455667788", "not a valid CAN FD length"},
      {"(1.0) can0 20000080#R", "error frames cannot be remote"},
      {"(1.0) can0 123#00_C", "bad raw DLC suffix"},
      {"(1.0) can0 123#0011223344556677_", "bad raw DLC suffix"},
  };
  for (const auto& [line, problem] : cases) {
    CandumpRecord r;
    std::string err;
    EXPECT_EQ(ParseCandumpLine(line, 17, r, &err), CandumpLineStatus::kError) << line;
    EXPECT_THAT(err, StartsWith("line 17: ")) << line;
    EXPECT_THAT(err, HasSubstr(problem)) << line;
  }
}

// Random truncations and byte mutations of valid lines: every outcome is a status, never a
// crash (the ASan/UBSan build runs this too).
TEST(CandumpParseTest, MutatedLinesNeverCrash) {
  std::mt19937 rng(1234);
  std::vector<std::string> lines;
  for (const auto& f : AllKinds())
    lines.push_back(FormatCandumpLine(9'223'372'035'999'999'999LL, "vcan0", f) + " R");
  int records = 0, errors = 0;
  for (int i = 0; i < 20000; ++i) {
    std::string l = lines[rng() % lines.size()];
    l.resize(rng() % (l.size() + 1));
    for (int k = rng() % 4; k > 0 && !l.empty(); --k) {
      l[rng() % l.size()] = "0123456789ABCDEFrR#._() \t\xff"[rng() % 27];
    }
    CandumpRecord r;
    std::string err;
    switch (ParseCandumpLine(l, 1, r, &err)) {
      case CandumpLineStatus::kRecord:
        ++records;
        EXPECT_TRUE(r.frame.IsValid()) << l;
        EXPECT_GE(r.timestamp_ns, 0) << l;
        break;
      case CandumpLineStatus::kError:
        ++errors;
        EXPECT_THAT(err, StartsWith("line 1: ")) << l;
        break;
      case CandumpLineStatus::kSkipped:
        break;
    }
  }
  EXPECT_GT(records, 100);
  EXPECT_GT(errors, 100);
}

TEST(CandumpReaderTest, StreamingGoesOnAfterBadLines) {
  std::istringstream in(
      "(1.000000) can0 123#01\n"
      "garbage without parenthesis is a comment\n"
      "(2.000000) can0 123#0\n"
      "(3.000000) can0 123#03\n");
  CandumpReader reader(in);
  CandumpRecord r;
  ASSERT_EQ(reader.Next(r), CandumpReader::Status::kRecord);
  EXPECT_EQ(reader.line_number(), 1u);
  ASSERT_EQ(reader.Next(r), CandumpReader::Status::kError);
  EXPECT_THAT(reader.error(), StartsWith("line 3: frame '123#0': odd number"));
  ASSERT_EQ(reader.Next(r), CandumpReader::Status::kRecord);
  EXPECT_EQ(r.frame.data[0], 0x03);
  EXPECT_EQ(reader.Next(r), CandumpReader::Status::kEnd);
}

TEST(CandumpReaderTest, LoadFileCollectsErrors) {
  const std::string path = ::testing::TempDir() + "/wheelhil_bus_codec_candump_bad.log";
  {
    std::ofstream out(path);
    out << "(1.000000) can0 123#01\n(2.000000) can0 800#\n(3.000000) can0 123#03\n";
  }
  const auto log = LoadCandumpFile(path);
  EXPECT_EQ(log.records.size(), 2u);
  ASSERT_EQ(log.errors.size(), 1u);
  EXPECT_THAT(log.errors[0], StartsWith(path + ":2: frame '800#'"));
  EXPECT_THROW(LoadCandumpFile("/nonexistent/x.log"), std::invalid_argument);
  EXPECT_THROW(CandumpWriter("/nonexistent/dir/x.log"), std::invalid_argument);
}

TEST(CandumpWriterTest, RefusesWhatCannotBeWritten) {
  std::stringstream out;
  CandumpWriter writer(out);
  CanFrame bad = Classic(0x123, {});
  bad.len = 9;
  EXPECT_FALSE(writer.Write(0, "can0", bad));
  EXPECT_FALSE(writer.Write(0, "", Classic(0x123, {})));
  EXPECT_FALSE(writer.Write(0, "can 0", Classic(0x123, {})));
  EXPECT_EQ(out.str(), "");
  EXPECT_EQ(writer.lines_written(), 0u);
}

// A log written by can-utils itself (asc2log 2020.11, see tests/data/candump/README.md).
TEST(CandumpGoldenTest, ReadsCanUtilsOutput) {
  const auto log = LoadCandumpFile(kDataDir + "/can_utils_asc2log.log");
  EXPECT_THAT(log.errors, ElementsAre());
  ASSERT_EQ(log.records.size(), 8u);
  std::vector<CanFrame> frames;
  for (const auto& r : log.records) frames.push_back(r.frame);
  CanFrame fd = Fd(0x181, 0x1, 8);
  const std::uint8_t tpdo[] = {0xE8, 0x03, 0, 0, 0xFA, 0, 0, 0};
  std::copy(std::begin(tpdo), std::end(tpdo), fd.data.begin());
  EXPECT_THAT(frames,
              ElementsAre(Classic(0x123, {0xDE, 0xAD, 0xBE, 0xEF}), Classic(0x12345678, {0}, true),
                          Rtr(0x7FF, 8), Classic(0, {}),
                          Classic(0x1FFFFFFF, {1, 0x23, 0x45, 0x67, 0x89, 0xAB, 0xCD, 0xEF}, true),
                          Error(0x80, {0, 0, 0, 0, 0, 0, 0, 0}), Classic(0x80, {}), fd));
  EXPECT_EQ(log.records[0].interface, "can0");
  EXPECT_EQ(log.records[2].interface, "can1");
  EXPECT_EQ(log.records[2].direction, 'T');
  EXPECT_EQ(log.records[0].direction, 'R');
  // Timestamp differences are those of the .asc file, to the microsecond.
  EXPECT_EQ(log.records[1].timestamp_ns - log.records[0].timestamp_ns, 10'000'000);
  EXPECT_EQ(log.records[6].timestamp_ns - log.records[0].timestamp_ns, 990'001'000);
}

TEST(CandumpGoldenTest, ReadsCandumpDashLWithTwoInterfaces) {
  const auto log = LoadCandumpFile(kDataDir + "/candump_L_two_interfaces.log");
  EXPECT_THAT(log.errors, ElementsAre());
  ASSERT_EQ(log.records.size(), 8u);
  EXPECT_EQ(log.records[0].interface, "vcan0");
  EXPECT_EQ(log.records[1].interface, "vcan10");
  EXPECT_EQ(log.records[0].timestamp_ns, 1'700'000'000'000'000'000LL);
  EXPECT_EQ(log.records[7].timestamp_ns, 1'700'000'001'999'999'000LL);
  EXPECT_EQ(log.records[3].frame, Rtr(0x7FF, 8));
  EXPECT_EQ(log.records[4].frame, Error(0x4, {0, 0, 8, 0, 0, 0, 0, 0}));
  EXPECT_EQ(log.records[5].frame, [] {
    CanFrame f = Fd(0x123, 1, 2);
    f.data[0] = 0xAA;
    f.data[1] = 0xBB;
    return f;
  }());
  EXPECT_EQ(log.records[7].frame, Fd(0x1ABCDEF0, 0, 12, true));
  // Our writer reproduces each line with the interface column unpadded.
  for (const auto& r : log.records) {
    const std::string line = FormatCandumpLine(r.timestamp_ns, r.interface, r.frame);
    CandumpRecord back;
    ASSERT_EQ(ParseCandumpLine(line, 1, back), CandumpLineStatus::kRecord) << line;
    EXPECT_EQ(back, r);
  }
}

// --- byte compatibility with independent readers -------------------------------------------

std::string WriteAllKindsLog(const std::string& name, bool fd_and_error) {
  const std::string path = ::testing::TempDir() + "/wheelhil_bus_codec_" + name;
  CandumpWriter writer(path);
  std::int64_t t = 1'700'000'000'000'000'000LL;
  int i = 0;
  for (const auto& f : AllKinds()) {
    if (!fd_and_error && (f.fd || f.error)) continue;
    t += 1'000'500;
    EXPECT_TRUE(writer.Write(t, i++ % 2 ? "can1" : "can0", f));
  }
  return path;
}

TEST(CandumpCompatTest, CanUtilsLog2AscReadsOurOutput) {
  if (std::system("command -v log2asc >/dev/null 2>&1") != 0) {
    GTEST_SKIP() << "can-utils log2asc not installed (./hil setup installs can-utils)";
  }
  const std::string path = WriteAllKindsLog("ours_for_log2asc.log", true);
  int status = 0;
  const std::string asc = test_support::CommandOutput("log2asc -I " + path + " can0 can1 2>&1", &status);
  ASSERT_EQ(status, 0) << asc;
  // One ASC line per frame (3 header lines; log2asc skips error frames in FD mode only).
  std::istringstream lines(asc);
  std::vector<std::string> body;
  for (std::string l; std::getline(lines, l);) {
    if (!l.empty() && l[0] == ' ') body.push_back(l);
  }
  ASSERT_EQ(body.size(), AllKinds().size()) << asc;
  EXPECT_THAT(body[0], HasSubstr("1  123             Rx   d 4 DE AD BE EF"));
  EXPECT_THAT(body[3], HasSubstr("2  12345678x       Rx   d 1 00"));
  EXPECT_THAT(body[7], HasSubstr("2  123             Rx   r 8"));
  EXPECT_THAT(body[9], HasSubstr("ErrorFrame"));
  EXPECT_THAT(body[12], HasSubstr("CANFD   1 Rx   1ABCDEF0x"));
  EXPECT_THAT(body[12], HasSubstr(" 1 1 9 12 00 01 02 03 04 05 06 07 08 09 0A 0B "));  // BRS ESI
  EXPECT_THAT(body[0], StartsWith("   0.000000 "));
  EXPECT_THAT(body[1], StartsWith("   0.001001 "));  // .0010005 s and .002001 s, truncated to us
}

TEST(CandumpCompatTest, PythonCanReadsOurOutput) {
  const std::string python = test_support::PythonWithCan();
  if (python.empty()) GTEST_SKIP() << "python3-can not installed (./hil setup installs it)";
  const std::string path = WriteAllKindsLog("ours_for_python_can.log", true);
  int status = 0;
  const std::string out = test_support::CommandOutput(
      python + " " + WHEELHIL_SOURCE_DIR + "/tests/bus/scripts/candump_python_can_read.py " + path,
      &status);
  ASSERT_EQ(status, 0) << out;
  const auto ours = LoadCandumpFile(path);
  ASSERT_TRUE(ours.errors.empty());
  std::istringstream lines(out);
  std::size_t i = 0;
  for (std::string l; std::getline(lines, l); ++i) {
    ASSERT_LT(i, ours.records.size());
    const auto& r = ours.records[i];
    std::istringstream fields(l);
    long long t_us = 0;
    std::string channel, id_hex, data;
    int ext, rtr, fd, brs, esi, err, dlc;
    fields >> t_us >> channel >> id_hex >> ext >> rtr >> fd >> brs >> esi >> err >> dlc >> data;
    ASSERT_FALSE(fields.fail()) << l;
    EXPECT_EQ(t_us, r.timestamp_ns / 1000) << l;
    EXPECT_EQ(channel, r.interface) << l;
    if (r.frame.error) {
      // python-can flags an error frame only when its class has CAN_ERR_BUSERROR (0x80);
      // other classes come back as plain extended frames. It keeps no id or data.
      EXPECT_EQ(err, (r.frame.id & 0x80) ? 1 : 0) << l;
      continue;
    }
    EXPECT_EQ(err, 0) << l;
    EXPECT_EQ(std::stoul(id_hex, nullptr, 16), r.frame.id) << l;
    EXPECT_EQ(ext, r.frame.extended ? 1 : 0) << l;
    EXPECT_EQ(rtr, r.frame.rtr ? 1 : 0) << l;
    EXPECT_EQ(fd, r.frame.fd ? 1 : 0) << l;
    EXPECT_EQ(brs, r.frame.fd_flags & 1) << l;
    EXPECT_EQ(esi, (r.frame.fd_flags >> 1) & 1) << l;
    EXPECT_EQ(dlc, r.frame.len) << l;
    std::string hex;
    for (auto b : r.frame.payload()) {
      char buf[3];
      std::snprintf(buf, sizeof buf, "%02X", b);
      hex += buf;
    }
    if (!r.frame.rtr) {
      EXPECT_EQ(data, hex.empty() ? "-" : hex) << l;
    }
  }
  EXPECT_EQ(i, ours.records.size());
}

}  // namespace
}  // namespace wheelhil::bus
