#include "bus/vector_logs.h"

#include <zlib.h>

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cstring>
#include <ctime>
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string_view>

#include "bus/internal/hex.h"
#include "bus/internal/input_file.h"

namespace wheelhil::bus {
namespace {

constexpr std::int64_t kNsPerMs = 1'000'000;
constexpr std::int64_t kNsPerS = 1'000'000'000;
constexpr std::uint32_t kCanErrBusError = 0x080;  // CAN_ERR_BUSERROR in linux/can/error.h
// Before 1990 a start is not a date (a run's own time from 0): the files then say so (BLF: a
// zero SYSTEMTIME, as python-can writes one).
constexpr std::int64_t kFirstDateNs = 631152000LL * kNsPerS;
// What a reader takes, so that every start plus every time since it fits int64 nanoseconds
// (year 2262): a start up to the end of 2199, times since it up to about 31 years.
constexpr int kLastYear = 2199;
constexpr std::int64_t kMaxSinceStartNs = 1'000'000'000LL * kNsPerS;
constexpr std::int64_t kEndOfLastYearNs = 7'258'118'400LL * kNsPerS;  // 2200-01-01T00:00:00Z
// A log read whole, and a BLF container inflated (python-can writes 128 KiB ones).
constexpr std::size_t kMaxLogBytes = std::size_t{2} << 30;
constexpr std::uint32_t kMaxContainerInflated = 64u << 20;

// ---- channels ----

// Interfaces numbered from 1 in the order first seen.
class ChannelNumbers {
 public:
  int Of(const std::string& name) {
    const auto it = numbers_.find(name);
    if (it != numbers_.end()) return it->second;
    names_.push_back(name);
    return numbers_[name] = static_cast<int>(names_.size());
  }
  const std::vector<std::string>& names() const { return names_; }

