#pragma once
/// Paper 002's four single-axis accelerometers served as one CAN node
/// (bus/dbc/wheelhil_accel4.dbc, ACC4_Data 0x170): every sample period all four sensors are
/// sampled at the same instant and sent in one 8-byte frame, four 14-bit channels in m/s^2
/// (0.0047884 m/s^2 per bit, saturated at -8192 / +8191), a 4-bit rolling counter (+1 mod 16
/// per frame) and a 4-bit XOR-of-nibbles checksum (frame_checksum.h kXor), everything encoded
/// through the DBC codec. The sample period is the accelerometers' rate (1 kHz in the paper; the
/// DBC's GenMsgCycleTime is 1 ms). Paper002AccelParams gives the paper's eq. 3 mounting.
/// Pure state machine in virtual time (integer ns); the caller supplies the true body motion at
/// each sample instant (next_sample_ns()). Sensor faults go between SampleSensors and
/// EncodeSample. Thread-compatible.

#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include "bus/can_frame.h"
#include "bus/dbc.h"
#include "emulator/sensors/accelerometer_model.h"

namespace wheelhil::emulator {

/// The paper 002 eq. 3 set at radius R: a1 along +x at (0, R, 0), a2 along +y at (R, 0, 0),
/// a3 along -y at (-R, 0, 0), a4 along -x at (0, -R, 0), so a1 = ax - ath R, a2 = ay + ath R,
/// a3 = -ay + ath R, a4 = -ax - ath R (plus the centripetal terms a real sensor sees). Seeds are
/// seed, seed+1, seed+2, seed+3; noise and errors zero (set them afterwards).
std::array<AccelerometerParams, 4> Paper002AccelParams(double radius_m, double rate_hz,
                                                       std::uint64_t seed);

class Accel4Node {
 public:
  /// Throws std::invalid_argument when the database lacks ACC4_Data or its signals, a sensor has
  /// not exactly one axis, the four rates differ, or the period is not a whole number of ns > 0.
  Accel4Node(std::shared_ptr<const bus::DbcDatabase> accel4_dbc,
             const std::array<AccelerometerParams, 4>& sensors, std::int64_t first_sample_ns);

  /// The instant of the next sample.
  std::int64_t next_sample_ns() const { return next_ns_; }
  std::int64_t period_ns() const { return period_ns_; }

  /// Samples the four sensors (m/s^2) for the sample at next_sample_ns(); does not advance.
  std::array<double, 4> SampleSensors(const BodyKinematics& k);
  /// Encodes one frame from four readings (m/s^2) with the next counter value and the
  /// checksum, and advances to the next sample instant. Returns false when a channel had to be
  /// saturated (the frame is still built, saturated).
  bool EncodeSample(const std::array<double, 4>& a_m_s2, bus::CanFrame& out) noexcept;
  /// SampleSensors + EncodeSample.
  bool Sample(const BodyKinematics& k, bus::CanFrame& out);

  const bus::DbcMessage& message() const { return *msg_; }
  /// A copy shares its four sensor models (their noise streams) with the node it was copied
  /// from, so that copying never reads them (a worker may be sampling them): this gives the
  /// node a copy of its own, for a copy that samples.
  void OwnSensors() { sensors_ = std::make_shared<std::vector<AccelerometerModel>>(*sensors_); }
  std::uint64_t samples() const { return samples_; }
  std::uint64_t saturated() const { return saturated_; }

 private:
  std::shared_ptr<const bus::DbcDatabase> dbc_;
  const bus::DbcMessage* msg_ = nullptr;
  std::array<const bus::DbcSignal*, 4> channels_{};
  const bus::DbcSignal* counter_ = nullptr;
  const bus::DbcSignal* checksum_ = nullptr;
  std::shared_ptr<std::vector<AccelerometerModel>> sensors_;
  std::int64_t period_ns_ = 0;
  std::int64_t next_ns_ = 0;
  std::uint64_t counter_value_ = 0;
  std::uint64_t samples_ = 0;
  std::uint64_t saturated_ = 0;
};

}  // namespace wheelhil::emulator
