#include "emulator/cli/new_command.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "bus/install_paths.h"
#include "emulator/platforms/robot_description.h"

namespace wheelhil::emulator {
namespace {

namespace fs = std::filesystem;

// The shipped scenarios: next to the build directory that holds this executable (a build
// tree), else the installed data directory.
fs::path ShippedScenarios() {
  const std::string bin = bus::RunningExecutableDir();
  const std::string root = bus::FindShippedDataRoot(bin);
  if (root.empty()) {
    throw std::invalid_argument(fmt::format(
        "new: the shipped scenarios (scenarios/platforms/diff2.yaml) are not next to {} nor in "
        "its installed data directory: is wheelhil installed whole?",
        bin));
  }
  return fs::path(root) / "scenarios";
}

// The JSON Schemas (docs/schemas in a source tree, <datadir>/wheelhil/schemas installed), or
// empty when neither is there.
fs::path SchemaDir(const fs::path& scenarios) {
  for (const fs::path& candidate :
       {scenarios / ".." / "docs" / "schemas", scenarios / ".." / "schemas"}) {
    std::error_code ec;
    if (fs::is_regular_file(candidate / "scenario.schema.json", ec)) {
      return fs::canonical(candidate, ec);
    }
  }
  return {};
}

// The first line of a file of `kind`: the YAML language server checks it against its schema
// as it is typed (docs/schemas.md).
std::string SchemaLine(const fs::path& schemas, const std::string& kind) {
  if (schemas.empty()) return {};
  return fmt::format("# yaml-language-server: $schema={}\n",
                     (schemas / (kind + ".schema.json")).string());
}

std::string Read(const fs::path& p) {
  std::ifstream in(p);
  if (!in) throw std::invalid_argument(fmt::format("new: cannot read {}", p.string()));
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// Lines of `text` from the first that starts with `from` (the file's own header comment goes).
std::string From(const std::string& text, const std::string& from) {
  const std::size_t at = text.find("\n" + from);
  return at == std::string::npos ? text : text.substr(at + 1);
}

std::string Replace(std::string text, const std::string& what, const std::string& with) {
  const std::size_t at = text.find(what);
  if (at != std::string::npos) text.replace(at, what.size(), with);
  return text;
}

// Drops every line that contains `what`.
std::string DropLines(const std::string& text, const std::string& what) {
  std::istringstream in(text);
  std::string out, line;
  while (std::getline(in, line)) {
    if (line.find(what) == std::string::npos) out += line + "\n";
  }
  return out;
}

// What the scenario tells the reference firmware about the drive (paper 000's robot, or the
// user's description).
struct Drive {
  double track_m = 0.32;
  double wheel_radius_m = 0.075;
  int left_sign = 1;
  int right_sign = 1;
};

// platform.yaml that reads the user's URDF or SDF: what the description cannot say is paper
// 000's robot's, to be set; the wheels from the description's wheel joints.
std::string DescribedPlatform(const std::string& name, const fs::path& dir, const fs::path& shipped,
                              const std::string& urdf, const std::string& sdf,
                              const std::string& model, Drive* drive) {
  const std::string file = urdf.empty() ? sdf : urdf;
  const fs::path path = fs::absolute(file).lexically_normal();
  bool base_has_box = false;
  const std::vector<platforms::WheelJoint> joints =
      platforms::FindWheelJoints(path.string(), model, &base_has_box);
  std::vector<const platforms::WheelJoint*> across, casters;
  std::string list;
  for (const auto& j : joints) {
    list += (list.empty() ? "" : ", ") + j.joint;
    if (j.below_moving_joint) {
      casters.push_back(&j);
    } else if (std::abs(j.axis.y()) > 0.99) {
      across.push_back(&j);
    }
  }
  if (across.size() != 2 || across[0]->centre_m.y() * across[1]->centre_m.y() >= 0) {
    throw std::invalid_argument(fmt::format(
        "new: {} has {} wheel joints with a fixed axle across the robot (its wheel joints: {}): "
        "wheelhil new starts a differential-drive robot from two, one on each side. Run it "
        "without --{} and make platform.yaml read your file by hand "
        "(docs/platforms-from-urdf-sdf.md)",
        file, across.size(), list.empty() ? "none" : list, urdf.empty() ? "sdf" : "urdf"));
  }
  if (across[0]->centre_m.y() < across[1]->centre_m.y()) std::swap(across[0], across[1]);
  const platforms::WheelJoint& left = *across[0];
  const platforms::WheelJoint& right = *across[1];
  drive->track_m = std::round((left.centre_m.y() - right.centre_m.y()) * 1e9) / 1e9;
  drive->wheel_radius_m = left.radius_m;
  drive->left_sign = left.axis.y() > 0 ? 1 : -1;
  drive->right_sign = right.axis.y() > 0 ? 1 : -1;
  const std::string diff2 = Read(shipped / "platforms" / "diff2.yaml");
  const std::size_t s0 = diff2.find("\nsolver:");
  const std::size_t s1 = diff2.find("\n# As built");
  const std::string defaults =
      s0 == std::string::npos || s1 == std::string::npos ? "" : diff2.substr(s0 + 1, s1 - s0);
  std::string out = fmt::format(
      "# {0}: your robot from {1} (docs/platforms-from-urdf-sdf.md). The chassis and the wheels'\n"
      "# places, axles, radii, masses and inertias come from there; this file says what it\n"
      "# cannot. The numbers below are paper 000's robot's (scenarios/platforms/diff2.yaml): set\n"
      "# yours. wheel_defaults' radius, inertia and hub mass count only where {1} has none.\n"
      "name: {0}\n"
      "{2}: {3}\n",
      name, path.filename().string(), urdf.empty() ? "sdf" : "urdf",
      fs::relative(path, dir).string());
  if (!model.empty()) out += fmt::format("model: {}\n", model);
  if (!base_has_box) {
    out +=
        "chassis:\n  half_extents_m: [0.225, 0.175, 0.075]  # its base link has no collision box\n";
  }
  out += defaults;
  out += "wheels:\n";
  out +=
      fmt::format("  - {{name: left, joint: {}, kind: conventional, motor: {{}}}}\n", left.joint);
  out +=
      fmt::format("  - {{name: right, joint: {}, kind: conventional, motor: {{}}}}\n", right.joint);
  for (std::size_t i = 0; i < casters.size(); ++i) {
    out +=
        fmt::format("  - {{name: caster_{}, joint: {}, kind: caster}}\n", i + 1, casters[i]->joint);
  }
  out += fmt::format(
      "kinematics:\n"
      "  type: diff_drive\n"
      "  track_m: {}  # from the two wheel joints\n"
      "  wheel_radius_m: {}\n"
      "sensors:\n"
      "  - {{name: gyro, kind: gyro, mount_m: [0.0, 0.0, 0.05], axis: [0, 0, 1]}}\n",
      drive->track_m, drive->wheel_radius_m);
  return out;
}

std::string Scenario(const std::string& name, const Drive& drive) {
  return fmt::format(
      R"(# {0}: your firmware on your robot (docs/scenarios.md). `wheelhil run scenario.yaml`.
# Starts as paper 000's robot driving 2 m with the reference firmware (wheelhil-fw) in the loop;
# change firmware.command to your firmware's (any program that speaks SocketCAN; the bus name is
# ${{CAN}}), outputs to the frames your firmware sends its estimate in, and platform to your robot.
name: {0}
description: "{0}: 2 m straight at 0.25 m/s on a dry floor"
seed: 1
platform: platform.yaml
terrain:
  friction: {{mu_peak: 0.8, mu_slide: 0.7}}
motion:
  - {{type: hold, duration_s: 0.5}}
  - {{type: trapezoid, direction: [1, 0, 0], distance: 2.0, speed: 0.25, accel: 0.5}}
  - {{type: hold, duration_s: 0.5}}
sensors:
  encoders:
    lines_per_rev: 500
    quadrature_x4: true
    nodes:
      - {{wheel: left, node_id: 1}}
      - {{wheel: right, node_id: 2}}
  gyro:
    rate_hz: 100
    noise_density_rad_s_sqrt_hz: 0.0032
  bus: {{bitrate_bps: 500000, heartbeat_ms: 100}}
firmware:
  command: "${{BIN}}/wheelhil-fw --can ${{CAN}} --config ${{CONFIG}} --quiet"
  config: firmware.yaml
  outputs: outputs.yaml
  overrides:
    paper000: {{track_width_m: {1}, wheel_radius_m: {2}, counts_per_rev: 2000,
               left: {{node_id: 1, sign: {3}}}, right: {{node_id: 2, sign: {4}}}}}
timing:
  mode: lockstep
  sync_period_s: 0.25
  physics_rate_hz: 1000
  timeout_s: 5
expectations:
  - {{metric: pose.final_position_error_m, "<": 0.05}}
  - {{metric: pose.distance_m, ">=": 1.5}}
)",
      name, drive.track_m, drive.wheel_radius_m, drive.left_sign, drive.right_sign);
}

std::string Campaign(const std::string& name) {
  return fmt::format(R"(# {0}: the scenario over ten seeds (docs/campaigns.md).
# `wheelhil campaign campaign.yaml -j 2`; --shard K/N splits it over machines.
campaign: {0}_seeds
description: "{0}: scenario.yaml, ten seeds"
base: scenario.yaml
sampling: grid
seed: 1
repeats: 10
timeout_s: 120
parameters:
  - path: motion[1].speed
    values: [0.25]
pass:
  verdict: false
  run:
    - {{metric: pose.final_position_error_m, max: 0.05}}
  campaign:
    - {{metric: pose.final_position_error_m, max: 0.05, fraction: 0.9}}
rank_by: pose.final_position_error_m
)",
                     name);
}

std::string Readme(const std::string& name) {
  return fmt::format(R"(# {0}

A wheelhil project: your robot and your firmware, tested with no robot at hand.

    wheelhil run scenario.yaml --out run       # one run; artefacts (report.html, can.log, ...) in run/
    wheelhil smoke --scenarios smoke.list      # the CI smoke suite (--junit out.xml for CI)
    wheelhil campaign campaign.yaml -j 2       # the scenario over ten seeds

It runs as it is, with the reference firmware (wheelhil-fw) standing in for yours. Then:

1. `scenario.yaml`, `firmware.command`: your firmware's command line (`${{CAN}}` is the bus to
   open, `${{CONFIG}}` the config file, `${{BIN}}` wheelhil's own programs). docs/firmware.md,
   docs/virtual-time.md.
2. `outputs.yaml`: the frames your firmware sends its estimate in, from your DBC
   (docs/own-hardware.md).
3. `platform.yaml`: your robot. Edit the numbers, or make it read your URDF or SDF
   (`urdf: robot.urdf`, a wheel's `joint:`; docs/platforms-from-urdf-sdf.md).
4. `scenario.yaml`: sensors and devices from your DBC and EDS files (`devices:`), faults,
   terrain, expectations (docs/scenarios.md, docs/faults.md).
)",
                     name);
}

}  // namespace

