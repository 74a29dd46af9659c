#pragma once
/// The adapter for wheelhil's own reference firmware (`wheelhil-fw`) and nothing else: the
/// config file a run hands to it. The scenario's firmware config with the scenario's overrides
/// merged in (maps recursively, everything else replaced), a relative `dbc_dir` made relative
/// to the config's folder, and the keys only wheelhil-fw knows set for the run: `sync.produce:
/// false` (the emulator produces SYNC), `sync.period_s` (the scenario's SYNC period) and
/// `sync.deadline_s` (0 in lockstep: the next SYNC closes an incomplete cycle; the period in
/// real time), unless the run leaves them to the firmware (set_sync). Any other firmware gets its config file as it is. Throws std::invalid_argument
/// naming the file for a config or overrides that are not valid YAML.

#include <string>

namespace wheelhil::emulator::firmware {

struct WheelhilFwRunSettings {
  double sync_period_s = 0.01;
  /// False: the sync.* keys stay as the config has them (a firmware on the virtual clock that
  /// produces SYNC itself runs with its own settings).
  bool set_sync = true;
};

/// The derived config as YAML text (a comment line names the source).
std::string DerivedWheelhilFwConfig(const std::string& config_path,
                                    const std::string& overrides_yaml,
                                    const WheelhilFwRunSettings& run);

}  // namespace wheelhil::emulator::firmware
