#include "emulator/devices/dbc_device.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <limits>
#include <numbers>
#include <span>
#include <stdexcept>

#include <fmt/format.h>

#include "bus/dbc_codec.h"

namespace wheelhil::emulator {

namespace {

using bus::PhysicalQuantity;

constexpr std::array<std::string_view, 16> kQuantityNames = {"rate_x",
                                                             "rate_y",
                                                             "rate_z",
                                                             "accel_x",
                                                             "accel_y",
                                                             "accel_z",
                                                             "wheel_angle",
                                                             "wheel_speed",
                                                             "temperature",
                                                             "constant",
                                                             "counter",
                                                             "checksum",
                                                             "wheel_speed_setpoint",
                                                             "drive_enable",
                                                             "motor_current",
                                                             "motor_torque"};
/// Events naming refused frames, at most this many per device (the count goes on).
constexpr std::uint64_t kRejectedFrameEvents = 10;
/// A wheel speed set point beyond this (rad/s at the wheel, ~9 500 rpm) is clamped to it, as a
/// drive clamps to its maximum speed: no wheeled robot's wheel turns that fast, and a float
/// signal can say 1e30.
constexpr double kMaxWheelSpeedSetpointRadS = 1000.0;

[[noreturn]] void Fail(const std::string& field, const std::string& problem) {
  throw std::invalid_argument(fmt::format("{}: {}", field, problem));
}

std::optional<double> AttributeNumber(const std::map<std::string, std::string, std::less<>>& a,
                                      std::string_view name) {
  const auto it = a.find(name);
  if (it == a.end()) return std::nullopt;
  double v = 0;
  const auto r = std::from_chars(it->second.data(), it->second.data() + it->second.size(), v);
  if (r.ec != std::errc() || r.ptr != it->second.data() + it->second.size() || !std::isfinite(v)) {
    return std::nullopt;
  }
  return v;
}

// GenMsgSendType by its string: the tools' enums differ, their cyclic types all say so.
bool SendsCyclically(const bus::DbcMessage& m) {
  const auto it = m.attributes.find("GenMsgSendType");
  if (it == m.attributes.end()) return true;
  std::string s = it->second;
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s.find("cyclic") != std::string::npos;
}

std::optional<PhysicalQuantity> UnitQuantity(DbcQuantity q) {
  switch (q) {
    case DbcQuantity::kRateX:
    case DbcQuantity::kRateY:
    case DbcQuantity::kRateZ:
    case DbcQuantity::kWheelSpeed:
    case DbcQuantity::kWheelSpeedSetpoint:
      return PhysicalQuantity::kAngularRate;
    case DbcQuantity::kMotorCurrent:
      return PhysicalQuantity::kCurrent;
    case DbcQuantity::kMotorTorque:
      return PhysicalQuantity::kTorque;
    case DbcQuantity::kAccelX:
    case DbcQuantity::kAccelY:
    case DbcQuantity::kAccelZ:
      return PhysicalQuantity::kAcceleration;
    case DbcQuantity::kWheelAngle:
      return PhysicalQuantity::kAngle;
    case DbcQuantity::kTemperature:
      return PhysicalQuantity::kTemperature;
    default:
      return std::nullopt;
  }
}

}  // namespace

std::optional<DbcQuantity> ParseDbcQuantity(std::string_view name) noexcept {
  for (std::size_t i = 0; i < kQuantityNames.size(); ++i) {
    if (kQuantityNames[i] == name) return static_cast<DbcQuantity>(i);
  }
  return std::nullopt;
}

std::string_view DbcQuantityNames() noexcept {
  return "rate_x, rate_y, rate_z, accel_x, accel_y, accel_z, wheel_angle, wheel_speed, "
         "temperature, constant, counter, checksum, wheel_speed_setpoint, drive_enable, "
         "motor_current, motor_torque";
}

Eigen::Matrix3d MountRotation(const Eigen::Vector3d& rpy_deg) {
  const Eigen::Vector3d r = rpy_deg * (std::numbers::pi / 180.0);
  return (Eigen::AngleAxisd(r.z(), Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(r.y(), Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(r.x(), Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

DbcDevice::DbcDevice(std::shared_ptr<const bus::DbcDatabase> dbc, const DbcDeviceConfig& config)
    : name_(config.name), dbc_(std::move(dbc)), config_(config) {
  if (!dbc_) throw std::invalid_argument(config_.field + ": a DBC database is required");
  const std::string& node = config_.node;
  const auto& nodes = dbc_->nodes();
  if (std::find(nodes.begin(), nodes.end(), node) == nodes.end()) {
    Fail(config_.field + ".node",
         fmt::format("'{}' is not a node of the DBC (BU_: {})", node, fmt::join(nodes, ", ")));
  }
  auto timing_of = [&](const std::string& msg) -> const DbcMessageTiming* {
    for (const auto& t : config_.timing) {
      if (t.message == msg) return &t;
    }
    return nullptr;
  };
  for (const auto& t : config_.timing) {
    const bus::DbcMessage* m = dbc_->FindMessage(t.message);
    if (m == nullptr || m->sender != node) {
      Fail(t.field, fmt::format("'{}' is not a message node {} sends", t.message, node));
    }
  }
  for (const bus::DbcMessage& m : dbc_->messages()) {
    if (m.sender != node) continue;
    const DbcMessageTiming* t = timing_of(m.name);
    const bool cyclic = (t != nullptr && t->cycle_time_ms) || SendsCyclically(m);
    if (!cyclic) continue;
    const double period_ms =
        t != nullptr && t->cycle_time_ms ? *t->cycle_time_ms : m.cycle_time_ms.value_or(0);
    if (!(period_ms > 0)) {
      Fail(config_.field + ".messages",
           fmt::format("{} is cyclic but has no GenMsgCycleTime > 0: give its cycle_time_ms",
                       m.name));
    }
    if (m.length > 8) {
      Fail(config_.field + ".messages",
           fmt::format("{} is {} bytes: only classic CAN frames (<= 8) are modelled", m.name,
                       m.length));
    }
    Message msg;
    msg.msg = &m;
    for (const bus::DbcSignal& sig : m.signals) {
      if (const auto start = AttributeNumber(sig.attributes, "GenSigStartValue")) {
        msg.start_values.emplace_back(&sig, static_cast<std::uint64_t>(std::llround(*start)));
      }
    }
    msg.period_ns = std::llround(period_ms * 1e6);
    const double delay_ms = t != nullptr && t->start_delay_ms
                                ? *t->start_delay_ms
                                : AttributeNumber(m.attributes, "GenMsgStartDelayTime").value_or(0);
    msg.next_ns = config_.start_ns + std::llround((delay_ms + (t ? t->phase_ms : 0.0)) * 1e6);
    messages_.push_back(std::move(msg));
  }
  if (messages_.empty()) {
    Fail(config_.field + ".node", fmt::format("node {} sends no cyclic message", node));
  }
  for (const DbcSignalBinding& b : config_.signals) {
    if (IsReceivedQuantity(b.quantity)) {
      BindReceived(b);
      continue;
    }
    bool found = false;
    for (Message& m : messages_) {
      if (!b.message.empty() && m.msg->name != b.message) continue;
      const bus::DbcSignal* sig = m.msg->FindSignal(b.signal);
      if (sig == nullptr) continue;
      found = true;
      auto bound_already = [&](const std::vector<Bound>& v) {
        return std::any_of(v.begin(), v.end(), [&](const Bound& x) { return x.signal == sig; });
      };
      if (bound_already(m.values) || bound_already(m.counters) || bound_already(m.checksums)) {
        Fail(b.field, fmt::format("{}.{} is bound twice", m.msg->name, b.signal));
      }
      Bound bound{&b, sig, {}, 0, 0};
      if (b.quantity == DbcQuantity::kCounter) {
        if (!sig->IsRawInteger()) {
          Fail(b.field, fmt::format("counter {} must be an integer signal with factor 1, offset 0",
                                    b.signal));
        }
        const std::uint64_t range = sig->length >= 63 ? (1ULL << 63) : (1ULL << sig->length);
        bound.modulo = b.counter_modulo.value_or(range);
        if (bound.modulo < 2 || bound.modulo > range) {
          Fail(b.field, fmt::format("modulo {} does not fit the {} bits of {}", bound.modulo,
                                    sig->length, b.signal));
        }
        m.counters.push_back(bound);
        continue;
      }
      if (b.quantity == DbcQuantity::kChecksum) {
        if (const std::string why = WhyChecksumDoesNotFit(b.checksum, *sig, *m.msg); !why.empty()) {
          Fail(b.field, why);
        }
        m.checksums.push_back(bound);
        continue;
      }
      if (const auto q = UnitQuantity(b.quantity)) {
        const bool counts = b.quantity == DbcQuantity::kWheelAngle && b.counts_per_rev > 0;
        const auto unit =
            bus::ConvertUnit(sig->unit, counts ? PhysicalQuantity::kDimensionless : *q);
        if (!unit) {
          Fail(b.field,
               fmt::format("{}'s unit '{}' is not a unit of {} ({}){}", b.signal, sig->unit,
                           bus::PhysicalQuantityName(*q), bus::AcceptedUnits(*q),
                           b.quantity == DbcQuantity::kWheelAngle
                               ? "; for encoder counts give counts_per_rev"
                               : ""));
        }
        bound.unit = *unit;
      }
      m.values.push_back(bound);
    }
    if (!found) {
      Fail(b.field, b.message.empty()
                        ? fmt::format("no message node {} sends cyclically has a signal '{}'", node,
                                      b.signal)
                        : fmt::format("'{}' is not a cyclic message of node {} with a signal '{}'",
                                      b.message, node, b.signal));
    }
  }
  for (Message& m : messages_) SplitByMultiplexerValue(m);
  if (config_.setpoint_timeout_s < 0) {
    Fail(config_.field + ".setpoint_timeout_ms", "must be >= 0");
  }
  for (const Channel& c : channels_) {
    if (!c.commanded_bound) {
      Fail(config_.field + ".signals",
           fmt::format("wheel {} has a drive_enable but no wheel_speed_setpoint", c.wheel));
    }
  }
  std::int64_t fastest = messages_.front().period_ns;
  for (const Message& m : messages_) fastest = std::min(fastest, m.period_ns);
  imu_ =
      std::make_unique<SixAxisImu>(name_, config_.gyro, config_.accel, config_.R_BS, config_.r_BS_B,
                                   1e9 / static_cast<double>(fastest), config_.seed);
}

DbcDevice::~DbcDevice() = default;

DbcDevice::DbcDevice(const DbcDevice& other)
    : Device(other),
      name_(other.name_),
      dbc_(other.dbc_),
      config_(other.config_),
      messages_(other.messages_),
      shared_counter_(other.shared_counter_),
      imu_(CopyOf(other.imu_)),
      frames_sent_(other.frames_sent_),
      clamped_(other.clamped_),
      received_(other.received_),
      channels_(other.channels_),
      last_setpoint_ns_(other.last_setpoint_ns_),
      setpoint_timed_out_(other.setpoint_timed_out_),
      setpoint_frames_(other.setpoint_frames_),
      rejected_frames_(other.rejected_frames_),
      clamped_setpoints_(other.clamped_setpoints_),
      nonfinite_setpoints_(other.nonfinite_setpoints_) {}

std::unique_ptr<Device> DbcDevice::Clone() const {
  return std::unique_ptr<Device>(new DbcDevice(*this));
}

// A frame carries one multiplexer value's signals; bound signals of two values in one frame
// would put one value's bits under the other's switch. So each bound value gets its own frame,
// and the switch is the device's to set.
void DbcDevice::SplitByMultiplexerValue(Message& m) {
  const bus::DbcSignal* mux = m.msg->multiplexer();
  if (mux == nullptr) return;
  const Bound* mux_binding = nullptr;
  for (const std::vector<Bound>* bound : {&m.values, &m.counters, &m.checksums}) {
    for (const Bound& b : *bound) {
      if (b.signal->multiplex_value) m.mux_values.push_back(*b.signal->multiplex_value);
      if (b.signal == mux) mux_binding = &b;
    }
  }
  std::sort(m.mux_values.begin(), m.mux_values.end());
  m.mux_values.erase(std::unique(m.mux_values.begin(), m.mux_values.end()), m.mux_values.end());
  if (m.mux_values.empty()) return;
  if (mux_binding != nullptr) {
    Fail(mux_binding->binding->field,
         fmt::format("{} is the multiplexer switch of {}, whose m{} signals are bound: the device "
                     "sends one frame per bound multiplexer value and sets the switch itself; "
                     "do not bind it",
                     mux->name, m.msg->name, fmt::join(m.mux_values, ", m")));
  }
  const int value_bits = mux->is_signed ? mux->length - 1 : mux->length;
  const auto largest = value_bits >= 63 ? std::numeric_limits<std::int64_t>::max()
                                        : (std::int64_t{1} << value_bits) - 1;
  if (m.mux_values.back() > largest) {
    Fail(config_.field + ".signals",
         fmt::format("{}: multiplexer value m{} does not fit the {}-bit switch {}", m.msg->name,
                     m.mux_values.back(), mux->length, mux->name));
  }
}

DbcDevice::Channel& DbcDevice::ChannelOf(std::size_t wheel) {
  for (Channel& c : channels_) {
    if (c.wheel == wheel) return c;
  }
  channels_.push_back(Channel{});
  channels_.back().wheel = wheel;
  return channels_.back();
}

void DbcDevice::BindReceived(const DbcSignalBinding& b) {
  const std::string& node = config_.node;
  for (const bus::DbcMessage& m : dbc_->messages()) {
    if (m.sender == node || (!b.message.empty() && m.name != b.message)) continue;
    const bus::DbcSignal* sig = m.FindSignal(b.signal);
    if (sig == nullptr) continue;
    if (m.length > 8) {
      Fail(b.field, fmt::format("{} is {} bytes: only classic CAN frames (<= 8) are modelled",
                                m.name, m.length));
    }
    auto it = std::find_if(received_.begin(), received_.end(),
                           [&](const Received& r) { return r.msg == &m; });
    if (it == received_.end()) {
      received_.push_back(Received{&m, {}});
      it = received_.end() - 1;
    }
    for (const Bound& x : it->values) {
      if (x.signal == sig) Fail(b.field, fmt::format("{}.{} is bound twice", m.name, b.signal));
    }
    Bound bound{&b, sig, {}, 0, 0};
    if (b.quantity == DbcQuantity::kWheelSpeedSetpoint) {
      const auto unit = bus::ConvertUnit(sig->unit, PhysicalQuantity::kAngularRate);
      if (!unit) {
        Fail(b.field, fmt::format("{}'s unit '{}' is not a unit of angular rate ({})", b.signal,
                                  sig->unit, bus::AcceptedUnits(PhysicalQuantity::kAngularRate)));
      }
      bound.unit = *unit;
    }
    Channel& c = ChannelOf(b.wheel_index);
    if (b.quantity == DbcQuantity::kWheelSpeedSetpoint) {
      if (c.commanded_bound) {
        Fail(b.field, fmt::format("wheel {} has two wheel_speed_setpoint signals", b.wheel_index));
      }
      c.commanded_bound = true;
      c.torque_limit_nm = b.motor_torque_limit_nm;
    } else {
      c.enable_bound = true;
    }
    it->values.push_back(bound);
    return;
  }
  Fail(b.field, b.message.empty()
                    ? fmt::format("no message node {} receives (sent by another node) has a "
                                  "signal '{}'",
                                  node, b.signal)
                    : fmt::format("'{}' is not a message another node sends with a signal '{}'",
                                  b.message, b.signal));
}

bool DbcDevice::ReadsFrame(std::uint32_t id) const {
  return std::any_of(received_.begin(), received_.end(),
                     [id](const Received& r) { return !r.msg->extended && r.msg->id == id; });
}

void DbcDevice::OnFrame(const bus::CanFrame& frame, std::int64_t t_ns, DevicePort& port) {
  for (Received& r : received_) {
    if (frame.id != r.msg->id || frame.extended != r.msg->extended || frame.rtr) continue;
    if (frame.len != r.msg->length) {
      if (++rejected_frames_ <= kRejectedFrameEvents) {
        port.Event(nlohmann::json{{"t_s", port.MotionSeconds(t_ns)},
                                  {"event", "rejected_frame"},
                                  {"device", name_},
                                  {"message", r.msg->name},
                                  {"id", frame.id},
                                  {"why", fmt::format("{} bytes, the DBC's {} has {}", frame.len,
                                                      r.msg->name, r.msg->length)}});
      }
      return;
    }
    // Taken whole or not at all: a non-finite set point is no command (a drive refuses it), so
    // it neither moves a wheel nor keeps the power stages on past setpoint_timeout_s.
    decoded_.clear();
    bool refused = false;
    for (const Bound& b : r.values) {
      double v = 0;
      if (!bus::DecodeSignalIfPresent(*r.msg, *b.signal, frame, &v))
        continue;  // another multiplexer value
      decoded_.emplace_back(&b, v);
      if (std::isfinite(v)) continue;
      refused = true;
      if (++nonfinite_setpoints_ <= kRejectedFrameEvents) {
        port.Event(nlohmann::json{{"t_s", port.MotionSeconds(t_ns)},
                                  {"event", "setpoint_not_finite"},
                                  {"device", name_},
                                  {"message", r.msg->name},
                                  {"signal", b.signal->name},
                                  {"wheel", b.binding->wheel_index},
                                  {"commanded", std::isnan(v) ? "nan"
                                                : v > 0       ? "inf"
                                                              : "-inf"}});
      }
    }
    if (decoded_.empty() || refused) return;
    for (const auto& [bound, v] : decoded_) {
      const Bound& b = *bound;
      Channel& c = ChannelOf(b.binding->wheel_index);
      if (b.binding->quantity == DbcQuantity::kWheelSpeedSetpoint) {
        const double omega = b.binding->gain * b.unit.ToSi(v);
        c.omega_rad_s = std::clamp(omega, -kMaxWheelSpeedSetpointRadS, kMaxWheelSpeedSetpointRadS);
        if (c.omega_rad_s != omega && ++clamped_setpoints_ <= kRejectedFrameEvents) {
          port.Event(nlohmann::json{{"t_s", port.MotionSeconds(t_ns)},
                                    {"event", "setpoint_clamped"},
                                    {"device", name_},
                                    {"message", r.msg->name},
                                    {"signal", b.signal->name},
                                    {"wheel", c.wheel},
                                    {"commanded_rad_s", omega},
                                    {"limit_rad_s", kMaxWheelSpeedSetpointRadS}});
        }
        c.commanded = true;
      } else {
        c.enabled = v != 0.0;
      }
    }
    ++setpoint_frames_;
    last_setpoint_ns_ = t_ns;
    setpoint_timed_out_ = false;
    return;
  }
}

void DbcDevice::EndStep(std::int64_t t_ns) {
  Device::EndStep(t_ns);
  if (config_.setpoint_timeout_s > 0 && setpoint_frames_ > 0 &&
      static_cast<double>(t_ns - last_setpoint_ns_) * 1e-9 > config_.setpoint_timeout_s) {
    setpoint_timed_out_ = true;
  }
}

std::vector<WheelDrive> DbcDevice::wheel_drives() const {
  std::vector<WheelDrive> out;
  for (const Channel& c : channels_) {
    WheelDrive d;
    d.wheel = c.wheel;
    const bool on = c.commanded && !setpoint_timed_out_ && (!c.enable_bound || c.enabled);
    if (on) d.command = WheelDriveCommand{c.omega_rad_s, c.torque_limit_nm};
    out.push_back(d);
  }
  return out;
}

std::int64_t DbcDevice::NextEventNs() const {
  std::int64_t next = std::numeric_limits<std::int64_t>::max();
  for (const Message& m : messages_) next = std::min(next, m.next_ns);
  return next;
}

std::vector<std::string> DbcDevice::sensor_channels() const { return imu_->channels(); }

double DbcDevice::channel_noise_std(const std::string& channel) const {
  return imu_->noise_std(channel);
}

void DbcDevice::ArmFaults(DeviceFaults faults) {
  TakeDeviceFaults(faults);
  imu_->ArmFaults(faults);
}

void DbcDevice::Encode(Message& m, std::optional<int> mux_value, const Sample& s,
                       const DeviceWorld& world, bus::CanFrame& out) {
  out = bus::CanFrame{};
  out.id = m.msg->id;
  out.extended = m.msg->extended;
  out.len = static_cast<std::uint8_t>(m.msg->length);
  const std::span<std::uint8_t> payload(out.data.data(), out.len);
  // Only the signals of the frame's multiplexer value (and those of every frame) are written.
  const bus::DbcSignal* mux = m.msg->multiplexer();
  auto in_frame = [&](const bus::DbcSignal& sig) {
    return !sig.multiplex_value || (mux_value && *sig.multiplex_value == *mux_value);
  };
  for (const auto& [sig, raw] : m.start_values) {
    if (in_frame(*sig)) bus::InsertRaw(*sig, raw, payload);
  }
  if (mux_value) bus::InsertRaw(*mux, static_cast<std::uint64_t>(*mux_value), payload);
  for (const Bound& b : m.values) {
    if (!in_frame(*b.signal)) continue;
    const DbcSignalBinding& cfg = *b.binding;
    double si = 0;
    switch (cfg.quantity) {
      case DbcQuantity::kRateX:
      case DbcQuantity::kRateY:
      case DbcQuantity::kRateZ:
      case DbcQuantity::kAccelX:
      case DbcQuantity::kAccelY:
      case DbcQuantity::kAccelZ:
        si = s.imu[static_cast<std::size_t>(cfg.quantity)];
        break;
      case DbcQuantity::kWheelAngle:
        si = (*world.wheels)[cfg.wheel_index].angle_rad;
        break;
      case DbcQuantity::kWheelSpeed:
        si = (*world.wheels)[cfg.wheel_index].omega_rad_s;
        break;
      case DbcQuantity::kMotorCurrent:
        si = (*world.wheels)[cfg.wheel_index].motor_current_a;
        break;
      case DbcQuantity::kMotorTorque:
        si = (*world.wheels)[cfg.wheel_index].motor_torque_nm;
        break;
      case DbcQuantity::kTemperature:
        si = config_.temperature_k;
        break;
      default:
        break;
    }
    double v = cfg.quantity == DbcQuantity::kConstant ? cfg.value : b.unit.FromSi(cfg.gain * si);
    if (cfg.quantity == DbcQuantity::kWheelAngle && cfg.counts_per_rev > 0) {
      v = cfg.gain * si / (2.0 * std::numbers::pi) * cfg.counts_per_rev;
    }
    const bus::DbcSignal& sig = *b.signal;
    if (sig.minimum < sig.maximum && (v < sig.minimum || v > sig.maximum)) {
      v = std::clamp(v, sig.minimum, sig.maximum);
      ++clamped_;
    }
    if (!bus::EncodeSignal(sig, v, payload)) ++clamped_;
  }
  if (mux != nullptr && !mux_value) {
    // No multiplexed signal is bound: the switch says what its start value (or binding) says,
    // and that value's signals carry their start values.
    std::int64_t raw = 0;
    if (bus::ExtractRawSigned(*mux, payload, raw)) {
      for (const auto& [sig, start] : m.start_values) {
        if (sig->multiplex_value && *sig->multiplex_value == raw) {
          bus::InsertRaw(*sig, start, payload);
        }
      }
      mux_value = static_cast<int>(raw);
    }
  }
  for (Bound& b : m.counters) {
    if (!in_frame(*b.signal)) continue;
    const DbcSignalBinding& cfg = *b.binding;
    const std::uint64_t value = (cfg.counter_shared ? shared_counter_ : b.counter) % b.modulo;
    bus::InsertRaw(*b.signal, value, payload);
    const auto mod = static_cast<std::int64_t>(b.modulo);
    b.counter = static_cast<std::uint64_t>(
        ((static_cast<std::int64_t>(b.counter % b.modulo) + cfg.counter_step) % mod + mod) % mod);
  }
  for (const Bound& b : m.checksums) {
    if (in_frame(*b.signal)) WriteChecksum(b.binding->checksum, *b.signal, payload);
  }
}

void DbcDevice::Poll(std::int64_t t_ns, const DeviceWorld& world, DevicePort& port) {
  while (NextEventNs() <= t_ns) {
    const std::int64_t ts = NextEventNs();
    Sample s;
    const bool dropped = !imu_->Sample(*world.body, ts, s.imu);
    std::vector<NodeFrame> frames;
    for (Message& m : messages_) {
      if (m.next_ns != ts) continue;
      m.next_ns += m.period_ns;
      if (dropped) continue;
      NodeFrame f;
      f.due_ns = ts;
      if (m.mux_values.empty()) {
        Encode(m, std::nullopt, s, world, f.frame);
        frames.push_back(f);
      }
      for (const int value : m.mux_values) {
        Encode(m, value, s, world, f.frame);
        frames.push_back(f);
      }
    }
    ++shared_counter_;
    frames_sent_ += frames.size();
    if (!frames.empty()) SendThroughDeviceFaults(std::move(frames), true, port);
  }
}

}  // namespace wheelhil::emulator
