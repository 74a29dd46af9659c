#pragma once
/// The device set of paper 002 as it appears on the bus, for the real-time workload of `wheelhil
/// bench`: per 1 ms cycle a SYNC (0x080, the master's), the TPDO1 of three CiA 406 encoder nodes
/// (1..3, transmission type 1, answering the SYNC), one ACC4_Data frame with the four
/// accelerometer channels (bus/dbc/wheelhil_accel4.dbc, counter and checksum), and every
/// imu_every_cycles cycles the three Bosch MM5.10 frames (bus/dbc/bosch_mm5_10.dbc). Every frame
/// is built by the device classes (CanopenEncoderNode over DbcCia406Codec, EncoderModel,
/// AccelerometerModel, GyroModel) and the DBC codec. The body follows the paper's experiment
/// (900 mm in x at 100 mm/s, trapezoid with 0.5 m/s^2 ramps; repeats every 10 s).
///
/// A frame's nominal instant is its start of frame on a modelled classic CAN bus
/// (CanBusModel, default 1 Mbit/s, exact stuffing): what a real bus would do with these nodes.
/// Virtual time only, no threads, no I/O. Thread-compatible.

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "emulator/realtime/realtime_pacer.h"

namespace wheelhil::emulator::bench {

struct Paper002DeviceSetOptions {
  /// Repository root (for bus/dbc/*.dbc).
  std::string source_dir;
  std::int64_t cycle_ns = 1'000'000;        ///< SYNC / accelerometer period.
  int imu_every_cycles = 10;                ///< MM5.10 frames every n cycles (10 ms).
  std::uint32_t bitrate_bps = 1'000'000;    ///< Modelled bus.
  std::int64_t response_delay_ns = 20'000;  ///< Encoder SYNC -> TPDO.
  std::uint64_t seed = 1;                   ///< Sensor noise.
};

class Paper002DeviceSet {
 public:
  /// Loads the DBC files and builds the devices; throws std::invalid_argument on a bad file or
  /// option.
  explicit Paper002DeviceSet(const Paper002DeviceSetOptions& options);
  ~Paper002DeviceSet();
  Paper002DeviceSet(const Paper002DeviceSet&) = delete;
  Paper002DeviceSet& operator=(const Paper002DeviceSet&) = delete;

  /// Appends the frames whose start of frame falls in the next cycle (in bus order, nominal
  /// instants non-decreasing across calls); the first cycle starts at nominal 0.
  void NextCycle(std::vector<realtime::PacedFrame>& out);

  std::int64_t cycle_ns() const noexcept;
  /// Cycles produced so far.
  std::int64_t cycles() const noexcept;
  /// Frames the modelled bus refused (full queue) or the codec could not build.
  std::uint64_t problems() const noexcept;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace wheelhil::emulator::bench
