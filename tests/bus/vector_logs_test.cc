// ASC and BLF logs (bus/vector_logs.h): every kind of frame (classic, extended, remote, FD
// with BRS/ESI, error, sent and received, two interfaces) survives candump -> ASC/BLF ->
// records; python-can's ASCReader and BLFReader (an independent implementation) read the same
// frames, ids, flags, data and timestamps from our files; a file we cannot read is named with
// the line (ASC) or byte (BLF) of the problem.
#include "bus/vector_logs.h"
#include "tests/command_output.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace wheelhil::bus {
namespace {

std::vector<CandumpRecord> AllKinds(std::int64_t t0) {
  std::vector<CanFrame> frames;
  frames.push_back(CanFrame::Classic(0x123, std::vector<std::uint8_t>{0xDE, 0xAD, 0xBE, 0xEF}));
  frames.push_back(CanFrame::Classic(0x1ABCDEF0, std::vector<std::uint8_t>{0x00}, true));
  frames.push_back(CanFrame::Classic(0x7FF, std::vector<std::uint8_t>{}));
  CanFrame rtr;
  rtr.id = 0x321;
  rtr.rtr = true;
  rtr.len = 4;
  frames.push_back(rtr);
  CanFrame fd;
  fd.id = 0x456;
  fd.fd = true;
  fd.fd_flags = 0x01;  // BRS
  fd.len = 12;
  for (int i = 0; i < 12; ++i) fd.data[i] = static_cast<std::uint8_t>(i * 17);
  frames.push_back(fd);
  CanFrame fd_ext = fd;
  fd_ext.id = 0x12345;
  fd_ext.extended = true;
  fd_ext.fd_flags = 0x03;  // BRS, ESI
  fd_ext.len = 64;
  for (int i = 0; i < 64; ++i) fd_ext.data[i] = static_cast<std::uint8_t>(255 - i);
  frames.push_back(fd_ext);
  CanFrame fd_empty;
  fd_empty.id = 0x10;
  fd_empty.fd = true;
  frames.push_back(fd_empty);
  CanFrame err;
  err.error = true;
  err.id = 0x080;  // CAN_ERR_BUSERROR
  err.len = 8;
  err.data[2] = 0x10;
  frames.push_back(err);
  std::vector<CandumpRecord> out;
  std::int64_t t = t0;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    t += 1'234'000 * static_cast<std::int64_t>(i + 1);  // whole microseconds
    CandumpRecord r;
    r.timestamp_ns = t;
    r.interface = i % 3 == 2 ? "ucan1" : "ucan0";
    r.frame = frames[i];
    r.direction = i % 2 ? 'T' : 'R';
    out.push_back(r);
  }
  return out;
}

std::string TempPath(const std::string& name) {
  return ::testing::TempDir() + "/vector_logs_" + name;
}

// What a format keeps: ASC's ErrorFrame line has no class bits and no data.
CandumpRecord AsKept(CandumpRecord r, CanLogFormat format) {
  if (r.direction == 0) r.direction = 'R';
  if (format == CanLogFormat::kAsc && r.frame.error) {
    r.frame.data = {};
    r.frame.id = 0x080;
  }
  return r;
}

class VectorLogs : public ::testing::TestWithParam<CanLogFormat> {};

TEST_P(VectorLogs, EveryKindOfFrameRoundTrips) {
  for (const std::int64_t t0 : {std::int64_t{0}, std::int64_t{1'700'000'000'123'000'000}}) {
    const auto records = AllKinds(t0);
    const std::string path = TempPath(GetParam() == CanLogFormat::kAsc ? "rt.asc" : "rt.blf");
    WriteCanLog(path, GetParam(), records);
    const auto back = ReadCanLog(path, GetParam());
    ASSERT_EQ(back.size(), records.size()) << "t0 " << t0;
    for (std::size_t i = 0; i < records.size(); ++i) {
      const CandumpRecord want = AsKept(records[i], GetParam());
      EXPECT_EQ(back[i].timestamp_ns, want.timestamp_ns) << i;
      EXPECT_EQ(back[i].interface, want.interface) << i;
      EXPECT_EQ(back[i].direction, want.frame.error ? back[i].direction : want.direction) << i;
      EXPECT_TRUE(back[i].frame == want.frame)
          << i << ": " << ToCanUtilsString(back[i].frame) << " vs " << ToCanUtilsString(want.frame);
    }
  }
}

