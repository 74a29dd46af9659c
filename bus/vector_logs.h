#pragma once
/// Vector's CAN log formats, written and read by the project itself (Debian has no library for
/// them): ASC (text) and BLF (binary, zlib-compressed containers), as CANoe/CANalyzer and
/// python-can (its ASCReader/BLFReader, the independent check in the tests) open them.
///
/// Records are bus::CandumpRecord: integer ns timestamps (since the epoch, or since a run's
/// start), an interface name, the frame, a direction ('T' transmitted, else received).
/// Channels: ASC and BLF number them from 1; a writer numbers the interfaces in the order it
/// first sees them and names them in the file (ASC: `// channel N NAME` comments; BLF: one
/// app-text object per channel), and a reader gives them back by those names, else as
/// `can<N-1>`.
///
/// Time: the file's start (ASC `date`/`Begin Triggerblock`, BLF's SYSTEMTIME) is the first
/// record's instant cut to the millisecond, in UTC; each record is stored relative to it (ASC:
/// microseconds, BLF: nanoseconds), so candump -> ASC/BLF -> candump gives the same records.
/// Error frames: BLF's CAN_ERROR_EXT keeps their class bits and data; ASC's `ErrorFrame` line
/// has neither, so they read back from ASC as CAN_ERR_BUSERROR with zero data. A CANFD line
/// without data is an empty FD frame here (python-can 4.1's ASCReader takes it for a remote
/// frame). Thread-compatible.

#include <cstdint>
#include <iosfwd>
#include <string>
#include <string_view>
#include <vector>

#include "bus/candump_log.h"

namespace wheelhil::bus {

enum class CanLogFormat { kCandump, kAsc, kBlf };

/// By the file's extension (.log, .asc, .blf; case-insensitive); throws std::invalid_argument
/// naming the file for any other.
CanLogFormat CanLogFormatOf(const std::string& path);

/// Writes `records` (in their order) to `path` in `format`. Throws std::invalid_argument naming
/// the file when it cannot be written, a record's frame is invalid, or (ASC, BLF) a record's
/// time is not from 1970 to 2199 and within ~31 years of the first (what the readers take).
void WriteCanLog(const std::string& path, CanLogFormat format,
                 const std::vector<CandumpRecord>& records);

/// Reads a log in `format`. Throws std::invalid_argument naming the file and the line (ASC),
/// byte offset or frame (BLF) of the first thing it cannot read: a frame no controller could
/// send, a time past the year 2262 in int64 ns, a BLF object or container that does not fit
/// (a container is inflated up to 64 MiB). The file is read whole (up to 2 GiB), a regular file
/// only.
std::vector<CandumpRecord> ReadCanLog(const std::string& path, CanLogFormat format);
/// The same for a log's bytes in memory, ASC or BLF; `name` stands for the file in errors.
std::vector<CandumpRecord> ParseCanLog(std::string_view bytes, CanLogFormat format,
                                       const std::string& name);

/// The ASC text of `records` (WriteCanLog's, for tests and streams).
std::string FormatAsc(const std::vector<CandumpRecord>& records);
/// The BLF bytes of `records`.
std::string FormatBlf(const std::vector<CandumpRecord>& records);

}  // namespace wheelhil::bus
