#pragma once
/// `wheelhil completion bash`: a bash completion script generated from the command-line
/// definition itself (every subcommand, option and option value list CLI11 knows), so it cannot
/// drift from the program. Installed as <datadir>/bash-completion/completions/wheelhil.
/// Thread-compatible.

#include <CLI/CLI.hpp>

#include <optional>
#include <string>

namespace wheelhil::emulator {

/// The bash completion script for `app` and everything registered under it; `program` is the
/// command name it completes.
std::string BashCompletionScript(const CLI::App& app, const std::string& program);

class CompletionCommand {
 public:
  /// Registers `completion`; `root` is read when the command runs, so register this first or
  /// last, it sees every subcommand either way.
  explicit CompletionCommand(CLI::App& root);
  std::optional<int> Run();

 private:
  CLI::App& root_;
  CLI::App* completion_ = nullptr;
  std::string shell_ = "bash";
};

}  // namespace wheelhil::emulator