NewCommand::NewCommand(CLI::App& app) {
  new_ = app.add_subcommand("new", "A project skeleton for your robot and firmware (runs at once)");
  new_->add_option("DIR", dir_, "Directory to create (new or empty)")->required();
  new_->add_flag("--force", force_, "Write into DIR even if it holds files (replacing ours)");
  auto* urdf = new_->add_option("--urdf", urdf_, "platform.yaml reads this URDF (your robot)");
  auto* sdf = new_->add_option("--sdf", sdf_, "platform.yaml reads this SDF file (your robot)");
  urdf->excludes(sdf);
  new_->add_option("--model", model_, "With --sdf: the model to read (a world of several)")
      ->needs(sdf);
}

std::optional<int> NewCommand::Run() {
  if (!new_->parsed()) return std::nullopt;
  const fs::path dir = fs::absolute(dir_).lexically_normal();
  std::error_code ec;
  if (fs::exists(dir, ec) && !fs::is_directory(dir, ec)) {
    throw std::invalid_argument(fmt::format("new: {} exists and is not a directory", dir_));
  }
  if (fs::is_directory(dir, ec) && !fs::is_empty(dir, ec) && !force_) {
    throw std::invalid_argument(
        fmt::format("new: {} is not empty (--force writes into it, replacing the skeleton's "
                    "files)",
                    dir_));
  }
  const fs::path shipped = ShippedScenarios();
  const fs::path schemas = SchemaDir(shipped);
  std::string name = dir.filename().string();
  if (name.empty()) name = "my_robot";
  Drive drive;
  const std::string platform =
      !urdf_.empty() || !sdf_.empty()
          ? SchemaLine(schemas, "platform") +
                DescribedPlatform(name, dir, shipped, urdf_, sdf_, model_, &drive)
          : SchemaLine(schemas, "platform") +
                "# Your robot (docs/physics.md, \"Platform files\"): paper 000's "
                "differential-drive robot "
                "to\n"
                "# start from. Or read your URDF or SDF: docs/platforms-from-urdf-sdf.md.\n" +
                Replace(
                    DropLines(From(Read(shipped / "platforms" / "diff2.yaml"), "name:"), "mesh:"),
                    "name: diff2", "name: " + name);
  const std::vector<std::pair<std::string, std::string>> files = {
      {"platform.yaml", platform},
      {"scenario.yaml", SchemaLine(schemas, "scenario") + Scenario(name, drive)},
      {"firmware.yaml",
       SchemaLine(schemas, "firmware-config") +
           "# The reference firmware's configuration (docs/firmware.md); yours reads its own.\n" +
           Read(shipped / "firmware" / "paper000_diff_drive.yaml")},
      {"outputs.yaml",
       SchemaLine(schemas, "outputs") +
           "# Which frames of which DBC carry the firmware's estimate (docs/own-hardware.md): the\n"
           "# reference firmware's. Point dbc: at yours and name your messages and signals.\n" +
           Read(shipped / "outputs" / "wheelhil_fw.yaml")},
      {"campaign.yaml", SchemaLine(schemas, "campaign") + Campaign(name)},
      {"smoke.list", "# The CI smoke suite (docs/ci.md): one scenario a line.\nscenario.yaml\n"},
      {"README.md", Readme(name)},
  };
  fs::create_directories(dir, ec);
  if (ec) {
    throw std::invalid_argument(fmt::format("new: cannot create {}: {}", dir_, ec.message()));
  }
  for (const auto& [file, text] : files) {
    std::ofstream out(dir / file);
    out << text;
    if (!out)
      throw std::invalid_argument(fmt::format("new: cannot write {}", (dir / file).string()));
  }
  fmt::print("wheelhil new: {} ({} files); next: wheelhil run {}\n", dir.string(), files.size(),
             (dir / "scenario.yaml").string());
  return 0;
}

}  // namespace wheelhil::emulator
