#include "bus/internal/input_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstring>
#include <stdexcept>

#include <fmt/format.h>

#include "bus/internal/unique_fd.h"

namespace wheelhil::bus::internal {

RegularFile ReadRegularFile(const std::string& path, std::size_t max_bytes) {
  RegularFile f;
  auto failed = [&](RegularFile::Problem problem, int error = 0) {
    f.problem = problem;
    f.error = error;
    f.text.clear();
    return std::move(f);
  };
  // O_NONBLOCK: opening a FIFO for reading would otherwise wait for a writer, forever.
  const UniqueFd fd(::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY));
  if (fd.get() < 0) return failed(RegularFile::kCannotOpen, errno);
  struct stat st {};
  if (::fstat(fd.get(), &st) != 0) return failed(RegularFile::kCannotOpen, errno);
  if (S_ISDIR(st.st_mode)) return failed(RegularFile::kDirectory);
  if (!S_ISREG(st.st_mode)) return failed(RegularFile::kNotRegular);
  if (static_cast<std::uint64_t>(st.st_size) > max_bytes) return failed(RegularFile::kTooLarge);
  f.text.reserve(static_cast<std::size_t>(st.st_size));
  char chunk[1 << 16];
  for (;;) {
    const ssize_t n = ::read(fd.get(), chunk, sizeof chunk);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) return failed(RegularFile::kCannotRead, errno);
    if (n == 0) break;
    f.text.append(chunk, static_cast<std::size_t>(n));
    if (f.text.size() > max_bytes) return failed(RegularFile::kTooLarge);
  }
  return f;
}

std::string ReadInputFile(const std::string& path, std::string_view kind, std::size_t max_bytes,
                          std::string_view why) {
  RegularFile f = ReadRegularFile(path, max_bytes);
  // "an EDS", "a DBC": the article goes by the letter's name.
  const bool an = !kind.empty() && std::string_view("AEFHILMNORSX").find(kind[0]) != kind.npos;
  const std::string_view article = an ? "an" : "a";
  std::string problem;
  switch (f.problem) {
    case RegularFile::kRead:
      return std::move(f.text);
    case RegularFile::kCannotOpen:
      problem = fmt::format("cannot open {} file ({})", kind, std::strerror(f.error));
      break;
    case RegularFile::kDirectory:
      problem = fmt::format("is a directory, not {} {} file", article, kind);
      break;
    case RegularFile::kNotRegular:
      problem = "is not a regular file (a device or a pipe?)";
      break;
    case RegularFile::kTooLarge:
      problem = fmt::format("is larger than {} MiB, the limit for {} {} file; {}", max_bytes >> 20,
                            article, kind, why);
      break;
    case RegularFile::kCannotRead:
      problem = fmt::format("cannot read {} file ({})", kind, std::strerror(f.error));
      break;
  }
  throw std::invalid_argument(fmt::format("{}:0: {}", path, problem));
}

std::string_view SkipUtf8Bom(std::string_view text) {
  if (text.substr(0, 3) == "\xEF\xBB\xBF") text.remove_prefix(3);
  return text;
}

}  // namespace wheelhil::bus::internal
