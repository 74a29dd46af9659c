#pragma once
/// A generic IMU node whose frames are defined entirely by a DBC message set, for users whose
/// IMU is not the Bosch MM5.10. The configuration names, per quantity (rate x/y/z, acceleration
/// x/y/z, body frame), the message and signal carrying it; the physical unit comes from the DBC
/// signal's unit string:
///   rates  "deg/s", "°/s", "dps"  or  "rad/s";
///   accel  "g"                   or  "m/s^2", "m/s2", "m/s²".
/// Each configured message is sent every GenMsgCycleTime ms (required, > 0), the first one at
/// first_sample_ns, with optional rolling counter (+1 mod 2^n per frame of that message) and
/// checksum signals (frame_checksum.h: XOR / sum / CRC-8 SAE J1850, computed last, over the
/// payload with the checksum bits zero). Values beyond a signal's raw range are sent saturated and
/// counted. Signals of a message that carry nothing configured are sent as raw 0.
/// Pure state machine in virtual time (integer ns): the caller asks NextEventNs(), computes the
/// measured IMU values (sensor models + sensor faults, SI units) for that instant and calls
/// Poll(t, sample). Thread-compatible.

#include <Eigen/Core>

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "bus/can_frame.h"
#include "bus/dbc.h"
#include "emulator/devices/canopen_encoder_node.h"
#include "emulator/devices/frame_checksum.h"

namespace wheelhil::emulator {

enum class ImuQuantity : std::uint8_t { kRateX, kRateY, kRateZ, kAccelX, kAccelY, kAccelZ };

/// "rate_x", "rate_y", "rate_z", "accel_x", "accel_y", "accel_z"; nullopt otherwise.
std::optional<ImuQuantity> ParseImuQuantity(std::string_view name) noexcept;

struct DbcImuChannel {
  ImuQuantity quantity = ImuQuantity::kRateZ;
  std::string message;  ///< DBC message name.
  std::string signal;   ///< DBC signal name in that message.
};

struct DbcImuMessageOptions {
  std::string message;          ///< DBC message name.
  std::string counter_signal;   ///< Empty: no rolling counter.
  std::string checksum_signal;  ///< Empty: no checksum.
  ChecksumKind checksum = ChecksumKind::kXor;
};

struct DbcImuConfig {
  std::vector<DbcImuChannel> channels;                ///< At least one.
  std::vector<DbcImuMessageOptions> message_options;  ///< Only for messages with counter/checksum.
};

/// Measured IMU values in SI units, body frame.
struct ImuSample {
  Eigen::Vector3d rate_rad_s = Eigen::Vector3d::Zero();
  Eigen::Vector3d accel_m_s2 = Eigen::Vector3d::Zero();
};

class DbcImuNode {
 public:
  /// Throws std::invalid_argument ("dbc_imu.<field>: problem") on an unknown message/signal, a
  /// unit that does not fit the quantity, a missing/zero GenMsgCycleTime, a counter/checksum
  /// signal that cannot carry its kind, or options for a message no channel uses.
  DbcImuNode(std::shared_ptr<const bus::DbcDatabase> dbc, const DbcImuConfig& config,
             std::int64_t first_sample_ns);

  /// The earliest instant a message is due (INT64_MAX if none).
  std::int64_t NextEventNs() const;
  /// Every message due at or before t_ns, in due order (ties in configuration order), encoded
  /// from `sample` (taken as the reading at each due instant). Never throws.
  std::vector<NodeFrame> Poll(std::int64_t t_ns, const ImuSample& sample);

  /// Message ids in configuration order and their periods.
  std::size_t message_count() const { return messages_.size(); }
  std::int64_t period_ns(std::size_t i) const { return messages_[i].period_ns; }
  const bus::DbcMessage& message(std::size_t i) const { return *messages_[i].msg; }
  std::uint64_t frames_sent() const { return frames_sent_; }
  std::uint64_t saturated() const { return saturated_; }

 private:
  struct Binding {
    ImuQuantity quantity;
    const bus::DbcSignal* signal;
    double si_to_signal;  ///< Multiplier from SI (rad/s, m/s^2) to the signal's unit.
  };
  struct Message {
    const bus::DbcMessage* msg;
    std::vector<Binding> bindings;
    const bus::DbcSignal* counter = nullptr;
    const bus::DbcSignal* checksum = nullptr;
    ChecksumKind checksum_kind = ChecksumKind::kXor;
    std::uint64_t counter_value = 0;
    std::int64_t period_ns = 0;
    std::int64_t next_ns = 0;
  };

  bool Encode(Message& m, const ImuSample& s, bus::CanFrame& out) noexcept;

  std::shared_ptr<const bus::DbcDatabase> dbc_;
  std::vector<Message> messages_;
  std::uint64_t frames_sent_ = 0;
  std::uint64_t saturated_ = 0;
};

}  // namespace wheelhil::emulator