TEST_P(VectorLogs, PythonCanReadsOurFiles) {
  const std::string python = test_support::PythonWithCan();
  if (python.empty()) GTEST_SKIP() << "python3-can not installed (./hil setup installs it)";
  const bool asc = GetParam() == CanLogFormat::kAsc;
  const std::int64_t t0 = 1'700'000'000'123'000'000LL;
  const auto records = AllKinds(t0);
  const std::string path = TempPath(asc ? "py.asc" : "py.blf");
  WriteCanLog(path, GetParam(), records);
  int status = 0;
  const std::string out = test_support::CommandOutput("TZ=UTC " + python + " " + WHEELHIL_SOURCE_DIR +
                                            "/tests/bus/scripts/vector_python_can_read.py " +
                                            (asc ? "asc " : "blf ") + path + " 2>&1", &status);
  ASSERT_EQ(status, 0) << out;
  std::istringstream lines(out);
  std::size_t i = 0;
  // The file's start: the first record's instant cut to the millisecond.
  const std::int64_t start_us = records.front().timestamp_ns / 1'000'000 * 1000;
  for (std::string l; std::getline(lines, l); ++i) {
    ASSERT_LT(i, records.size()) << out;
    const CandumpRecord& r = records[i];
    std::istringstream fields(l);
    long long t_us = 0;
    int channel = 0, ext = 0, rtr = 0, fd = 0, brs = 0, esi = 0, err = 0, tx = 0, dlc = 0;
    std::string id_hex, data;
    fields >> t_us >> channel >> id_hex >> ext >> rtr >> fd >> brs >> esi >> err >> tx >> dlc >>
        data;
    ASSERT_FALSE(fields.fail()) << l;
    EXPECT_EQ(t_us, asc ? r.timestamp_ns / 1000 - start_us : r.timestamp_ns / 1000) << l;
    EXPECT_EQ(channel, r.interface == "ucan0" ? 0 : 1) << l;
    EXPECT_EQ(err, r.frame.error ? 1 : 0) << l;
    if (r.frame.error) continue;
    EXPECT_EQ(std::stoul(id_hex, nullptr, 16), r.frame.id) << l;
    EXPECT_EQ(ext, r.frame.extended ? 1 : 0) << l;
    // python-can 4.1's ASCReader takes a CANFD line without data for a remote frame (CAN FD
    // has none); its BLFReader does not.
    const bool empty_fd_in_asc = asc && r.frame.fd && r.frame.len == 0;
    EXPECT_EQ(rtr, r.frame.rtr || empty_fd_in_asc ? 1 : 0) << l;
    EXPECT_EQ(fd, r.frame.fd ? 1 : 0) << l;
    EXPECT_EQ(brs, r.frame.fd_flags & 1) << l;
    EXPECT_EQ(esi, (r.frame.fd_flags >> 1) & 1) << l;
    EXPECT_EQ(tx, r.direction == 'T' ? 1 : 0) << l;
    EXPECT_EQ(dlc, r.frame.len) << l;
    std::string hex;
    for (auto b : r.frame.payload()) {
      char buf[3];
      std::snprintf(buf, sizeof buf, "%02X", b);
      hex += buf;
    }
    if (!r.frame.rtr && !empty_fd_in_asc) {
      EXPECT_EQ(data, hex.empty() ? "-" : hex) << l;
    }
  }
  EXPECT_EQ(i, records.size()) << out;
}

INSTANTIATE_TEST_SUITE_P(Formats, VectorLogs,
                         ::testing::Values(CanLogFormat::kAsc, CanLogFormat::kBlf),
                         [](const auto& info) {
                           return info.param == CanLogFormat::kAsc ? "Asc" : "Blf";
                         });

