#pragma once
/// `wheelhil bus up|down|list NAME` and `wheelhil exec [--bus NAME | --runtime-dir DIR] --
/// PROGRAM ARGS...`: the userspace CAN bus daemon and running unmodified SocketCAN programs on
/// it (LD_PRELOAD of libwheelhil_ucan.so of this build tree or install, or $WHEELHIL_UCAN_LIB).
/// The runtime directory comes from the environment (bus/ucan_runtime_dir.h), or for exec from
/// --runtime-dir (a run's private bus).
/// Thread-compatible; exec replaces the process.

#include <CLI/CLI.hpp>

#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace wheelhil::emulator {

class BusCommands {
 public:
  /// Adds the `bus` and `exec` subcommands to `app` (call before parsing).
  explicit BusCommands(CLI::App& app);
  /// After parsing: the exit code when one of these subcommands ran, else nullopt.
  std::optional<int> Run();
  /// Call first thing in main(): handles `wheelhil exec ...` itself (the program's arguments
  /// must not go through CLI11) and returns its exit code (exec replaces the process on
  /// success); nullopt for any other command line.
  static std::optional<int> RunExecIfRequested(int argc, char** argv);

 private:
  CLI::App* bus_ = nullptr;
  CLI::App* up_ = nullptr;
  CLI::App* down_ = nullptr;
  CLI::App* list_ = nullptr;
  CLI::App* exec_ = nullptr;
  std::string up_name_;
  std::string down_name_;
  std::vector<std::string> exec_buses_;
  std::string exec_runtime_dir_;
};

/// Makes sure a daemon broker serves `runtime_dir` (starting one, detached, if none does) and
/// that it has bus `name`. Returns the bus's interface index; throws std::runtime_error with a
/// fixable message on failure.
int EnsureUcanBus(const std::string& runtime_dir, const std::string& name);

/// Environment for a child process that must see the buses of `runtime_dir` through the plain
/// SocketCAN API: bus::UcanChildEnvironment with UcanPreloadLibraryPath(). Set these in the child
/// before exec (what `wheelhil exec` does).
std::vector<std::pair<std::string, std::string>> UcanChildEnvironment(
    const std::string& runtime_dir);

/// Path of libwheelhil_ucan.so for LD_PRELOAD: $WHEELHIL_UCAN_LIB, else the one of the build
/// tree or the install this executable belongs to (bus/install_paths.h).
std::string UcanPreloadLibraryPath();

}  // namespace wheelhil::emulator
