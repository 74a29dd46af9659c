#pragma once
/// Reading a user's device description (DBC, EDS) whole, as the YAML reader reads its files
/// (bus/yaml_fields.h): regular files only, a size limit, the reason in the error. Not
/// installed: the loaders' own headers say what they refuse.

#include <cstddef>
#include <string>
#include <string_view>

namespace wheelhil::bus::internal {

/// A regular file read whole, or why not: the one reader behind every loader of a user's file
/// (YAML, DBC, EDS), each of which words the problem in its own messages.
struct RegularFile {
  enum Problem { kRead, kCannotOpen, kDirectory, kNotRegular, kTooLarge, kCannotRead };
  Problem problem = kRead;
  int error = 0;     ///< errno for kCannotOpen and kCannotRead
  std::string text;  ///< kRead: the whole file
};
/// Opens without waiting (a FIFO is refused at once, not read), checks the kind and the size,
/// and counts while it reads (a file that grows meanwhile is caught too).
RegularFile ReadRegularFile(const std::string& path, std::size_t max_bytes);

/// The whole text of `path`. Throws std::invalid_argument "path:0: problem" when it cannot be
/// opened ("cannot open DBC file (No such file or directory)"), is a directory ("is a directory,
/// not a DBC file"), is not a regular file ("is not a regular file (a device or a pipe?)"; a FIFO
/// is refused without waiting for a writer) or holds more than `max_bytes` ("is larger than 256
/// MiB, the limit for a DBC file; <why>"). `kind` names the file ("DBC"), `why` the limit.
std::string ReadInputFile(const std::string& path, std::string_view kind, std::size_t max_bytes,
                          std::string_view why);

/// `text` without a leading UTF-8 byte-order mark (EF BB BF), which Windows tools write.
std::string_view SkipUtf8Bom(std::string_view text);

}  // namespace wheelhil::bus::internal
