#pragma once
/// An owned file descriptor: closed when it goes, movable, not copyable. Header-only (the
/// interposition libraries may use it too). Thread-compatible.

#include <unistd.h>

#include <utility>

namespace wheelhil::bus::internal {

class UniqueFd {
 public:
  UniqueFd() = default;
  explicit UniqueFd(int fd) : fd_(fd) {}
  UniqueFd(UniqueFd&& o) noexcept : fd_(std::exchange(o.fd_, -1)) {}
  UniqueFd& operator=(UniqueFd&& o) noexcept {
    if (this != &o) {
      Reset();
      fd_ = std::exchange(o.fd_, -1);
    }
    return *this;
  }
  UniqueFd(const UniqueFd&) = delete;
  UniqueFd& operator=(const UniqueFd&) = delete;
  ~UniqueFd() { Reset(); }

  void Reset() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }
  /// Gives the descriptor up without closing it.
  int release() { return std::exchange(fd_, -1); }
  int get() const { return fd_; }

 private:
  int fd_ = -1;
};

}  // namespace wheelhil::bus::internal
