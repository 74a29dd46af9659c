// `wheelhil`: the command-line front end of the emulator. Each subcommand lives with the module
// that owns it; this file only wires them together. Exit codes: 0 success, 1 failure, 2 usage or
// input error.

#include <fmt/format.h>
#include <CLI/CLI.hpp>

#include "emulator/bullet_precision.h"
#include "emulator/cli/bench_command.h"
#include "emulator/cli/bus_commands.h"
#include "emulator/cli/campaign_command.h"
#include "emulator/cli/run_command.h"

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
  app.require_subcommand(1);
  auto* version = app.add_subcommand("version", "Print the version and build facts");
  wheelhil::emulator::BusCommands bus_commands(app);
  wheelhil::emulator::BenchCommand bench_command(app);
  wheelhil::emulator::CampaignCommand campaign_command(app);
  wheelhil::emulator::RunCommand run_command(app);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? 0 : 2;
  }
  if (version->parsed()) return RunVersion();
  if (auto code = bus_commands.Run()) return *code;
  if (auto code = bench_command.Run()) return *code;
  if (auto code = campaign_command.Run()) return *code;
  if (auto code = run_command.Run()) return *code;
  return 2;
}
