#pragma once
/// The config file a run hands to the firmware as ${CONFIG}: the scenario's firmware config
/// with the scenario's overrides merged in (maps recursively, everything else replaced) and a
/// relative `dbc_dir` made relative to the config's folder. Nothing else is set: a firmware's
/// config says itself whether it produces SYNC (with `timing.sync_producer: emulator` the
/// scenario's overrides tell the reference firmware `sync.produce: false`). Throws
/// std::invalid_argument naming the file for a config or overrides that are not valid YAML.

#include <string>

namespace wheelhil::emulator::firmware {

/// The derived config as YAML text (a comment line names the source).
std::string DerivedWheelhilFwConfig(const std::string& config_path,
                                    const std::string& overrides_yaml);

}  // namespace wheelhil::emulator::firmware
