#pragma once
/// Everything a scenario injects, grouped the way the runner wires it: sensor faults by sensor
/// name (one SensorFaultInjector each), device faults by node name (one DeviceFaultInjector
/// each), frame faults (one FrameFaultFilter between the devices and the bus) and bus faults
/// (one FaultyCanBus around the CanBusModel). All instants are integer ns of virtual time.
/// A value type; thread-compatible.

#include <map>
#include <string>
#include <vector>

#include "emulator/faults/bus_faults.h"
#include "emulator/faults/device_faults.h"
#include "emulator/faults/fault_event.h"
#include "emulator/faults/frame_faults.h"
#include "emulator/faults/sensor_faults.h"

namespace wheelhil::emulator {

struct FaultSchedule {
  std::map<std::string, std::vector<SensorFault>, std::less<>> sensor;  ///< By sensor name.
  std::map<std::string, std::vector<DeviceFault>, std::less<>> device;  ///< By node name.
  std::vector<FrameFault> frame;
  std::vector<BusFault> bus;

  bool empty() const { return sensor.empty() && device.empty() && frame.empty() && bus.empty(); }
};

}  // namespace wheelhil::emulator
