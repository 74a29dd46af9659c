#pragma once
/// `wheelhil new DIR`: a project skeleton for a user's own robot and firmware, which runs at
/// once with the reference firmware standing in for theirs: platform.yaml (paper 000's
/// differential-drive robot, to edit or to replace by one that reads their URDF or SDF),
/// scenario.yaml (a 2 m drive that runs `firmware.command`), firmware.yaml (the reference
/// firmware's configuration), outputs.yaml (which frames of which DBC carry the firmware's
/// estimate), campaign.yaml (the scenario over ten seeds), smoke.list (the CI smoke suite) and
/// a README.md saying what to change first. With --urdf FILE (or --sdf FILE [--model NAME])
/// platform.yaml reads the user's robot description instead: its two driven wheels are the
/// continuous joints with a fixed horizontal axle across the robot, its casters those below a
/// swivel (docs/platforms-from-urdf-sdf.md), and the scenario tells the firmware their track,
/// radius and spin signs. Each YAML file opens with the line that makes an
/// editor's YAML language server check it against its JSON Schema as it is typed
/// (docs/schemas.md). The shipped files it starts from come from the
/// source tree next to the build directory, else the installed data directory. DIR must be new
/// or empty (--force: write into it anyway, replacing those files). Thread-compatible.

#include <CLI/CLI.hpp>

#include <optional>
#include <string>

namespace wheelhil::emulator {

class NewCommand {
 public:
  /// Adds the `new` subcommand to `app` (call before parsing).
  explicit NewCommand(CLI::App& app);
  /// After parsing: the exit code when `new` ran, else nullopt. Input errors throw
  /// std::invalid_argument (main reports them, exit 2).
  std::optional<int> Run();

 private:
  CLI::App* new_ = nullptr;
  std::string dir_;
  std::string urdf_;
  std::string sdf_;
  std::string model_;
  bool force_ = false;
};

}  // namespace wheelhil::emulator
