#include "emulator/devices/mm5_imu_node.h"

#include <cmath>
#include <numbers>
#include <stdexcept>

#include "bus/dbc_codec.h"

namespace wheelhil::emulator {

Mm5ImuNode::Mm5ImuNode(std::shared_ptr<const bus::DbcDatabase> mm5_dbc, const GyroParams& gyro,
                       std::int64_t first_sample_ns)
    : dbc_(std::move(mm5_dbc)),
      gyro_(gyro),
      period_ns_(std::llround(1e9 / gyro.rate_hz)),
      first_ns_(first_sample_ns),
      next_ns_(first_sample_ns) {
  if (!dbc_) throw std::invalid_argument("Mm5ImuNode: no DBC database");
  yaw_msg_ = dbc_->FindMessage("MM5_YawRate_AccelY");
  if (yaw_msg_ == nullptr) {
    throw std::invalid_argument("Mm5ImuNode: the DBC has no message MM5_YawRate_AccelY");
  }
  yaw_sig_ = yaw_msg_->FindSignal("MM5_YawRate");
  accel_sig_ = yaw_msg_->FindSignal("MM5_AccelY");
  if (yaw_sig_ == nullptr || accel_sig_ == nullptr) {
    throw std::invalid_argument("Mm5ImuNode: MM5_YawRate_AccelY lacks MM5_YawRate/MM5_AccelY");
  }
  if (period_ns_ <= 0) throw std::invalid_argument("Mm5ImuNode: gyro rate_hz too high");
}

bool Mm5ImuNode::Sample(const Eigen::Vector3d& omega_WB_B, double accel_y_B_m_s2,
                        bus::CanFrame& out) {
  const double rate_rad_s = SampleYawRate(omega_WB_B);
  return Encode(rate_rad_s, accel_y_B_m_s2, out);
}

double Mm5ImuNode::SampleYawRate(const Eigen::Vector3d& omega_WB_B) {
  ++samples_;
  next_ns_ = first_ns_ + static_cast<std::int64_t>(samples_) * period_ns_;
  return gyro_.Sample(omega_WB_B);
}

bool Mm5ImuNode::Encode(double rate_rad_s, double accel_y_B_m_s2, bus::CanFrame& out) {
  bus::CanFrame f;
  f.id = yaw_msg_->id;
  f.extended = yaw_msg_->extended;
  f.len = static_cast<std::uint8_t>(yaw_msg_->length);
  const std::span<std::uint8_t> payload(f.data.data(), f.len);
  bool ok = bus::EncodeSignal(*yaw_sig_, rate_rad_s * 180.0 / std::numbers::pi, payload);
  ok = bus::EncodeSignal(*accel_sig_, accel_y_B_m_s2 / 9.80665, payload) && ok;
  if (!ok) ++saturated_;
  out = f;
  return ok;
}

}  // namespace wheelhil::emulator
