#pragma once
/// The can-utils `candump -L` log format, the lingua franca of CAN logs and golden traces:
///
///     (0000000000.010000) vcan0 123#DEADBEEF
///
/// A line is `(<seconds>.<fraction>) <interface> <ID#DATA>[ <T|R>]`. What we write matches byte
/// for byte what Debian 12's can-utils 2020.11 `candump -L` writes for one interface: seconds
/// zero-padded to 10 digits, 6 fraction digits (microseconds), the frame in can-utils `ID#DATA`
/// notation (bus::ToCanUtilsString), no direction flag. The reader also accepts what other
/// writers produce: unpadded seconds and 1..9 fraction digits (newer candump writes
/// nanoseconds with -N, python-can writes `%f`), padded interface columns, a trailing ` R`/` T`
/// direction flag (candump -x, python-can), `.` data separators, `r` for RTR, and the
/// `_<dlc>` raw-DLC suffix of newer can-utils (accepted, the raw DLC is dropped). Lines that do
/// not start with `(` are comments (as for canplayer and log2asc) and are skipped.
///
/// Timestamps are integer nanoseconds since the epoch (or since the run's start for emulator
/// traces): no floating point anywhere, so a log round-trips exactly at microsecond resolution.

#include <cstdint>
#include <fstream>
#include <iosfwd>
#include <string>
#include <string_view>
#include <vector>

#include "bus/can_frame.h"

namespace wheelhil::bus {

/// One logged frame.
struct CandumpRecord {
  std::int64_t timestamp_ns = 0;  ///< >= 0; candump's resolution is 1 us.
  std::string interface;          ///< e.g. "vcan0", "ucan0".
  CanFrame frame;
  char direction = 0;  ///< 'R' (received), 'T' (transmitted) or 0 when the line has no flag.

  bool operator==(const CandumpRecord&) const = default;
};

/// What ParseCandumpLine found on a line.
enum class CandumpLineStatus {
  kRecord,   ///< `out` holds the frame.
  kSkipped,  ///< Blank line or comment (does not start with '(').
  kError,    ///< Malformed; `error` says "line N: problem".
};

/// Parses one log line (a trailing "\n" or "\r\n" is allowed). Never throws on bad input; on
/// kError `*error` (when given) reads "line <line_number>: <problem>" and `out` is unspecified.
CandumpLineStatus ParseCandumpLine(std::string_view line, std::size_t line_number,
                                   CandumpRecord& out, std::string* error = nullptr);

/// Parses can-utils `ID#DATA` notation (the third field of a log line; see lib.c
/// parse_canframe): `123#DEADBEEF`, `1ABCDEF0#00`, `20000080#0000000000000000` (error frame),
/// `123#R`, `123#R4`, `123##1AABB` (FD, flags nibble). Stricter than lib.c: rejects invalid ids,
/// odd hex digits, more than 8 (classic) / 64 (FD) bytes, invalid FD lengths and trailing junk.
bool ParseCanUtilsFrame(std::string_view text, CanFrame& out, std::string* error = nullptr);

/// Formats one line (without '\n') exactly as `candump -L` writes it. A negative timestamp is
/// clamped to 0. Sub-microsecond parts are truncated (as the kernel's timeval is).
std::string FormatCandumpLine(std::int64_t timestamp_ns, std::string_view interface,
                              const CanFrame& frame);

/// Longest line FormatCandumpLine can produce for an interface name of `interface_len` chars
/// (an FD frame with 64 bytes), without '\n'.
constexpr std::size_t MaxCandumpLineLength(std::size_t interface_len) {
  return 20 /* (ssssssssss.uuuuuu) */ + 1 + interface_len + 1 + 8 + 2 + 1 + 2 * 64;
}

/// Allocation-free form: writes the line (without '\n', not NUL-terminated) into `buf` and
/// returns its length, or 0 when `capacity` is too small (MaxCandumpLineLength is enough).
std::size_t FormatCandumpLine(std::int64_t timestamp_ns, std::string_view interface,
                              const CanFrame& frame, char* buf, std::size_t capacity) noexcept;

/// Writes candump -L lines to a stream or file. Flush policy: kEveryLine flushes after each
/// line (a crash or a concurrent `tail -f` sees every frame; costs a write(2) per line);
/// kBuffered leaves it to the stream buffer, Flush() and the destructor (file mode). Write()
/// returns false when the frame is invalid (!frame.IsValid()), the interface name is empty,
/// longer than 64 characters or contains whitespace, or the stream failed; it never throws
/// and does not allocate. Thread-compatible.
class CandumpWriter {
 public:
  enum class FlushPolicy { kEveryLine, kBuffered };

  /// Writes to `out`, which must outlive the writer.
  explicit CandumpWriter(std::ostream& out, FlushPolicy policy = FlushPolicy::kBuffered);
  /// Creates/truncates `path`; throws std::invalid_argument if it cannot be opened.
  explicit CandumpWriter(const std::string& path, FlushPolicy policy = FlushPolicy::kBuffered);
  ~CandumpWriter();
  CandumpWriter(const CandumpWriter&) = delete;
  CandumpWriter& operator=(const CandumpWriter&) = delete;

  [[nodiscard]] bool Write(std::int64_t timestamp_ns, std::string_view interface,
                           const CanFrame& frame);
  [[nodiscard]] bool Write(const CandumpRecord& record) {
    return Write(record.timestamp_ns, record.interface, record.frame);
  }
  [[nodiscard]] bool Flush();
  std::size_t lines_written() const { return lines_written_; }

 private:
  std::ofstream file_;
  std::ostream* out_;
  FlushPolicy policy_;
  std::size_t lines_written_ = 0;
};

/// Streams records from a log. Bad lines do not stop the stream: Next() returns kError for
/// such a line (error() names the line and the problem) and the following call goes on with
/// the next line. Thread-compatible.
class CandumpReader {
 public:
  enum class Status { kRecord, kEnd, kError };

  /// Reads from `in`, which must outlive the reader.
  explicit CandumpReader(std::istream& in) : in_(&in) {}

  Status Next(CandumpRecord& out);
  const std::string& error() const { return error_; }
  /// 1-based number of the line last read.
  std::size_t line_number() const { return line_number_; }

 private:
  std::istream* in_;
  std::string line_;
  std::string error_;
  std::size_t line_number_ = 0;
};

/// A whole log file: every good record plus one message per bad line ("path:line: problem").
struct CandumpLog {
  std::vector<CandumpRecord> records;
  std::vector<std::string> errors;
};

/// Loads a file, collecting bad lines in `errors`; throws std::invalid_argument only if the
/// file cannot be opened.
CandumpLog LoadCandumpFile(const std::string& path);

}  // namespace wheelhil::bus