// An ASC written by another tool (tests/data/candump/can_utils_input.asc, beside what can-utils'
// asc2log made of it): the same frames, channels and spacing in time.
TEST(VectorLogsAsc, ReadsWhatCanUtilsAsc2LogReads) {
  const std::string dir = std::string(WHEELHIL_SOURCE_DIR) + "/tests/data/candump/";
  const auto ours = ReadCanLog(dir + "can_utils_input.asc", CanLogFormat::kAsc);
  const CandumpLog theirs = LoadCandumpFile(dir + "can_utils_asc2log.log");
  ASSERT_TRUE(theirs.errors.empty());
  ASSERT_EQ(ours.size(), theirs.records.size());
  for (std::size_t i = 0; i < ours.size(); ++i) {
    const CandumpRecord& t = theirs.records[i];
    EXPECT_EQ(ours[i].interface, t.interface) << i;
    EXPECT_EQ(ours[i].direction, t.direction) << i;
    EXPECT_EQ(ours[i].timestamp_ns - ours[0].timestamp_ns,
              t.timestamp_ns - theirs.records[0].timestamp_ns)
        << i;
    if (!t.frame.error) {  // asc2log gives its ErrorFrame class bits of its own
      EXPECT_TRUE(ours[i].frame == t.frame)
          << i << ": " << ToCanUtilsString(ours[i].frame) << " vs " << ToCanUtilsString(t.frame);
    }
    EXPECT_EQ(ours[i].frame.error, t.frame.error) << i;
  }
}

// A BLF file of one uncompressed container holding `objects` (as a reader meets third-party
// files: nothing of FormatBlf's).
std::string BlfWith(const std::string& objects) {
  auto put = [](std::string& b, auto v) { b.append(reinterpret_cast<const char*>(&v), sizeof v); };
  std::string file = "LOGG";
  put(file, std::uint32_t{144});
  file.resize(144, '\0');
  file += "LOBJ";
  put(file, std::uint16_t{16});
  put(file, std::uint16_t{1});
  put(file, static_cast<std::uint32_t>(32 + objects.size()));
  put(file, std::uint32_t{10});  // LOG_CONTAINER
  put(file, std::uint16_t{0});   // no compression
  file.append(6, '\0');
  put(file, static_cast<std::uint32_t>(objects.size()));
  file.append(4, '\0');
  return file + objects;
}

// One object with a v1 header: its type, time flags (1: 10 us units, 2: ns), time and data.
std::string BlfObject(std::uint32_t type, std::uint32_t time_flags, std::uint64_t t,
                      const std::string& data) {
  auto put = [](std::string& b, auto v) { b.append(reinterpret_cast<const char*>(&v), sizeof v); };
  std::string o = "LOBJ";
  put(o, std::uint16_t{32});
  put(o, std::uint16_t{1});
  put(o, static_cast<std::uint32_t>(32 + data.size()));
  put(o, type);
  put(o, time_flags);
  put(o, std::uint32_t{0});
  put(o, t);
  return o + data;
}

// CAN_FD_MESSAGE_64, which CANoe writes for CAN FD and FormatBlf does not: read as python-can
// reads it (flags EDL/BRS/ESI, the direction byte, the data after the 40-byte head), its time
// in 10 us units.
TEST(VectorLogsBlf, CanFdMessage64IsRead) {
  auto put = [](std::string& b, auto v) { b.append(reinterpret_cast<const char*>(&v), sizeof v); };
  std::string d;
  for (std::uint8_t v : {2, 9, 12, 0}) put(d, v);  // channel 2, DLC 9, 12 bytes, tx count
  put(d, std::uint32_t{0x80012345});               // extended id
  put(d, std::uint32_t{0});                        // frame length
  put(d, std::uint32_t{0x1000 | 0x2000});          // EDL, BRS
  d.append(16, '\0');                              // bit timing
  put(d, std::uint16_t{0});                        // bit count
  put(d, std::uint8_t{1});                         // dir: Tx
  put(d, std::uint8_t{0});
  put(d, std::uint32_t{0});  // crc
  for (int i = 0; i < 12; ++i) d.push_back(static_cast<char>(0xA0 + i));
  const auto records =
      ParseCanLog(BlfWith(BlfObject(101, 1, 250, d)), CanLogFormat::kBlf, "third.blf");
  ASSERT_EQ(records.size(), 1u);
  const CandumpRecord& r = records[0];
  EXPECT_EQ(r.timestamp_ns, 2'500'000);  // 250 x 10 us
  EXPECT_EQ(r.interface, "can1");
  EXPECT_EQ(r.direction, 'T');
  EXPECT_TRUE(r.frame.fd);
  EXPECT_TRUE(r.frame.extended);
  EXPECT_EQ(r.frame.id, 0x12345u);
  EXPECT_EQ(r.frame.fd_flags, 0x01);
  ASSERT_EQ(r.frame.len, 12);
  EXPECT_EQ(r.frame.data[11], 0xAB);
}

