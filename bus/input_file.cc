#include "bus/internal/input_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstring>
#include <stdexcept>

#include <fmt/format.h>

namespace wheelhil::bus::internal {
namespace {

class Fd {
 public:
  explicit Fd(int fd) : fd_(fd) {}
  ~Fd() {
    if (fd_ >= 0) ::close(fd_);
  }
  Fd(const Fd&) = delete;
  Fd& operator=(const Fd&) = delete;
  int get() const { return fd_; }

 private:
  int fd_;
};

}  // namespace

std::string ReadInputFile(const std::string& path, std::string_view kind, std::size_t max_bytes,
                          std::string_view why) {
  auto fail = [&](const std::string& problem) {
    throw std::invalid_argument(fmt::format("{}:0: {}", path, problem));
  };
  // O_NONBLOCK: opening a FIFO for reading would otherwise wait for a writer, forever.
  const Fd fd(::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY));
  if (fd.get() < 0) fail(fmt::format("cannot open {} file ({})", kind, std::strerror(errno)));
  struct stat st {};
  if (::fstat(fd.get(), &st) != 0) {
    fail(fmt::format("cannot open {} file ({})", kind, std::strerror(errno)));
  }
  // "an EDS", "a DBC": the article goes by the letter's name.
  const bool an = !kind.empty() && std::string_view("AEFHILMNORSX").find(kind[0]) != kind.npos;
  const std::string_view article = an ? "an" : "a";
  if (S_ISDIR(st.st_mode)) fail(fmt::format("is a directory, not {} {} file", article, kind));
  if (!S_ISREG(st.st_mode)) fail("is not a regular file (a device or a pipe?)");
  const std::string too_large = fmt::format("is larger than {} MiB, the limit for {} {} file; {}",
                                            max_bytes >> 20, article, kind, why);
  if (static_cast<std::uint64_t>(st.st_size) > max_bytes) fail(too_large);
  std::string text;
  text.reserve(static_cast<std::size_t>(st.st_size));
  // Counted while read as well: a file that grows meanwhile is caught too.
  char chunk[1 << 16];
  for (;;) {
    const ssize_t n = ::read(fd.get(), chunk, sizeof chunk);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) fail(fmt::format("cannot read {} file ({})", kind, std::strerror(errno)));
    if (n == 0) break;
    text.append(chunk, static_cast<std::size_t>(n));
    if (text.size() > max_bytes) fail(too_large);
  }
  return text;
}

std::string_view SkipUtf8Bom(std::string_view text) {
  if (text.substr(0, 3) == "\xEF\xBB\xBF") text.remove_prefix(3);
  return text;
}

}  // namespace wheelhil::bus::internal
