// `wheelhil-fw --can IFACE --config FILE.yaml`: the reference estimator firmware. It talks plain
// SocketCAN only; nothing of emulator/ is linked in.

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include <stdexcept>

#include "firmware_stub/fw_config.h"

int main(int argc, char** argv) {
  CLI::App app{"wheelhil-fw - reference estimator firmware over SocketCAN"};
  std::string iface;
  std::string config_path;
  app.add_option("--can", iface, "CAN interface (vcan0, can0, ucan0, ...)")->required();
  app.add_option("--config", config_path, "Firmware config YAML")->required();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? 0 : 2;
  }
  try {
    const auto cfg = wheelhil::fw::LoadFwConfig(config_path);
    fmt::print(stderr, "wheelhil-fw: estimator {} on {}: the estimator loop is not built yet\n",
               wheelhil::fw::EstimatorName(cfg.estimator), iface);
    return 1;
  } catch (const std::invalid_argument& e) {
    fmt::print(stderr, "wheelhil-fw: {}\n", e.what());
    return 2;
  }
}
