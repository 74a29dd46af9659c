#include "emulator/devices/accel4_node.h"

#include <cmath>
#include <stdexcept>

#include <fmt/format.h>

#include "bus/dbc_codec.h"
#include "emulator/devices/frame_checksum.h"

namespace wheelhil::emulator {

namespace {

const bus::DbcSignal* Need(const bus::DbcMessage& m, const char* name) {
  const bus::DbcSignal* s = m.FindSignal(name);
  if (!s) throw std::invalid_argument(fmt::format("accel4_node: {} lacks signal {}", m.name, name));
  return s;
}

}  // namespace

std::array<AccelerometerParams, 4> Paper002AccelParams(double radius_m, double rate_hz,
                                                       std::uint64_t seed) {
  const double r = radius_m;
  const std::array<std::pair<Eigen::Vector3d, Eigen::Vector3d>, 4> mounts = {{
      {Eigen::Vector3d(0, r, 0), Eigen::Vector3d::UnitX()},
      {Eigen::Vector3d(r, 0, 0), Eigen::Vector3d::UnitY()},
      {Eigen::Vector3d(-r, 0, 0), -Eigen::Vector3d::UnitY()},
      {Eigen::Vector3d(0, -r, 0), -Eigen::Vector3d::UnitX()},
  }};
  std::array<AccelerometerParams, 4> out;
  for (std::size_t i = 0; i < 4; ++i) {
    out[i].rate_hz = rate_hz;
    out[i].r_BP_B = mounts[i].first;
    out[i].axes_B = {mounts[i].second};
    out[i].seed = seed + i;
  }
  return out;
}

Accel4Node::Accel4Node(std::shared_ptr<const bus::DbcDatabase> accel4_dbc,
                       const std::array<AccelerometerParams, 4>& sensors,
                       std::int64_t first_sample_ns)
    : dbc_(std::move(accel4_dbc)),
      sensors_(std::make_shared<std::vector<AccelerometerModel>>()),
      next_ns_(first_sample_ns) {
  if (!dbc_) throw std::invalid_argument("accel4_node: a DBC database is required");
  msg_ = dbc_->FindMessage("ACC4_Data");
  if (!msg_) throw std::invalid_argument("accel4_node: the DBC has no message ACC4_Data");
  const char* names[] = {"ACC4_A1", "ACC4_A2", "ACC4_A3", "ACC4_A4"};
  for (int i = 0; i < 4; ++i) channels_[static_cast<std::size_t>(i)] = Need(*msg_, names[i]);
  counter_ = Need(*msg_, "ACC4_Counter");
  checksum_ = Need(*msg_, "ACC4_Checksum");
  if (!ChecksumFits(ChecksumKind::kXor, *checksum_)) {
    throw std::invalid_argument("accel4_node: ACC4_Checksum must be a 4- or 8-bit integer");
  }
  for (std::size_t i = 0; i < 4; ++i) {
    if (sensors[i].axes_B.size() != 1) {
      throw std::invalid_argument(
          fmt::format("accel4_node.sensors[{}].axes: a single-axis sensor is required", i));
    }
    if (sensors[i].rate_hz != sensors[0].rate_hz) {
      throw std::invalid_argument(fmt::format(
          "accel4_node.sensors[{}].rate_hz ({}) differs from sensor 0 ({}): one frame carries "
          "all four",
          i, sensors[i].rate_hz, sensors[0].rate_hz));
    }
    sensors_->emplace_back(sensors[i]);
  }
  const double period = 1e9 / sensors[0].rate_hz;
  if (!(period >= 1.0) || std::abs(period - std::round(period)) > 1e-6 * period) {
    throw std::invalid_argument(fmt::format(
        "accel4_node.rate_hz ({}): the period must be a whole number of ns", sensors[0].rate_hz));
  }
  period_ns_ = static_cast<std::int64_t>(std::llround(period));
}

std::array<double, 4> Accel4Node::SampleSensors(const BodyKinematics& k) {
  std::array<double, 4> a{};
  for (std::size_t i = 0; i < 4; ++i) a[i] = (*sensors_)[i].Sample(k)[0];
  return a;
}

bool Accel4Node::EncodeSample(const std::array<double, 4>& a_m_s2, bus::CanFrame& out) noexcept {
  out = bus::CanFrame{};
  out.id = msg_->id;
  out.extended = msg_->extended;
  out.len = static_cast<std::uint8_t>(msg_->length);
  const std::span<std::uint8_t> payload(out.data.data(), out.len);
  bool ok = true;
  for (std::size_t i = 0; i < 4; ++i)
    ok = bus::EncodeSignal(*channels_[i], a_m_s2[i], payload) && ok;
  const std::uint64_t counter_mask = (1ULL << counter_->length) - 1;
  bus::InsertRaw(*counter_, counter_value_ & counter_mask, payload);
  counter_value_ = (counter_value_ + 1) & counter_mask;
  WriteChecksum(ChecksumKind::kXor, *checksum_, payload);
  ++samples_;
  if (!ok) ++saturated_;
  next_ns_ += period_ns_;
  return ok;
}

bool Accel4Node::Sample(const BodyKinematics& k, bus::CanFrame& out) {
  return EncodeSample(SampleSensors(k), out);
}

}  // namespace wheelhil::emulator
