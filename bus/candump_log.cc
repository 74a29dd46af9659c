#include "bus/candump_log.h"

#include <fmt/format.h>

#include <algorithm>
#include <istream>
#include <ostream>
#include <stdexcept>

#include "bus/internal/hex.h"

namespace wheelhil::bus {
namespace {

constexpr std::uint32_t kCanErrFlag = 0x20000000;  // CAN_ERR_FLAG in linux/can.h
// Largest whole second whose nanosecond count (plus a fraction) fits an int64 (year 2262).
constexpr std::int64_t kMaxSeconds = 9'223'372'035LL;

using internal::HexValue;

bool IsSpace(char c) noexcept { return c == ' ' || c == '\t'; }

bool Fail(std::string* error, std::string message) {
  if (error) *error = std::move(message);
  return false;
}

// Reads hex byte pairs (optionally separated by '.') into out.data; stops at end or at '_'.
bool ParseData(std::string_view s, std::size_t& i, std::size_t max_len, CanFrame& out,
               std::string* error) {
  std::size_t n = 0;
  while (i < s.size() && s[i] != '_') {
    if (s[i] == '.') {
      ++i;
      continue;
    }
    const int hi = HexValue(s[i]);
    if (hi < 0) return Fail(error, fmt::format("'{}' is not a hex digit in data", s[i]));
    if (i + 1 >= s.size()) return Fail(error, "odd number of hex digits in data");
    const int lo = HexValue(s[i + 1]);
    if (lo < 0) return Fail(error, fmt::format("'{}' is not a hex digit in data", s[i + 1]));
    if (n >= max_len) {
      return Fail(error, fmt::format("more than {} data bytes", max_len));
    }
    out.data[n++] = static_cast<std::uint8_t>(hi << 4 | lo);
    i += 2;
  }
  out.len = static_cast<std::uint8_t>(n);
  return true;
}

}  // namespace

bool ParseCanUtilsFrame(std::string_view s, CanFrame& out, std::string* error) {
  out = CanFrame{};
  const std::size_t hash = s.find('#');
  if (hash == std::string_view::npos) return Fail(error, "frame has no '#'");
  if (hash != 3 && hash != 8) {
    return Fail(error, fmt::format("CAN id '{}' must have 3 (standard) or 8 (extended) hex digits",
                                   s.substr(0, hash)));
  }
  std::uint32_t id = 0;
  for (std::size_t i = 0; i < hash; ++i) {
    const int v = HexValue(s[i]);
    if (v < 0) return Fail(error, fmt::format("CAN id '{}' is not hex", s.substr(0, hash)));
    id = id << 4 | static_cast<std::uint32_t>(v);
  }
  if (hash == 3) {
    if (id > CanFrame::kMaxStandardId) {
      return Fail(error, fmt::format("standard CAN id 0x{:03X} exceeds 0x7FF", id));
    }
  } else if (id & kCanErrFlag) {
    out.error = true;
    id &= CanFrame::kMaxExtendedId;  // error class bits
  } else {
    if (id > CanFrame::kMaxExtendedId) {
      return Fail(error, fmt::format("extended CAN id 0x{:08X} exceeds 0x1FFFFFFF", id));
    }
    out.extended = true;
  }
  out.id = id;

  std::size_t i = hash + 1;
  if (i < s.size() && (s[i] == 'R' || s[i] == 'r')) {
    if (out.error) return Fail(error, "error frames cannot be remote frames");
    out.rtr = true;
    ++i;
    if (i < s.size()) {
      const int dlc = HexValue(s[i]);
      if (dlc < 0 || dlc > 8 || i + 1 != s.size()) {
        return Fail(error, fmt::format("bad remote frame length '{}'", s.substr(i)));
      }
      out.len = static_cast<std::uint8_t>(dlc);
    }
    return true;
  }
  if (i < s.size() && s[i] == '#') {
    if (out.error) return Fail(error, "error frames cannot be CAN FD frames");
    out.fd = true;
    ++i;
    const int flags = i < s.size() ? HexValue(s[i]) : -1;
    if (flags < 0) return Fail(error, "CAN FD frame lacks its flags nibble after '##'");
    out.fd_flags = static_cast<std::uint8_t>(flags);
    ++i;
    if (i < s.size() && s[i] == '.') ++i;
    if (!ParseData(s, i, CanFrame::kMaxFdLen, out, error)) return false;
    if (i != s.size()) return Fail(error, "unexpected '_' in a CAN FD frame");
    if (!IsValidFdLength(out.len)) {
      return Fail(error, fmt::format("{} bytes is not a valid CAN FD length", out.len));
    }
    return true;
  }
  if (!ParseData(s, i, CanFrame::kMaxClassicLen, out, error)) return false;
  if (i < s.size()) {
    // `_<dlc>`: raw DLC 9..F of an 8-byte classic frame (can-utils >= 2021). Dropped.
    const int dlc = i + 2 == s.size() ? HexValue(s[i + 1]) : -1;
    if (out.len != 8 || dlc < 9) {
      return Fail(error, fmt::format("bad raw DLC suffix '{}'", s.substr(i)));
    }
  }
  return true;
}

CandumpLineStatus ParseCandumpLine(std::string_view line, std::size_t line_number,
                                   CandumpRecord& out, std::string* error) {
  auto fail = [&](std::string_view problem) {
    if (error) *error = fmt::format("line {}: {}", line_number, problem);
    return CandumpLineStatus::kError;
  };
  while (!line.empty() && (line.back() == '\n' || line.back() == '\r' || IsSpace(line.back()))) {
    line.remove_suffix(1);
  }
  std::size_t i = 0;
  while (i < line.size() && IsSpace(line[i])) ++i;
  if (i == line.size() || line[i] != '(') return CandumpLineStatus::kSkipped;
  ++i;

  // Timestamp: digits '.' 1..9 digits ')'; integer arithmetic only.
  std::int64_t seconds = 0;
  std::size_t digits = 0;
  for (; i < line.size() && line[i] >= '0' && line[i] <= '9'; ++i, ++digits) {
    if (seconds > kMaxSeconds) break;  // reported below; stops before any overflow
    seconds = seconds * 10 + (line[i] - '0');
  }
  if (digits == 0) return fail("timestamp must be '(<seconds>.<fraction>)'");
  if (seconds > kMaxSeconds) return fail("timestamp seconds out of range (int64 nanoseconds)");
  if (i >= line.size() || line[i] != '.')
    return fail("timestamp lacks the '.' before the fraction");
  ++i;
  std::int64_t fraction_ns = 0;
  digits = 0;
  for (; i < line.size() && line[i] >= '0' && line[i] <= '9'; ++i, ++digits) {
    if (digits == 9) return fail("timestamp fraction has more than 9 digits");
    fraction_ns = fraction_ns * 10 + (line[i] - '0');
  }
  if (digits == 0) return fail("timestamp fraction is empty");
  for (std::size_t d = digits; d < 9; ++d) fraction_ns *= 10;
  if (i >= line.size() || line[i] != ')') return fail("timestamp lacks its closing ')'");
  ++i;

  auto next_field = [&](std::string_view& field) {
    const std::size_t start = i;
    while (i < line.size() && IsSpace(line[i])) ++i;
    if (i == start && i < line.size()) return false;  // fields need separating whitespace
    const std::size_t begin = i;
    while (i < line.size() && !IsSpace(line[i])) ++i;
    field = line.substr(begin, i - begin);
    return !field.empty();
  };
  std::string_view iface, frame_text, flag;
  if (!next_field(iface)) return fail("missing interface name after the timestamp");
  if (!next_field(frame_text)) return fail("missing frame after the interface name");
  if (next_field(flag)) {
    if (flag.size() != 1 ||
        (flag[0] != 'R' && flag[0] != 'T' && flag[0] != 'r' && flag[0] != 't')) {
      return fail(fmt::format("unexpected trailing field '{}' (only R or T allowed)", flag));
    }
    if (i != line.size()) return fail("unexpected text after the direction flag");
  }

  std::string frame_error;
  if (!ParseCanUtilsFrame(frame_text, out.frame, &frame_error)) {
    return fail(fmt::format("frame '{}': {}", frame_text, frame_error));
  }
  out.timestamp_ns = seconds * 1'000'000'000LL + fraction_ns;
  out.interface.assign(iface);
  out.direction = flag.empty() ? 0 : static_cast<char>(flag[0] & ~0x20);  // upper case
  return CandumpLineStatus::kRecord;
}

std::size_t FormatCandumpLine(std::int64_t timestamp_ns, std::string_view interface,
                              const CanFrame& f, char* buf, std::size_t capacity) noexcept {
  static constexpr char kHex[] = "0123456789ABCDEF";
  if (capacity < MaxCandumpLineLength(interface.size())) return 0;
  if (timestamp_ns < 0) timestamp_ns = 0;
  const auto ns = static_cast<std::uint64_t>(timestamp_ns);
  std::uint64_t sec = ns / 1'000'000'000ULL;
  std::uint64_t usec = (ns % 1'000'000'000ULL) / 1000ULL;
  // candump.c: "(%010llu.%06llu) %*s %s%s\n"; seconds < 1e10 up to the year 2286, 20 digits max.
  char digits[20];
  int nd = 0;
  do {
    digits[nd++] = static_cast<char>('0' + sec % 10);
    sec /= 10;
  } while (sec != 0);
  char* p = buf;
  *p++ = '(';
  for (int pad = nd; pad < 10; ++pad) *p++ = '0';
  while (nd > 0) *p++ = digits[--nd];
  *p++ = '.';
  for (int k = 5; k >= 0; --k) {
    p[k] = static_cast<char>('0' + usec % 10);
    usec /= 10;
  }
  p += 6;
  *p++ = ')';
  *p++ = ' ';
  for (char c : interface) *p++ = c;
  *p++ = ' ';
  // lib.c sprint_canframe (bus::ToCanUtilsString writes the same text).
  auto put_id = [&p](std::uint32_t id, int n) {
    for (int k = n - 1; k >= 0; --k) *p++ = kHex[(id >> (4 * k)) & 0xF];
  };
  if (f.error) {
    put_id((f.id & CanFrame::kMaxExtendedId) | kCanErrFlag, 8);
  } else if (f.extended) {
    put_id(f.id, 8);
  } else {
    put_id(f.id, 3);
  }
  *p++ = '#';
  if (f.rtr) {
    *p++ = 'R';
    if (f.len > 0 && f.len <= CanFrame::kMaxClassicLen) *p++ = static_cast<char>('0' + f.len);
    return static_cast<std::size_t>(p - buf);
  }
  if (f.fd) {
    *p++ = '#';
    *p++ = kHex[f.fd_flags & 0x0F];
  }
  const std::size_t len = std::min<std::size_t>(f.len, CanFrame::kMaxFdLen);
  for (std::size_t i = 0; i < len; ++i) {
    *p++ = kHex[f.data[i] >> 4];
    *p++ = kHex[f.data[i] & 0x0F];
  }
  return static_cast<std::size_t>(p - buf);
}

std::string FormatCandumpLine(std::int64_t timestamp_ns, std::string_view interface,
                              const CanFrame& frame) {
  std::string line(MaxCandumpLineLength(interface.size()), '\0');
  line.resize(FormatCandumpLine(timestamp_ns, interface, frame, line.data(), line.size()));
  return line;
}

CandumpWriter::CandumpWriter(std::ostream& out, FlushPolicy policy) : out_(&out), policy_(policy) {}

CandumpWriter::CandumpWriter(const std::string& path, FlushPolicy policy)
    : file_(path, std::ios::out | std::ios::trunc), out_(&file_), policy_(policy) {
  if (!file_) {
    throw std::invalid_argument(fmt::format("{}: cannot open candump log for writing", path));
  }
}

CandumpWriter::~CandumpWriter() {
  if (file_.is_open()) file_.flush();
}

bool CandumpWriter::Write(std::int64_t timestamp_ns, std::string_view interface,
                          const CanFrame& frame) {
  if (!frame.IsValid() || interface.empty()) return false;
  for (char c : interface) {
    if (IsSpace(c) || c == '\n' || c == '\r') return false;
  }
  if (interface.size() > 64) return false;
  char line[MaxCandumpLineLength(64) + 1];
  std::size_t n = FormatCandumpLine(timestamp_ns, interface, frame, line, sizeof line);
  line[n++] = '\n';
  out_->write(line, static_cast<std::streamsize>(n));
  if (policy_ == FlushPolicy::kEveryLine) out_->flush();
  if (!*out_) return false;
  ++lines_written_;
  return true;
}

bool CandumpWriter::Flush() {
  out_->flush();
  return static_cast<bool>(*out_);
}

CandumpReader::Status CandumpReader::Next(CandumpRecord& out) {
  while (std::getline(*in_, line_)) {
    ++line_number_;
    switch (ParseCandumpLine(line_, line_number_, out, &error_)) {
      case CandumpLineStatus::kRecord:
        return Status::kRecord;
      case CandumpLineStatus::kError:
        return Status::kError;
      case CandumpLineStatus::kSkipped:
        break;
    }
  }
  return Status::kEnd;
}

CandumpLog LoadCandumpFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::invalid_argument(fmt::format("{}: cannot open candump log", path));
  CandumpLog log;
  CandumpReader reader(in);
  CandumpRecord record;
  for (;;) {
    const auto status = reader.Next(record);
    if (status == CandumpReader::Status::kEnd) break;
    if (status == CandumpReader::Status::kRecord) {
      log.records.push_back(record);
    } else {
      const std::string& msg = reader.error();  // "line N: problem"
      const std::size_t colon = msg.find(": ");
      log.errors.push_back(fmt::format("{}:{}: {}", path, reader.line_number(),
                                       colon == std::string::npos ? msg : msg.substr(colon + 2)));
    }
  }
  return log;
}

}  // namespace wheelhil::bus
