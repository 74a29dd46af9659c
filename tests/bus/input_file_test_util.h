#pragma once
// Paths of every kind a user can give a loader (DBC, EDS): a scratch folder, a FIFO, a sparse
// file past a size limit; and a load of a FIFO that cannot hang the test.

#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <future>
#include <stdexcept>
#include <string>

namespace wheelhil::bus::testing {

class ScratchDir {
 public:
  ScratchDir() {
    std::string tmpl = ::testing::TempDir() + "/wheelhil_input_XXXXXX";
    if (::mkdtemp(tmpl.data()) == nullptr) throw std::runtime_error("mkdtemp failed");
    path_ = tmpl;
  }
  ~ScratchDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
  std::string Path(const std::string& name) const { return path_ + "/" + name; }
  std::string Fifo(const std::string& name) const {
    const std::string p = Path(name);
    if (::mkfifo(p.c_str(), 0600) != 0) throw std::runtime_error("mkfifo failed");
    return p;
  }
  // A file of `bytes` zero bytes that takes no disk space.
  std::string Sparse(const std::string& name, std::size_t bytes) const {
    const std::string p = Path(name);
    const int fd = ::open(p.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
    if (fd < 0 || ::ftruncate(fd, static_cast<off_t>(bytes)) != 0) {
      throw std::runtime_error("cannot make a sparse file");
    }
    ::close(fd);
    return p;
  }

 private:
  std::string path_;
};

// The error `load` throws for the FIFO `fifo`. A load that waits for a writer is released after
// 10 s (a writer opens and closes the FIFO: end of file) and is a failure, not a hung test.
inline std::string LoadErrorOfFifo(const std::string& fifo, const std::function<void()>& load) {
  auto result = std::async(std::launch::async, [&]() -> std::string {
    try {
      load();
      return "(loaded without an error)";
    } catch (const std::invalid_argument& e) {
      return e.what();
    }
  });
  if (result.wait_for(std::chrono::seconds(10)) != std::future_status::ready) {
    ADD_FAILURE() << fifo << ": the load waits for a writer";
    const int fd = ::open(fifo.c_str(), O_WRONLY);
    if (fd >= 0) ::close(fd);
  }
  return result.get();
}

}  // namespace wheelhil::bus::testing
