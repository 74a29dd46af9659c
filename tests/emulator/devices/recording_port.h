#pragma once
// A DevicePort for tests that poll a device directly: it keeps every frame the device sends.

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "emulator/devices/device.h"

namespace wheelhil::emulator::testing {

class RecordingPort final : public DevicePort {
 public:
  void Send(std::vector<NodeFrame> frames, bool) override {
    for (auto& f : frames) sent.push_back(f);
  }
  void CountSilenced(std::size_t) override {}
  void Event(nlohmann::json e) override { events.push_back(std::move(e)); }
  double MotionSeconds(std::int64_t t_ns) const override { return 1e-9 * static_cast<double>(t_ns); }
  void Fail(std::string) override {}
  std::vector<NodeFrame> sent;
  std::vector<nlohmann::json> events;
};

}  // namespace wheelhil::emulator::testing
