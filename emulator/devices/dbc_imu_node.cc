#include "emulator/devices/dbc_imu_node.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>

#include <fmt/format.h>

#include "bus/dbc_codec.h"

namespace wheelhil::emulator {

namespace {

constexpr double kG = 9.80665;

bool IsRate(ImuQuantity q) {
  return q == ImuQuantity::kRateX || q == ImuQuantity::kRateY || q == ImuQuantity::kRateZ;
}

/// Multiplier SI -> unit, or nullopt when the unit does not fit the quantity.
std::optional<double> SiToUnit(ImuQuantity q, const std::string& unit) {
  if (IsRate(q)) {
    if (unit == "deg/s" || unit == "\xC2\xB0/s" || unit == "dps") return 180.0 / std::numbers::pi;
    if (unit == "rad/s") return 1.0;
    return std::nullopt;
  }
  if (unit == "g") return 1.0 / kG;
  if (unit == "m/s^2" || unit == "m/s2" || unit == "m/s\xC2\xB2") return 1.0;
  return std::nullopt;
}

double Component(const ImuSample& s, ImuQuantity q) {
  switch (q) {
    case ImuQuantity::kRateX:
      return s.rate_rad_s.x();
    case ImuQuantity::kRateY:
      return s.rate_rad_s.y();
    case ImuQuantity::kRateZ:
      return s.rate_rad_s.z();
    case ImuQuantity::kAccelX:
      return s.accel_m_s2.x();
    case ImuQuantity::kAccelY:
      return s.accel_m_s2.y();
    case ImuQuantity::kAccelZ:
      return s.accel_m_s2.z();
  }
  return 0.0;
}

}  // namespace

std::optional<ImuQuantity> ParseImuQuantity(std::string_view name) noexcept {
  if (name == "rate_x") return ImuQuantity::kRateX;
  if (name == "rate_y") return ImuQuantity::kRateY;
  if (name == "rate_z") return ImuQuantity::kRateZ;
  if (name == "accel_x") return ImuQuantity::kAccelX;
  if (name == "accel_y") return ImuQuantity::kAccelY;
  if (name == "accel_z") return ImuQuantity::kAccelZ;
  return std::nullopt;
}

DbcImuNode::DbcImuNode(std::shared_ptr<const bus::DbcDatabase> dbc, const DbcImuConfig& config,
                       std::int64_t first_sample_ns)
    : dbc_(std::move(dbc)) {
  if (!dbc_) throw std::invalid_argument("dbc_imu: a DBC database is required");
  if (config.channels.empty()) throw std::invalid_argument("dbc_imu.channels: none configured");
  auto message_index = [&](const std::string& name, const std::string& field) -> std::size_t {
    for (std::size_t i = 0; i < messages_.size(); ++i) {
      if (messages_[i].msg->name == name) return i;
    }
    const bus::DbcMessage* msg = dbc_->FindMessage(name);
    if (!msg) throw std::invalid_argument(fmt::format("{}: no DBC message '{}'", field, name));
    if (!msg->cycle_time_ms || *msg->cycle_time_ms <= 0) {
      throw std::invalid_argument(
          fmt::format("{}: message '{}' has no GenMsgCycleTime > 0", field, name));
    }
    if (msg->length > 8) {
      throw std::invalid_argument(
          fmt::format("{}: message '{}' is {} bytes: only classic CAN frames (<= 8) are modelled",
                      field, name, msg->length));
    }
    Message m;
    m.msg = msg;
    m.period_ns = static_cast<std::int64_t>(*msg->cycle_time_ms) * 1'000'000;
    m.next_ns = first_sample_ns;
    messages_.push_back(std::move(m));
    return messages_.size() - 1;
  };
  for (std::size_t i = 0; i < config.channels.size(); ++i) {
    const DbcImuChannel& c = config.channels[i];
    const std::string field = fmt::format("dbc_imu.channels[{}]", i);
    Message& m = messages_[message_index(c.message, field + ".message")];
    const bus::DbcSignal* sig = m.msg->FindSignal(c.signal);
    if (!sig) {
      throw std::invalid_argument(
          fmt::format("{}.signal: message '{}' has no signal '{}'", field, c.message, c.signal));
    }
    const std::optional<double> k = SiToUnit(c.quantity, sig->unit);
    if (!k) {
      throw std::invalid_argument(
          fmt::format("{}.signal: unit '{}' of '{}' does not fit a {} (expected {})", field,
                      sig->unit, c.signal, IsRate(c.quantity) ? "rate" : "acceleration",
                      IsRate(c.quantity) ? "deg/s or rad/s" : "g or m/s^2"));
    }
    m.bindings.push_back({c.quantity, sig, *k});
  }
  for (std::size_t i = 0; i < config.message_options.size(); ++i) {
    const DbcImuMessageOptions& o = config.message_options[i];
    const std::string field = fmt::format("dbc_imu.message_options[{}]", i);
    auto it = std::find_if(messages_.begin(), messages_.end(),
                           [&](const Message& m) { return m.msg->name == o.message; });
    if (it == messages_.end()) {
      throw std::invalid_argument(
          fmt::format("{}.message: '{}' carries no configured channel", field, o.message));
    }
    if (!o.counter_signal.empty()) {
      it->counter = it->msg->FindSignal(o.counter_signal);
      if (!it->counter || it->counter->value_type != bus::DbcValueType::kInteger) {
        throw std::invalid_argument(
            fmt::format("{}.counter_signal: '{}' is not an integer signal of '{}'", field,
                        o.counter_signal, o.message));
      }
    }
    if (!o.checksum_signal.empty()) {
      it->checksum = it->msg->FindSignal(o.checksum_signal);
      it->checksum_kind = o.checksum;
      if (!it->checksum || !ChecksumFits(o.checksum, *it->checksum)) {
        throw std::invalid_argument(fmt::format(
            "{}.checksum_signal: '{}' is not a signal of '{}' that can carry a {} checksum", field,
            o.checksum_signal, o.message, ChecksumKindName(o.checksum)));
      }
    }
  }
}

std::int64_t DbcImuNode::NextEventNs() const {
  std::int64_t next = std::numeric_limits<std::int64_t>::max();
  for (const Message& m : messages_) next = std::min(next, m.next_ns);
  return next;
}

bool DbcImuNode::Encode(Message& m, const ImuSample& s, bus::CanFrame& out) noexcept {
  out = bus::CanFrame{};
  out.id = m.msg->id;
  out.extended = m.msg->extended;
  out.len = static_cast<std::uint8_t>(std::min(m.msg->length, 8));
  const std::span<std::uint8_t> payload(out.data.data(), out.len);
  bool ok = true;
  for (const Binding& b : m.bindings) {
    ok = bus::EncodeSignal(*b.signal, Component(s, b.quantity) * b.si_to_signal, payload) && ok;
  }
  if (m.counter) {
    const int n = m.counter->length;
    const std::uint64_t mask = n >= 64 ? ~0ULL : ((1ULL << n) - 1);
    bus::InsertRaw(*m.counter, m.counter_value & mask, payload);
    m.counter_value = (m.counter_value + 1) & mask;
  }
  if (m.checksum) WriteChecksum(m.checksum_kind, *m.checksum, payload);
  return ok;
}

std::vector<NodeFrame> DbcImuNode::Poll(std::int64_t t_ns, const ImuSample& sample) {
  std::vector<NodeFrame> out;
  for (;;) {
    Message* due = nullptr;
    for (Message& m : messages_) {
      if (m.next_ns <= t_ns && (!due || m.next_ns < due->next_ns)) due = &m;
    }
    if (!due) break;
    NodeFrame f;
    f.due_ns = due->next_ns;
    if (!Encode(*due, sample, f.frame)) ++saturated_;
    out.push_back(f);
    ++frames_sent_;
    due->next_ns += due->period_ns;
  }
  return out;
}

}  // namespace wheelhil::emulator
