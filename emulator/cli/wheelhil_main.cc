// `wheelhil`: the command-line front end of the emulator. Each subcommand lives with the module
// that owns it; this file only wires them together. Exit codes: 0 success, 1 failure, 2 usage or
// input error.

#include <fmt/format.h>
#include <CLI/CLI.hpp>
#include <yaml-cpp/yaml.h>

#include <exception>
#include <new>
#include <stdexcept>

#include "emulator/bullet_precision.h"
#include "emulator/cli/bench_command.h"
#include "emulator/cli/bus_commands.h"
#include "emulator/cli/campaign_command.h"
#include "emulator/cli/completion_command.h"
#include "emulator/cli/log_command.h"
#include "emulator/cli/new_command.h"
#include "emulator/cli/run_command.h"
#include "emulator/cli/schema_command.h"

namespace {

int RunVersion() {
  fmt::print("wheelhil {}\n", WHEELHIL_VERSION);
  fmt::print("bullet: {} precision (compiled {})\n",
             wheelhil::emulator::LinkedBulletIsDoublePrecision() ? "double" : "single",
             wheelhil::emulator::CompiledWithDoublePrecision() ? "double" : "single");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (auto code = wheelhil::emulator::BusCommands::RunExecIfRequested(argc, argv)) return *code;
  CLI::App app{"wheelhil - hardware-in-the-loop emulator for wheeled mobile robots"};
  app.require_subcommand(0, 1);
  auto* version = app.add_subcommand("version", "Print the version and build facts");
  wheelhil::emulator::BusCommands bus_commands(app);
  wheelhil::emulator::BenchCommand bench_command(app);
  wheelhil::emulator::CampaignCommand campaign_command(app);
  wheelhil::emulator::LogCommand log_command(app);
  wheelhil::emulator::NewCommand new_command(app);
  wheelhil::emulator::SchemaCommand schema_command(app);
  wheelhil::emulator::RunCommand run_command(app);
  wheelhil::emulator::CompletionCommand completion_command(app);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? 0 : 2;
  }
  if (version->parsed()) return RunVersion();
  if (app.get_subcommands().empty()) {  // `wheelhil` alone: what it can do
    fmt::print("{}", app.help());
    return 0;
  }
  // The commands report their own errors; this is the boundary for what escapes them, so that
  // no input ends in std::terminate. Input errors (the loaders' std::invalid_argument, which
  // carry file:line:col, and yaml-cpp's own) exit 2; anything else is a fault of ours.
  try {
    if (auto code = bus_commands.Run()) return *code;
    if (auto code = bench_command.Run()) return *code;
    if (auto code = campaign_command.Run()) return *code;
    if (auto code = log_command.Run()) return *code;
    if (auto code = new_command.Run()) return *code;
    if (auto code = schema_command.Run()) return *code;
    if (auto code = run_command.Run()) return *code;
    if (auto code = completion_command.Run()) return *code;
  } catch (const std::invalid_argument& e) {
    fmt::print(stderr, "wheelhil: {}\n", e.what());
    return 2;
  } catch (const YAML::Exception& e) {
    if (e.mark.is_null()) {
      fmt::print(stderr, "wheelhil: YAML error: {}\n", e.msg);
    } else {
      fmt::print(stderr, "wheelhil: YAML error at line {}, column {}: {}\n", e.mark.line + 1,
                 e.mark.column + 1, e.msg);
    }
    return 2;
  } catch (const std::bad_alloc&) {
    fmt::print(stderr, "wheelhil: out of memory\n");
    return 1;
  } catch (const std::exception& e) {
    fmt::print(stderr, "wheelhil: internal error: {}\n", e.what());
    return 1;
  }
  return 2;
}
