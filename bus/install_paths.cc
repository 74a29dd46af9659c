#include "bus/install_paths.h"

#include <filesystem>
#include <system_error>

// Set by the top-level CMakeLists.txt from the GNUInstallDirs layout.
#ifndef WHEELHIL_BIN_TO_PRELOAD
#define WHEELHIL_BIN_TO_PRELOAD "../lib/wheelhil"
#endif
#ifndef WHEELHIL_BIN_TO_DATA
#define WHEELHIL_BIN_TO_DATA "../share/wheelhil"
#endif

namespace wheelhil::bus {

namespace fs = std::filesystem;

std::string RunningExecutableDir() {
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  return ec ? std::string(".") : exe.parent_path().string();
}

std::string InstalledDataDirFromBin() { return WHEELHIL_BIN_TO_DATA; }

std::string FindShippedDbcDir(const std::string& exe_dir) {
  for (const fs::path& dir : {fs::path(exe_dir) / ".." / ".." / "bus" / "dbc",
                              fs::path(exe_dir) / WHEELHIL_BIN_TO_DATA / "dbc"}) {
    std::error_code ec;
    if (fs::exists(dir / "wheelhil_fw.dbc", ec)) {
      const fs::path canonical = fs::canonical(dir, ec);
      return (ec ? dir.lexically_normal() : canonical).string();
    }
  }
  return {};
}

std::string FindShippedDataRoot(const std::string& exe_dir) {
  for (const fs::path& dir :
       {fs::path(exe_dir) / ".." / "..", fs::path(exe_dir) / WHEELHIL_BIN_TO_DATA}) {
    std::error_code ec;
    if (fs::is_regular_file(dir / "scenarios" / "platforms" / "diff2.yaml", ec)) {
      const fs::path canonical = fs::canonical(dir, ec);
      return (ec ? dir.lexically_normal() : canonical).string();
    }
  }
  return {};
}

std::string FindPreloadLibrary(const std::string& exe_dir, const std::string& file) {
  const fs::path build_tree = fs::path(exe_dir) / ".." / "lib" / file;
  std::error_code ec;
  if (fs::exists(build_tree, ec)) return build_tree.lexically_normal().string();
  return (fs::path(exe_dir) / WHEELHIL_BIN_TO_PRELOAD / file).lexically_normal().string();
}

}  // namespace wheelhil::bus