// What a hostile or broken BLF file gets: a message naming where, never a hang, an outsized
// allocation or an overflowing time.
TEST(VectorLogsBlf, BrokenFilesAreNamedWithWhere) {
  auto error_of = [](const std::string& bytes) {
    try {
      (void)ParseCanLog(bytes, CanLogFormat::kBlf, "x.blf");
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("read");
  };
  std::string empty_object = BlfWith("");
  empty_object.replace(144 + 4, 2, std::string(2, '\0'));  // header size 0
  empty_object.replace(144 + 8, 4, std::string(4, '\0'));  // object size 0: no progress
  EXPECT_EQ(error_of(empty_object), "x.blf: byte 144: an object runs past the end");
  std::string huge = BlfWith("");
  huge.replace(144 + 16, 2, std::string("\x02\x00", 2));          // zlib
  huge.replace(144 + 24, 4, std::string("\x00\x00\x00\xC0", 4));  // 3 GiB inflated
  EXPECT_EQ(error_of(huge),
            "x.blf: byte 144: a container of 3072 MiB inflated, more than the 64 MiB a reader "
            "takes");
  std::string classic(16, '\0');
  classic[0] = 1;                                             // channel 1
  classic[3] = 1;                                             // DLC 1
  classic.replace(4, 4, std::string("\x00\x08\x00\x00", 4));  // id 0x800, not extended
  EXPECT_EQ(error_of(BlfWith(BlfObject(1, 2, 0, classic))),
            "x.blf: frame 1 (id 800) is not a valid CAN frame");
  classic.replace(4, 4, std::string("\x23\x01\x00\x00", 4));
  EXPECT_THAT(error_of(BlfWith(BlfObject(1, 1, ~std::uint64_t{0} / 2, classic))),
              ::testing::HasSubstr("is more than 31 years from the start"));
}

TEST(VectorLogsErrors, AFileThatCannotBeReadIsNamedWithWhere) {
  const auto records = AllKinds(0);
  const std::string asc = TempPath("bad.asc");
  std::string text = FormatAsc(records);
  const std::size_t at = text.find(" DE AD");
  ASSERT_NE(at, std::string::npos);
  text.replace(at, 6, " DE ZZ");
  std::ofstream(asc) << text;
  try {
    (void)ReadCanLog(asc, CanLogFormat::kAsc);
    FAIL() << "a bad data byte was read";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(asc + ":9: a bad data byte"), std::string::npos)
        << e.what();
  }
  const std::string blf = TempPath("bad.blf");
  const std::string bytes = FormatBlf(records);
  std::ofstream(blf, std::ios::binary) << bytes.substr(0, bytes.size() - 10);
  try {
    (void)ReadCanLog(blf, CanLogFormat::kBlf);
    FAIL() << "a cut file was read";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(blf + ": byte 144: an object runs past the end"),
              std::string::npos)
        << e.what();
  }
  // A frame no controller could send, a time beyond int64 nanoseconds.
  text = FormatAsc(records);
  const std::size_t id = text.find(" 123 ");
  ASSERT_NE(id, std::string::npos);
  text.replace(id, 5, " 923 ");
  std::ofstream(asc) << text;
  EXPECT_THROW(
      {
        try {
          (void)ReadCanLog(asc, CanLogFormat::kAsc);
        } catch (const std::invalid_argument& e) {
          EXPECT_NE(std::string(e.what()).find(asc + ":9: not a valid CAN frame (its id)"),
                    std::string::npos)
              << e.what();
          throw;
        }
      },
      std::invalid_argument);
  text = FormatAsc(records);
  const std::size_t t = text.find("   0.000234 ");  // the first frame
  ASSERT_NE(t, std::string::npos) << text;
  text.replace(t, 12, " 99999999999999999999.000001 ");
  std::ofstream(asc) << text;
  EXPECT_THROW(
      {
        try {
          (void)ReadCanLog(asc, CanLogFormat::kAsc);
        } catch (const std::invalid_argument& e) {
          EXPECT_NE(std::string(e.what()).find(asc + ":9: a time that is not seconds"),
                    std::string::npos)
              << e.what();
          throw;
        }
      },
      std::invalid_argument);
  EXPECT_THROW((void)CanLogFormatOf("run.trc"), std::invalid_argument);
  EXPECT_EQ(CanLogFormatOf("RUN.BLF"), CanLogFormat::kBlf);
}

}  // namespace
}  // namespace wheelhil::bus
