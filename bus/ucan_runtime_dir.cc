#include "bus/ucan_runtime_dir.h"

#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <system_error>
#include <vector>

#include "bus/ucan_protocol.h"

namespace wheelhil::bus {

std::string ResolveUcanRuntimeDir() {
  if (const char* dir = std::getenv("WHEELHIL_UCAN_DIR"); dir != nullptr && dir[0] != '\0') {
    return dir;
  }
  if (const char* xdg = std::getenv("XDG_RUNTIME_DIR"); xdg != nullptr && xdg[0] != '\0') {
    return std::string(xdg) + "/wheelhil";
  }
  return "/tmp/wheelhil-" + std::to_string(static_cast<unsigned long>(geteuid()));
}

std::error_code VerifyUcanRuntimeDir(const std::string& dir) noexcept {
  struct stat st {};
  if (::lstat(dir.c_str(), &st) != 0) return {errno, std::generic_category()};
  if (!S_ISDIR(st.st_mode)) return std::make_error_code(std::errc::not_a_directory);
  if (st.st_uid != ::geteuid() || (st.st_mode & 07777) != 0700) {
    return std::make_error_code(std::errc::permission_denied);
  }
  return {};
}

std::error_code EnsureUcanRuntimeDir(const std::string& dir) noexcept {
  if (dir.empty()) return std::make_error_code(std::errc::invalid_argument);
  if (::mkdir(dir.c_str(), 0700) != 0 && errno != EEXIST) {
    return {errno, std::generic_category()};
  }
  return VerifyUcanRuntimeDir(dir);
}

std::string UcanSocketPath(const std::string& dir) { return dir + "/" + ucan::kSocketName; }

std::string UcanTempRoot() {
  const char* tmp = std::getenv("TMPDIR");
  return tmp != nullptr && tmp[0] != '\0' ? std::string(tmp) : std::string("/tmp");
}

std::string CreateTempUcanRuntimeDir(const std::string& prefix) {
  std::string tmpl = UcanTempRoot() + "/" + prefix + "XXXXXX";
  std::vector<char> buf(tmpl.begin(), tmpl.end());
  buf.push_back('\0');
  if (::mkdtemp(buf.data()) == nullptr) {
    throw std::system_error(errno, std::generic_category(), "mkdtemp " + tmpl);
  }
  return std::string(buf.data());
}

std::vector<std::pair<std::string, std::string>> UcanChildEnvironment(
    const std::string& preload_library, const std::string& runtime_dir) {
  std::string preload = preload_library;
  if (const char* old = std::getenv("LD_PRELOAD"); old != nullptr && old[0] != '\0') {
    preload.append(":").append(old);  // not `":" + std::string(old)`: GCC 12 -Wrestrict (-O2)
  }
  std::string asan = "verify_asan_link_order=0";
  if (const char* old = std::getenv("ASAN_OPTIONS"); old != nullptr && old[0] != '\0') {
    asan = std::string(old).append(":").append(asan);
  }
  return {{"LD_PRELOAD", preload}, {"WHEELHIL_UCAN_DIR", runtime_dir}, {"ASAN_OPTIONS", asan}};
}

}  // namespace wheelhil::bus