 private:
  std::map<std::string, int> numbers_;
  std::vector<std::string> names_;
};

// The file's start: the first record's instant cut to the millisecond.
std::int64_t StartOf(const std::vector<CandumpRecord>& records) {
  if (records.empty() || records.front().timestamp_ns < 0) return 0;
  return records.front().timestamp_ns / kNsPerMs * kNsPerMs;
}

std::string ChannelName(const std::map<int, std::string>& names, int channel) {
  const auto it = names.find(channel);
  return it != names.end() ? it->second : fmt::format("can{}", channel - 1);
}

std::string Hex(std::span<const std::uint8_t> bytes) {
  std::string out;
  for (std::size_t i = 0; i < bytes.size(); ++i)
    out += fmt::format("{}{:02X}", i ? " " : "", bytes[i]);
  return out;
}

// ---- ASC ----

constexpr const char* kWeekdays[] = {"Sun", "Mon", "Tue", "Wed", "Thu", "Fri", "Sat"};
constexpr const char* kMonths[] = {"Jan", "Feb", "Mar", "Apr", "May", "Jun",
                                   "Jul", "Aug", "Sep", "Oct", "Nov", "Dec"};

// "Thu Jan 01 12:00:00.000 am 1970" (UTC), as CANoe writes ASC dates.
std::string AscDate(std::int64_t ns) {
  const std::time_t s = static_cast<std::time_t>(ns / kNsPerS);
  std::tm t{};
  ::gmtime_r(&s, &t);
  const int hour12 = t.tm_hour % 12 == 0 ? 12 : t.tm_hour % 12;
  return fmt::format("{} {} {:02} {:02}:{:02}:{:02}.{:03} {} {}", kWeekdays[t.tm_wday],
                     kMonths[t.tm_mon], t.tm_mday, hour12, t.tm_min, t.tm_sec,
                     ns % kNsPerS / kNsPerMs, t.tm_hour < 12 ? "am" : "pm", t.tm_year + 1900);
}

// The inverse of AscDate (English month names; "am"/"pm" in any case); -1 when it is not one.
std::int64_t ParseAscDate(std::string_view text) {
  std::istringstream in{std::string(text)};
  std::string weekday, month, clock, ampm;
  int day = 0, year = 0;
  if (!(in >> weekday >> month >> day >> clock >> ampm >> year)) return -1;
  int mon = -1;
  for (int m = 0; m < 12; ++m) {
    if (month == kMonths[m]) mon = m;
  }
  int h = 0, mi = 0, sec = 0, ms = 0;
  if (mon < 0 || std::sscanf(clock.c_str(), "%d:%d:%d.%d", &h, &mi, &sec, &ms) < 3) return -1;
  for (char& c : ampm) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (ampm != "am" && ampm != "pm") return -1;
  if (year < 1970 || year > kLastYear || mon < 0 || day < 1 || day > 31 || h > 12 || mi > 59 ||
      sec > 60 || ms < 0 || ms > 999) {
    return -1;
  }
  h = h % 12 + (ampm == "pm" ? 12 : 0);
  std::tm t{};
  t.tm_year = year - 1900;
  t.tm_mon = mon;
  t.tm_mday = day;
  t.tm_hour = h;
  t.tm_min = mi;
  t.tm_sec = sec;
  return static_cast<std::int64_t>(::timegm(&t)) * kNsPerS + std::int64_t{ms} * kNsPerMs;
}

// "   0.010238": seconds since the start with microseconds, as python-can's ASCWriter writes.
std::string AscTime(std::int64_t relative_ns) {
  const std::int64_t us = std::max<std::int64_t>(0, relative_ns) / 1000;
  return fmt::format("{:>11}", fmt::format("{}.{:06}", us / 1'000'000, us % 1'000'000));
}

// Decimal seconds with up to 9 fraction digits as ns; false when it is not one.
bool ParseSeconds(std::string_view s, std::int64_t& ns) {
  const std::size_t dot = s.find('.');
  std::int64_t whole = 0, frac = 0;
  const std::string_view w = s.substr(0, dot);
  if (w.empty()) return false;
  for (char c : w) {
    if (!std::isdigit(static_cast<unsigned char>(c))) return false;
    whole = whole * 10 + (c - '0');
    if (whole > kMaxSinceStartNs / kNsPerS) return false;
  }
  int digits = 0;
  if (dot != std::string_view::npos) {
    for (char c : s.substr(dot + 1)) {
      if (!std::isdigit(static_cast<unsigned char>(c)) || digits == 9) return false;
      frac = frac * 10 + (c - '0');
      ++digits;
    }
  }
  for (; digits < 9; ++digits) frac *= 10;
  ns = whole * kNsPerS + frac;
  return true;
}

bool ParseHexId(std::string_view s, CanFrame& f) {
  f.extended = !s.empty() && (s.back() == 'x' || s.back() == 'X');
  if (f.extended) s.remove_suffix(1);
  if (s.empty() || s.size() > 8) return false;
  std::uint32_t id = 0;
  for (char c : s) {
    const int v = internal::HexValue(c);
    if (v < 0) return false;
    id = id << 4 | static_cast<std::uint32_t>(v);
  }
  f.id = id;
  return true;
}

bool ParseHexByte(const std::string& s, std::uint8_t& out) {
  const int hi = s.size() == 2 ? internal::HexValue(s[0]) : -1;
  const int lo = s.size() == 2 ? internal::HexValue(s[1]) : -1;
  if (hi < 0 || lo < 0) return false;
  out = static_cast<std::uint8_t>(hi << 4 | lo);
  return true;
}

// One ASC body line into `r` (its time relative to the start); false with `why` when it is a
// CAN line that cannot be read; `skipped` for events and anything not a frame.
bool ParseAscLine(const std::string& line, const std::map<int, std::string>& names,
                  CandumpRecord& r, bool& skipped, std::string& why) {
  skipped = true;
  std::istringstream in(line);
  std::vector<std::string> tok;
  for (std::string t; in >> t;) tok.push_back(t);
  std::int64_t t_ns = 0;
  if (tok.size() < 3) return true;
  if (!ParseSeconds(tok[0], t_ns)) {
    // Not a time: not a frame line. A number that is one but out of range is an error.
    if (!std::isdigit(static_cast<unsigned char>(tok[0][0]))) return true;
    return (why = "a time that is not seconds (up to 31 years) since the start", false);
  }
  r = CandumpRecord{};
  r.timestamp_ns = t_ns;
  CanFrame& f = r.frame;
  auto channel = [&](const std::string& s) {
    const bool digits = !s.empty() && s.size() < 6 && std::all_of(s.begin(), s.end(), [](char c) {
      return std::isdigit(static_cast<unsigned char>(c)) != 0;
    });
    return digits ? std::stoi(s) : -1;
  };
  if (tok[1] == "CANFD") {
    // CANFD <ch> <Rx|Tx> <id> [name] <brs> <esi> <dlc> <length> <data...> ...
    if (tok.size() < 9) return (why = "a CANFD line with too few fields", false);
    const int ch = channel(tok[2]);
    if (ch < 1 || !ParseHexId(tok[4], f)) return (why = "a bad channel or id", false);
    std::size_t i = 5;
    if (tok[i] != "0" && tok[i] != "1") ++i;  // a symbolic name
    if (i + 4 > tok.size()) return (why = "a CANFD line with too few fields", false);
    f.fd = true;
    if (tok[i] == "1") f.fd_flags |= 0x01;
    if (tok[i + 1] == "1") f.fd_flags |= 0x02;
    char* end = nullptr;
    const long len = std::strtol(tok[i + 3].c_str(), &end, 10);
    if (end != tok[i + 3].c_str() + tok[i + 3].size())
      return (why = "a bad CANFD data length", false);
    if (len < 0 || !IsValidFdLength(static_cast<std::size_t>(len)) ||
        i + 4 + static_cast<std::size_t>(len) > tok.size()) {
      return (why = "a bad CANFD data length", false);
    }
    for (long k = 0; k < len; ++k) {
      if (!ParseHexByte(tok[i + 4 + static_cast<std::size_t>(k)],
                        f.data[static_cast<std::size_t>(k)])) {
        return (why = "a bad data byte", false);
      }
    }
    f.len = static_cast<std::uint8_t>(len);
    if (!f.IsValid()) return (why = "not a valid CAN FD frame (its id)", false);
    r.interface = ChannelName(names, ch);
    r.direction = tok[3] == "Tx" ? 'T' : 'R';
    skipped = false;
    return true;
  }
  const int ch = channel(tok[1]);
  if (ch < 1) return true;  // an event ("Start of measurement", statistics)
  r.interface = ChannelName(names, ch);
  if (tok[2] == "ErrorFrame") {
    f.error = true;
    f.id = kCanErrBusError;
    f.len = 8;
    skipped = false;
    return true;
  }
  if (tok.size() < 5 || (tok[3] != "Rx" && tok[3] != "Tx")) return true;
  if (!ParseHexId(tok[2], f)) return (why = "a bad id", false);
  r.direction = tok[3] == "Tx" ? 'T' : 'R';
  int dlc = 0;
  if (tok.size() > 5) {
    dlc = tok[5].size() == 1 ? internal::HexValue(tok[5][0]) : -1;
    if (dlc < 0) return (why = "a bad DLC", false);
  }
  if (dlc > 8) return (why = "a DLC above 8", false);
  if (tok[4] == "r") {
    f.rtr = true;
    f.len = static_cast<std::uint8_t>(dlc);
  } else if (tok[4] == "d") {
    if (tok.size() < 6 + static_cast<std::size_t>(dlc))
      return (why = "fewer data bytes than the DLC", false);
    for (int k = 0; k < dlc; ++k) {
      if (!ParseHexByte(tok[6 + static_cast<std::size_t>(k)],
                        f.data[static_cast<std::size_t>(k)])) {
        return (why = "a bad data byte", false);
      }
    }
    f.len = static_cast<std::uint8_t>(dlc);
  } else {
    return true;
  }
  if (!f.IsValid()) return (why = "not a valid CAN frame (its id)", false);
  skipped = false;
  return true;
}

std::vector<CandumpRecord> ParseAsc(std::istream& in, const std::string& path) {
  std::vector<CandumpRecord> out;
  std::map<int, std::string> names;
  std::int64_t start = -1;
  bool body = false;
  std::size_t line_number = 0;
  for (std::string line; std::getline(in, line);) {
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const std::size_t first = line.find_first_not_of(" \t");
    if (first == std::string::npos) continue;
    const std::string_view l = std::string_view(line).substr(first);
    if (l.starts_with("//")) {
      int n = 0;
      char name[64] = {};
      if (std::sscanf(line.c_str() + first, "// channel %d %63s", &n, name) == 2) names[n] = name;
      continue;
    }
    if (!body) {
      if (l.starts_with("date ") && start < 0) start = ParseAscDate(l.substr(5));
      if (l.starts_with("Begin Triggerblock")) {
        body = true;
        const std::int64_t begin = ParseAscDate(l.substr(std::strlen("Begin Triggerblock")));
        if (begin >= 0) start = begin;
      }
      continue;
    }
    if (l.starts_with("End TriggerBlock")) break;
    CandumpRecord r;
    bool skipped = true;
    std::string why;
    if (!ParseAscLine(line, names, r, skipped, why)) {
      throw std::invalid_argument(fmt::format("{}:{}: {}", path, line_number, why));
    }
    if (skipped) continue;
    r.timestamp_ns += std::max<std::int64_t>(0, start);
    out.push_back(r);
  }
  if (!body) throw std::invalid_argument(path + ": no 'Begin Triggerblock': not an ASC log");
  return out;
}

// ---- BLF ----

constexpr std::uint32_t kCanMessage = 1;
constexpr std::uint32_t kLogContainer = 10;
constexpr std::uint32_t kAppText = 65;
constexpr std::uint32_t kCanErrorExt = 73;
constexpr std::uint32_t kCanMessage2 = 86;
constexpr std::uint32_t kCanFdMessage = 100;
constexpr std::uint32_t kCanFdMessage64 = 101;
constexpr std::uint32_t kExtendedIdFlag = 0x80000000;
constexpr std::uint8_t kRemoteFlag = 0x80;
constexpr std::uint8_t kTxFlag = 0x01;
constexpr std::uint32_t kTimeTenUs = 1;  // object time flags: 10 us units, else ns
constexpr std::uint32_t kTimeOneNs = 2;
constexpr std::size_t kFileHeaderSize = 144;
constexpr std::size_t kMaxContainerBytes = 128 * 1024;
constexpr std::uint32_t kAppTextMetadata = 2;
constexpr char kChannelText[] = "wheelhil channel ";

void Put8(std::string& b, std::uint8_t v) { b.push_back(static_cast<char>(v)); }
void Put16(std::string& b, std::uint16_t v) { b.append(reinterpret_cast<const char*>(&v), 2); }
void Put32(std::string& b, std::uint32_t v) { b.append(reinterpret_cast<const char*>(&v), 4); }
void Put64(std::string& b, std::uint64_t v) { b.append(reinterpret_cast<const char*>(&v), 8); }
void Zeros(std::string& b, std::size_t n) { b.append(n, '\0'); }

template <typename T>
T Get(std::string_view b, std::size_t at) {
  T v{};
  std::memcpy(&v, b.data() + at, sizeof(T));
  return v;
}

// SYSTEMTIME (year, month, weekday, day, hour, minute, second, ms), UTC; zeros for no date.
void PutSystemTime(std::string& b, std::int64_t ns) {
  if (ns < kFirstDateNs) {
    Zeros(b, 16);
    return;
  }
  const std::time_t s = static_cast<std::time_t>(ns / kNsPerS);
  std::tm t{};
  ::gmtime_r(&s, &t);
  for (int v : {t.tm_year + 1900, t.tm_mon + 1, t.tm_wday, t.tm_mday, t.tm_hour, t.tm_min, t.tm_sec,
                static_cast<int>(ns % kNsPerS / kNsPerMs)}) {
    Put16(b, static_cast<std::uint16_t>(v));
  }
}

// The inverse of PutSystemTime; 0 (times from 0) for a SYSTEMTIME that is no date from 1970
// to kLastYear, as python-can's reader takes one it cannot convert.
std::int64_t GetSystemTime(std::string_view b, std::size_t at) {
  const int year = Get<std::uint16_t>(b, at), month = Get<std::uint16_t>(b, at + 2);
  const int day = Get<std::uint16_t>(b, at + 6), hour = Get<std::uint16_t>(b, at + 8);
  const int minute = Get<std::uint16_t>(b, at + 10), second = Get<std::uint16_t>(b, at + 12);
  const int ms = Get<std::uint16_t>(b, at + 14);
  if (year < 1970 || year > kLastYear || month < 1 || month > 12 || day < 1 || day > 31 ||
      hour > 23 || minute > 59 || second > 60 || ms > 999) {
    return 0;
  }
  std::tm t{};
  t.tm_year = year - 1900;
  t.tm_mon = month - 1;
  t.tm_mday = day;
  t.tm_hour = hour;
  t.tm_min = minute;
  t.tm_sec = second;
  return static_cast<std::int64_t>(::timegm(&t)) * kNsPerS + std::int64_t{ms} * kNsPerMs;
}

// One object (v1 header, ns timestamps since the start) appended to `out`, padded as
// python-can's BLFWriter pads (its reader looks for the next "LOBJ" within 8 bytes).
void PutObject(std::string& out, std::uint32_t type, std::uint64_t t_ns, const std::string& data) {
  const std::uint32_t size = static_cast<std::uint32_t>(32 + data.size());
  out += "LOBJ";
  Put16(out, 32);
  Put16(out, 1);
  Put32(out, size);
  Put32(out, type);
  Put32(out, kTimeOneNs);
  Put16(out, 0);
  Put16(out, 0);
  Put64(out, t_ns);
  out += data;
  Zeros(out, data.size() % 4);
}

std::string FrameObject(const CanFrame& f, int channel, char direction, std::uint32_t* type) {
  std::string d;
  std::uint32_t id = f.id | (f.extended ? kExtendedIdFlag : 0u);
  const std::uint8_t flags =
      static_cast<std::uint8_t>((f.rtr ? kRemoteFlag : 0) | (direction == 'T' ? kTxFlag : 0));
  if (f.error) {
    *type = kCanErrorExt;
    Put16(d, static_cast<std::uint16_t>(channel));
    Put16(d, 0);
    Put32(d, 0);
    Put8(d, 0);
    Put8(d, 0);
    Put8(d, LengthToDlc(f.len));
    Put8(d, 0);
    Put32(d, 0);
    Put32(d, f.id);
    Put16(d, 0);
    Zeros(d, 2);
    d.append(reinterpret_cast<const char*>(f.data.data()), 8);
  } else if (f.fd) {
    *type = kCanFdMessage;
    Put16(d, static_cast<std::uint16_t>(channel));
    Put8(d, flags);
    Put8(d, LengthToDlc(f.len));
    Put32(d, id);
    Put32(d, 0);  // frame length (ns on the wire): not known here
    Put8(d, 0);   // bit count
    Put8(d, static_cast<std::uint8_t>(0x1 | (f.fd_flags & 0x01 ? 0x2 : 0) |
                                      (f.fd_flags & 0x02 ? 0x4 : 0)));  // EDL, BRS, ESI
    Put8(d, f.len);
    Zeros(d, 5);
    d.append(reinterpret_cast<const char*>(f.data.data()), 64);
  } else {
    *type = kCanMessage;
    Put16(d, static_cast<std::uint16_t>(channel));
    Put8(d, flags);
    Put8(d, f.len);
    Put32(d, id);
    d.append(reinterpret_cast<const char*>(f.data.data()), 8);
  }
  return d;
}

std::string AppText(const std::string& text) {
  std::string d;
  Put32(d, kAppTextMetadata);
  Put32(d, 0);
  Put32(d, static_cast<std::uint32_t>(text.size()));
  Put32(d, 0);
  return d + text;
}

// Frames from the objects in `data` (the containers' contents, joined), each with its channel
// number in `channels`; channel names from the app-text objects into `names`.
void ParseBlfObjects(std::string_view data, std::int64_t start, const std::string& path,
                     std::vector<CandumpRecord>& out, std::vector<int>& channels,
                     std::map<int, std::string>& names) {
  std::size_t pos = 0;
  while (pos + 16 <= data.size()) {
    const std::size_t at = data.substr(pos, 12).find("LOBJ");
    if (at == std::string_view::npos) {
      throw std::invalid_argument(
          fmt::format("{}: after frame {}: no object where one should begin", path, out.size()));
    }
    pos += at;
    const auto header_size = Get<std::uint16_t>(data, pos + 4);
    const auto size = Get<std::uint32_t>(data, pos + 8);
    const auto type = Get<std::uint32_t>(data, pos + 12);
    if (header_size < 32 || size < header_size || size > data.size() - pos) {
      throw std::invalid_argument(fmt::format("{}: an object of {} bytes (header {}) does not fit",
                                              path, size, header_size));
    }
    // v1 and v2 headers keep the time flags and the time at the same places.
    const std::uint32_t tflags = Get<std::uint32_t>(data, pos + 16);
    const std::uint64_t t = Get<std::uint64_t>(data, pos + 24);
    const std::uint64_t unit = tflags == kTimeTenUs ? 10'000 : 1;
    if (t > static_cast<std::uint64_t>(kMaxSinceStartNs) / unit) {
      throw std::invalid_argument(fmt::format(
          "{}: an object's time ({} units of {} ns) is more than 31 years from the start", path, t,
          unit));
    }
    const std::string_view d = data.substr(pos + header_size, size - header_size);
    pos += size;
    CandumpRecord r;
    r.timestamp_ns = start + static_cast<std::int64_t>(t * unit);
    CanFrame& f = r.frame;
    int channel = 0;
    if ((type == kCanMessage || type == kCanMessage2) && d.size() >= 16) {
      channel = Get<std::uint16_t>(d, 0);
      const std::uint8_t flags = Get<std::uint8_t>(d, 2);
      const std::uint32_t id = Get<std::uint32_t>(d, 4);
      f.extended = (id & kExtendedIdFlag) != 0;
      f.id = id & CanFrame::kMaxExtendedId;
      f.rtr = (flags & kRemoteFlag) != 0;
      f.len = std::min<std::uint8_t>(Get<std::uint8_t>(d, 3), 8);
      std::memcpy(f.data.data(), d.data() + 8, f.rtr ? 0 : f.len);
      r.direction = flags & kTxFlag ? 'T' : 'R';
    } else if (type == kCanFdMessage && d.size() >= 84) {
      channel = Get<std::uint16_t>(d, 0);
      const std::uint8_t flags = Get<std::uint8_t>(d, 2);
      const std::uint32_t id = Get<std::uint32_t>(d, 4);
      const std::uint8_t fd_flags = Get<std::uint8_t>(d, 13);
      f.extended = (id & kExtendedIdFlag) != 0;
      f.id = id & CanFrame::kMaxExtendedId;
      f.fd = (fd_flags & 0x1) != 0;
      f.rtr = !f.fd && (flags & kRemoteFlag) != 0;
      if (f.fd) {
        f.fd_flags =
            static_cast<std::uint8_t>((fd_flags & 0x2 ? 0x01 : 0) | (fd_flags & 0x4 ? 0x02 : 0));
      }
      f.len = std::min<std::uint8_t>(Get<std::uint8_t>(d, 14), f.fd ? 64 : 8);
      std::memcpy(f.data.data(), d.data() + 20, f.len);
      r.direction = flags & kTxFlag ? 'T' : 'R';
    } else if (type == kCanFdMessage64 && d.size() >= 40) {
      // channel u8, dlc u8, valid bytes u8, tx count u8, id, frame length, flags (EDL 0x1000,
      // BRS 0x2000, ESI 0x4000, remote 0x0010), four bit-timing words, bit count u16, dir u8
      // (at 34), ext data offset u8, crc; the data follows at 40.
      channel = Get<std::uint8_t>(d, 0);
      const std::uint32_t id = Get<std::uint32_t>(d, 4);
      const std::uint32_t flags = Get<std::uint32_t>(d, 12);
      f.extended = (id & kExtendedIdFlag) != 0;
      f.id = id & CanFrame::kMaxExtendedId;
      f.fd = (flags & 0x1000) != 0;
      f.rtr = !f.fd && (flags & 0x0010) != 0;
      if (f.fd) {
        f.fd_flags =
            static_cast<std::uint8_t>((flags & 0x2000 ? 0x01 : 0) | (flags & 0x4000 ? 0x02 : 0));
      }
      f.len = std::min<std::uint8_t>(Get<std::uint8_t>(d, 2), f.fd ? 64 : 8);
      if (d.size() < 40u + (f.rtr ? 0 : f.len)) {
        throw std::invalid_argument(
            fmt::format("{}: a CAN_FD_MESSAGE_64 shorter than its {} data bytes", path, f.len));
      }
      std::memcpy(f.data.data(), d.data() + 40, f.rtr ? 0 : f.len);
      r.direction = Get<std::uint8_t>(d, 34) != 0 ? 'T' : 'R';
    } else if (type == kCanErrorExt && d.size() >= 32) {
      channel = Get<std::uint16_t>(d, 0);
      f.error = true;
      f.id = Get<std::uint32_t>(d, 16) & CanFrame::kMaxExtendedId;
      if (f.id == 0) f.id = kCanErrBusError;
      f.len = 8;
      std::memcpy(f.data.data(), d.data() + 24, 8);
    } else if (type == kAppText && d.size() >= 16) {
      const std::string_view text = d.substr(16, Get<std::uint32_t>(d, 8));
      if (text.starts_with(kChannelText)) {
        int n = 0;
        char name[64] = {};
        const std::string s(text);
        if (std::sscanf(s.c_str() + std::strlen(kChannelText), "%d %63s", &n, name) == 2) {
          names[n] = name;
        }
      }
      continue;
    } else {
      continue;  // another object type (statistics, markers, other buses)
    }
    if (!f.IsValid()) {
      throw std::invalid_argument(fmt::format("{}: frame {} (id {:X}) is not a valid CAN frame",
                                              path, out.size() + 1, f.id));
    }
    out.push_back(r);
    channels.push_back(channel);
  }
}

std::vector<CandumpRecord> ParseBlf(std::string_view file, const std::string& path) {
  if (file.size() < 72 || file.substr(0, 4) != "LOGG") {
    throw std::invalid_argument(path + ": no 'LOGG' signature: not a BLF log");
  }
  const std::int64_t start = GetSystemTime(file, 40);
  std::size_t pos = Get<std::uint32_t>(file, 4);
  std::string objects;
  while (pos + 16 <= file.size()) {
    if (file.substr(pos, 4) != "LOBJ") {
      throw std::invalid_argument(
          fmt::format("{}: byte {}: no object where one should begin", path, pos));
    }
    const auto size = Get<std::uint32_t>(file, pos + 8);
    const auto type = Get<std::uint32_t>(file, pos + 12);
    const auto header_size = Get<std::uint16_t>(file, pos + 4);
    if (header_size < 16 || size < header_size || size > file.size() - pos) {
      throw std::invalid_argument(
          fmt::format("{}: byte {}: an object runs past the end", path, pos));
    }
    if (type == kLogContainer && size >= header_size + 16u) {
      const std::string_view c = file.substr(pos + header_size, size - header_size);
      const auto method = Get<std::uint16_t>(c, 0);
      const auto raw_size = Get<std::uint32_t>(c, 8);
      const std::string_view payload = c.substr(16);
      if (method == 0) {
        objects.append(payload);
      } else if (method == 2) {
        if (raw_size > kMaxContainerInflated) {
          throw std::invalid_argument(
              fmt::format("{}: byte {}: a container of {} MiB inflated, more than the {} MiB a "
                          "reader takes",
                          path, pos, raw_size >> 20, kMaxContainerInflated >> 20));
        }
        std::string raw(raw_size, '\0');
        uLongf n = raw_size;
        if (::uncompress(reinterpret_cast<Bytef*>(raw.data()), &n,
                         reinterpret_cast<const Bytef*>(payload.data()),
                         static_cast<uLong>(payload.size())) != Z_OK) {
          throw std::invalid_argument(
              fmt::format("{}: byte {}: a container zlib cannot inflate", path, pos));
        }
        raw.resize(n);
        objects += raw;
      }
    }
    pos += size + size % 4;
  }
  std::vector<CandumpRecord> out;
  std::vector<int> channels;
  std::map<int, std::string> names;
  ParseBlfObjects(objects, start, path, out, channels, names);
  for (std::size_t i = 0; i < out.size(); ++i) out[i].interface = ChannelName(names, channels[i]);
  return out;
}

}  // namespace

CanLogFormat CanLogFormatOf(const std::string& path) {
  const std::size_t dot = path.rfind('.');
  std::string ext = dot == std::string::npos ? "" : path.substr(dot + 1);
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (ext == "log") return CanLogFormat::kCandump;
  if (ext == "asc") return CanLogFormat::kAsc;
  if (ext == "blf") return CanLogFormat::kBlf;
  throw std::invalid_argument(path + ": not a CAN log by its name (.log candump, .asc, .blf)");
}

std::string FormatAsc(const std::vector<CandumpRecord>& records) {
  const std::int64_t start = StartOf(records);
  ChannelNumbers channels;
  std::string body;
  for (const CandumpRecord& r : records) {
    const CanFrame& f = r.frame;
    const int ch = channels.Of(r.interface);
    std::string line;
    const std::string id = fmt::format("{:X}{}", f.id, f.extended ? "x" : "");
    const char* dir = r.direction == 'T' ? "Tx" : "Rx";
    if (f.error) {
      line = fmt::format("{}  ErrorFrame", ch);
    } else if (f.fd) {
      // python-can's ASCWriter layout (its reader and CANoe's take it); no symbolic name, no
      // bit timing: zeros.
      line = fmt::format(
          "CANFD {:>3} {:<4} {:>8}  {:>32} {} {} {:x} {:>2} {}{}{:>8} {:>4} {:>8X} {:>8} {:>8} "
          "{:>8} {:>8} {:>8}",
          ch, dir, id, "", f.fd_flags & 0x01 ? 1 : 0, f.fd_flags & 0x02 ? 1 : 0, LengthToDlc(f.len),
          f.len, Hex(f.payload()), f.len ? " " : "", 0, 0,
          0x1000 | (f.fd_flags & 0x01 ? 0x2000 : 0) | (f.fd_flags & 0x02 ? 0x4000 : 0), 0, 0, 0, 0,
          0);
    } else if (f.rtr) {
      line = fmt::format("{}  {:<15} {:<4} r {:x}", ch, id, dir, f.len);
    } else {
      line = fmt::format("{}  {:<15} {:<4} d {:x}{}{}", ch, id, dir, f.len, f.len ? " " : "",
                         Hex(f.payload()));
    }
    body += AscTime(r.timestamp_ns - start) + " " + line + "\n";
  }
  const std::string date = AscDate(start);
  std::string out = fmt::format(
      "date {}\nbase hex  timestamps absolute\ninternal events logged\n"
      "// version 9.0.0\n",
      date);
  for (std::size_t i = 0; i < channels.names().size(); ++i) {
    out += fmt::format("// channel {} {}\n", i + 1, channels.names()[i]);
  }
  out += fmt::format("Begin Triggerblock {}\n{} Start of measurement\n", date, AscTime(0));
  return out + body + "End TriggerBlock\n";
}

std::string FormatBlf(const std::vector<CandumpRecord>& records) {
  const std::int64_t start = StartOf(records);
  const std::int64_t base = start >= kFirstDateNs ? start : 0;
  ChannelNumbers channels;
  std::string objects;
  std::uint32_t count = 0;
  for (const CandumpRecord& r : records) {
    const std::size_t known = channels.names().size();
    const int ch = channels.Of(r.interface);
    const auto t = static_cast<std::uint64_t>(std::max<std::int64_t>(0, r.timestamp_ns - base));
    if (channels.names().size() > known) {
      PutObject(objects, kAppText, t,
                AppText(fmt::format("{}{} {}", kChannelText, ch, r.interface)));
      ++count;
    }
    std::uint32_t type = 0;
    const std::string d = FrameObject(r.frame, ch, r.direction, &type);
    PutObject(objects, type, t, d);
    ++count;
  }
  std::string body;
  std::uint64_t uncompressed = kFileHeaderSize;
  for (std::size_t at = 0; at < objects.size(); at += kMaxContainerBytes) {
    const std::string_view raw = std::string_view(objects).substr(at, kMaxContainerBytes);
    uLongf n = ::compressBound(static_cast<uLong>(raw.size()));
    std::string z(n, '\0');
    if (::compress(reinterpret_cast<Bytef*>(z.data()), &n,
                   reinterpret_cast<const Bytef*>(raw.data()),
                   static_cast<uLong>(raw.size())) != Z_OK) {
      throw std::runtime_error("zlib cannot compress a BLF container");
    }
    z.resize(n);
    const std::uint32_t size = static_cast<std::uint32_t>(16 + 16 + z.size());
    body += "LOBJ";
    Put16(body, 16);
    Put16(body, 1);
    Put32(body, size);
    Put32(body, kLogContainer);
    Put16(body, 2);  // zlib deflate
    Zeros(body, 6);
    Put32(body, static_cast<std::uint32_t>(raw.size()));
    Zeros(body, 4);
    body += z;
    Zeros(body, size % 4);
    uncompressed += 32 + raw.size();
  }
  std::string head = "LOGG";
  Put32(head, kFileHeaderSize);
  for (std::uint8_t v : {5, 0, 0, 0, 2, 6, 8, 1}) Put8(head, v);  // application, BLF version
  Put64(head, kFileHeaderSize + body.size());
  Put64(head, uncompressed);
  Put32(head, count);
  Put32(head, 0);
  PutSystemTime(head, base);
  PutSystemTime(head, records.empty() ? base : std::max(base, records.back().timestamp_ns));
  Zeros(head, kFileHeaderSize - head.size());
  return head + body;
}

void WriteCanLog(const std::string& path, CanLogFormat format,
                 const std::vector<CandumpRecord>& records) {
  for (std::size_t i = 0; i < records.size(); ++i) {
    if (!records[i].frame.IsValid()) {
      throw std::invalid_argument(fmt::format("{}: record {} is not a valid frame", path, i + 1));
    }
    // What the readers take back: dates up to kLastYear, times up to ~31 years after the first.
    const std::int64_t t = records[i].timestamp_ns;
    if (format != CanLogFormat::kCandump &&
        (t < 0 || t >= kEndOfLastYearNs || t - records.front().timestamp_ns > kMaxSinceStartNs)) {
      throw std::invalid_argument(fmt::format(
          "{}: record {}: its time is not between 1970 and {} and within 31 years of the first",
          path, i + 1, kLastYear));
    }
  }
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw std::invalid_argument(path + ": cannot be written");
  if (format == CanLogFormat::kCandump) {
    CandumpWriter w(out);
    for (const CandumpRecord& r : records) {
      if (!w.Write(r)) throw std::invalid_argument(path + ": cannot be written");
    }
    if (!w.Flush()) throw std::invalid_argument(path + ": cannot be written");
    return;
  }
  out << (format == CanLogFormat::kAsc ? FormatAsc(records) : FormatBlf(records));
  if (!out.flush()) throw std::invalid_argument(path + ": cannot be written");
}

std::vector<CandumpRecord> ParseCanLog(std::string_view bytes, CanLogFormat format,
                                       const std::string& name) {
  if (format == CanLogFormat::kBlf) return ParseBlf(bytes, name);
  if (format == CanLogFormat::kAsc) {
    std::istringstream in{std::string(bytes)};
    return ParseAsc(in, name);
  }
  throw std::invalid_argument(name + ": ParseCanLog reads ASC and BLF (candump: CandumpReader)");
}

std::vector<CandumpRecord> ReadCanLog(const std::string& path, CanLogFormat format) {
  if (format == CanLogFormat::kCandump) {
    CandumpLog log = LoadCandumpFile(path);
    if (!log.errors.empty()) throw std::invalid_argument(log.errors.front());
    return std::move(log.records);
  }
  const char* kind = format == CanLogFormat::kAsc ? "ASC" : "BLF";
  return ParseCanLog(
      internal::ReadInputFile(path, kind, kMaxLogBytes, "a log is read whole; convert it in parts"),
      format, path);
}

}  // namespace wheelhil::bus
