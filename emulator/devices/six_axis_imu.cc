#include "emulator/devices/six_axis_imu.h"

#include "emulator/devices/accel4_device.h"
#include "emulator/faults/sensor_faults.h"

namespace wheelhil::emulator {

namespace {
constexpr std::array<const char*, 6> kSuffix = {".rate_x",  ".rate_y",  ".rate_z",
                                                ".accel_x", ".accel_y", ".accel_z"};
}  // namespace

SixAxisImu::SixAxisImu(std::string name, const GyroParams& gyro,
                       const AccelerometerParams& accel, const Eigen::Matrix3d& R_BS,
                       const Eigen::Vector3d& r_BS_B, double rate_hz, std::uint64_t seed)
    : name_(std::move(name)) {
  for (int axis = 0; axis < 3; ++axis) {
    GyroParams gp = gyro;
    gp.axis_B = R_BS.col(axis);
    gp.rate_hz = rate_hz;
    gp.seed = seed * 31 + static_cast<std::uint64_t>(axis);
    gyros_.emplace_back(gp);
  }
  AccelerometerParams ap = accel;
  ap.rate_hz = rate_hz;
  ap.r_BP_B = r_BS_B;
  ap.axes_B = {R_BS.col(0), R_BS.col(1), R_BS.col(2)};
  ap.seed = seed * 31 + 3;
  accel_ = std::make_unique<AccelerometerModel>(ap);
}

SixAxisImu::~SixAxisImu() = default;

SixAxisImu::SixAxisImu(const SixAxisImu& other)
    : name_(other.name_),
      gyros_(other.gyros_),
      accel_(CopyOf(other.accel_)),
      faults_(CopyOf(other.faults_)) {}

bool SixAxisImu::Sample(const physics::BodyTruth& body, std::int64_t t_ns,
                        std::array<double, 6>& out) {
  const BodyKinematics k = AccelKinematics(body);
  for (std::size_t c = 0; c < 3; ++c) out[c] = gyros_[c].Sample(k.omega_WB_B);
  const std::vector<double>& a = accel_->Sample(k);
  for (std::size_t c = 0; c < 3; ++c) out[3 + c] = a[c];
  return ApplyToChannels(faults_, out, t_ns);
}

std::vector<std::string> SixAxisImu::channels() const {
  std::vector<std::string> out;
  for (const char* s : kSuffix) out.push_back(name_ + s);
  return out;
}

double SixAxisImu::noise_std(const std::string& channel) const {
  for (std::size_t c = 0; c < 3; ++c) {
    if (channel == name_ + kSuffix[c]) return gyros_[c].noise_std_rad_s();
  }
  return accel_->noise_std_m_s2();
}

void SixAxisImu::ArmFaults(DeviceFaults& faults) {
  for (auto& [channel, injector] : faults.sensors) {
    for (std::size_t c = 0; c < kSuffix.size(); ++c) {
      if (injector && channel == name_ + kSuffix[c]) faults_[c] = std::move(injector);
    }
  }
}

}  // namespace wheelhil::emulator
