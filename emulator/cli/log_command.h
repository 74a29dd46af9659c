#pragma once
/// `wheelhil log convert IN OUT`: a CAN log from one format into another, each known by its
/// file name (.log candump -L, .asc Vector ASC, .blf Vector BLF; bus/vector_logs.h). Prints
/// how many frames it wrote. Thread-compatible.

#include <CLI/CLI.hpp>

#include <optional>
#include <string>

namespace wheelhil::emulator {

class LogCommand {
 public:
  /// Adds the `log` subcommand to `app` (call before parsing).
  explicit LogCommand(CLI::App& app);
  /// After parsing: the exit code when `log` ran, else nullopt. Input errors throw
  /// std::invalid_argument naming the file (main reports them, exit 2).
  std::optional<int> Run();

 private:
  CLI::App* log_ = nullptr;
  CLI::App* convert_ = nullptr;
  std::string in_;
  std::string out_;
};

}  // namespace wheelhil::emulator
