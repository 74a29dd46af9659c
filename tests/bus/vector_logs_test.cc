// ASC and BLF logs (bus/vector_logs.h): every kind of frame (classic, extended, remote, FD
// with BRS/ESI, error, sent and received, two interfaces) survives candump -> ASC/BLF ->
// records; python-can's ASCReader and BLFReader (an independent implementation) read the same
// frames, ids, flags, data and timestamps from our files; a file we cannot read is named with
// the line (ASC) or byte (BLF) of the problem.
#include "bus/vector_logs.h"

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

std::string Python() {
  for (const char* py : {"/usr/bin/python3", "python3"}) {
    if (std::system((std::string(py) + " -c 'import can' >/dev/null 2>&1").c_str()) == 0) {
      return py;
    }
  }
  return "";
}

std::string RunAndCapture(const std::string& cmd, int& status) {
  std::string out;
  FILE* p = ::popen(cmd.c_str(), "r");
  if (p == nullptr) {
    status = -1;
    return out;
  }
  char buf[4096];
  while (std::size_t n = std::fread(buf, 1, sizeof buf, p)) out.append(buf, n);
  status = ::pclose(p);
  return out;
}

TEST_P(VectorLogs, PythonCanReadsOurFiles) {
  const std::string python = Python();
  if (python.empty()) GTEST_SKIP() << "python3-can not installed (./hil setup installs it)";
  const bool asc = GetParam() == CanLogFormat::kAsc;
  const std::int64_t t0 = 1'700'000'000'123'000'000LL;
  const auto records = AllKinds(t0);
  const std::string path = TempPath(asc ? "py.asc" : "py.blf");
  WriteCanLog(path, GetParam(), records);
  int status = 0;
  const std::string out = RunAndCapture("TZ=UTC " + python + " " + WHEELHIL_SOURCE_DIR +
                                            "/tests/bus/scripts/vector_python_can_read.py " +
                                            (asc ? "asc " : "blf ") + path + " 2>&1",
                                        status);
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
  EXPECT_THROW((void)CanLogFormatOf("run.trc"), std::invalid_argument);
  EXPECT_EQ(CanLogFormatOf("RUN.BLF"), CanLogFormat::kBlf);
}

}  // namespace
}  // namespace wheelhil::bus
