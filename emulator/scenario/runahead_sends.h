#pragma once
/// What of the firmware's own sends may run through a runahead window (docs/virtual-time.md,
/// "Sends in a window"). A send can change what the firmware is handed next: its SYNC is
/// answered, a drive obeys its command, and any frame of its holds the bus and delays the
/// devices' frames. Two kinds of send cannot, and the firmware's library lets them through:
///   - foreseen: a frame it sent at least three times with the same bytes at the same spacing,
///     expected at the instants that follow (SendPatterns); the forecast holds it there, and
///     the library checks each is sent exactly so, at its instant, before any other frame;
///   - unforeseen but harmless: a standard data frame no device reads, sent where the forecast
///     bus has room for it after the arbitrations it loses (BusForecast::SendGaps).
/// The run takes each at the instant it was sent and checks the frames it then hands over are
/// the forecast's (a difference fails the run). Thread-compatible: the run's thread.

#include <bitset>
#include <cstdint>
#include <map>
#include <memory>
#include <utility>
#include <vector>

#include "bus/can_frame.h"
#include "emulator/devices/device.h"

namespace wheelhil::emulator::scenario {

/// Sends expected of the firmware, as (run instant ns, frame).
using ForeseenSends = std::vector<std::pair<std::int64_t, bus::CanFrame>>;

class SendPatterns {
 public:
  /// A frame the firmware sent at run instant t_ns.
  void Note(const bus::CanFrame& frame, std::int64_t t_ns);
  /// The sends expected in (now_ns, until_ns], on the grid now_ns + k * step_ns, ordered by
  /// instant and then as last sent; at most `max`. A frame whose next send was due by now_ns
  /// and did not come is no longer expected.
  ForeseenSends Foresee(std::int64_t now_ns, std::int64_t until_ns, std::int64_t step_ns,
                        std::size_t max);

 private:
  // How often the same bytes at the same spacing make a frame foreseen.
  static constexpr int kRepeats = 2;  // spacings: three sends
  struct Pattern {
    bus::CanFrame frame;
    std::int64_t last_ns = -1;
    std::int64_t period_ns = 0;
    int repeats = 0;        // equal spacings in a row with these bytes
    std::uint64_t seq = 0;  // the order of the last sends
  };
  std::map<std::uint32_t, Pattern> patterns_;  // by id, with extended and RTR bits
  std::uint64_t seq_ = 0;
};

/// Standard ids no device reads (Device::ReadsFrame).
std::bitset<2048> UnreadStandardIds(const std::vector<std::unique_ptr<Device>>& devices);

}  // namespace wheelhil::emulator::scenario
