#pragma once
/// Builds a scenario's CAN devices. The one place that names concrete device classes: each kind
/// has a builder that reads its part of the scenario file. Today's `sensors:` block gives, in
/// bus order, one "cia406_encoder" per `sensors.encoders` entry (CiA 406 node over
/// bus/dbc/cia406_encoder.dbc with an incremental encoder on its wheel), the "mm5_10" yaw-rate
/// node when `sensors.gyro` (bus/dbc/bosch_mm5_10.dbc), the "accel4" node when
/// `sensors.accel4` (bus/dbc/wheelhil_accel4.dbc) and a "dbc_imu" (a user's IMU from its own
/// DBC file) for `sensors.dbc_imu`; then the `devices:` list in its order ("dbc" and "mm5_10":
/// DbcDevice, "canopen_cia406": the encoder node, from its EDS when it has one). Every random
/// stream is seeded from the run seed. Throws std::invalid_argument naming the file for a DBC file that cannot be read.

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "emulator/devices/device.h"
#include "emulator/scenario/scenario.h"

namespace wheelhil::emulator::scenario {

struct DeviceBuildContext {
  const Scenario& scenario;
  std::uint64_t seed = 1;
  std::string dbc_dir;
  /// The vehicle's wheels at power-on (encoders start counting from their angle).
  const std::vector<physics::WheelTruth>& wheels;
};

/// Every device of the scenario, in bus order.
std::vector<std::unique_ptr<Device>> BuildScenarioDevices(const DeviceBuildContext& context);

}  // namespace wheelhil::emulator::scenario
