#include "firmware_stub/fw_config.h"

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <set>
#include <sstream>
#include <stdexcept>

namespace wheelhil::fw {
namespace {

constexpr double kDegToRad = 3.14159265358979323846 / 180.0;

/// Reads one YAML mapping with located errors: "file:line:col: prefix.key: problem".
class Section {
 public:
  Section(const std::string& file, YAML::Node node, std::string prefix)
      : file_(file), node_(std::move(node)), prefix_(std::move(prefix)) {
    if (!node_.IsMap()) Fail(node_, "", "must be a mapping");
  }

  /// Rejects keys not in `allowed` (catches typos such as `trackwidth_m`).
  void Allow(std::initializer_list<const char*> allowed) const {
    std::set<std::string> ok(allowed.begin(), allowed.end());
    for (const auto& kv : node_) {
      const std::string key = kv.first.as<std::string>("");
      if (!ok.count(key)) Fail(kv.first, key, "unknown field");
    }
  }

  bool Has(const char* key) const { return static_cast<bool>(node_[key]); }
  YAML::Node Node(const char* key) const { return node_[key]; }
  std::string Field(const std::string& key) const {
    return prefix_.empty() ? key : prefix_ + "." + key;
  }

  [[noreturn]] void Fail(const YAML::Node& at, const std::string& key,
                         const std::string& problem) const {
    const YAML::Mark m = at.Mark();
    const std::string where =
        m.is_null() ? file_ : fmt::format("{}:{}:{}", file_, m.line + 1, m.column + 1);
    const std::string field = key.empty() ? (prefix_.empty() ? "config" : prefix_) : Field(key);
    throw std::invalid_argument(fmt::format("{}: {}: {}", where, field, problem));
  }
  [[noreturn]] void FailHere(const std::string& key, const std::string& problem) const {
    Fail(node_[key] ? node_[key] : node_, key, problem);
  }

  /// A finite number; `positive`: > 0, else >= 0 when `non_negative`.
  double Number(const char* key, double fallback, bool required, bool positive,
                bool non_negative = false) const {
    const YAML::Node n = node_[key];
    if (!n) {
      if (required) Fail(node_, key, "missing (required)");
      return fallback;
    }
    double v = 0.0;
    try {
      v = n.as<double>();
    } catch (const YAML::Exception&) {
      Fail(n, key, fmt::format("'{}' is not a number", n.as<std::string>("?")));
    }
    if (!std::isfinite(v)) Fail(n, key, "must be finite");
    if (positive && !(v > 0.0)) Fail(n, key, fmt::format("({}) must be > 0", v));
    if (non_negative && v < 0.0) Fail(n, key, fmt::format("({}) must be >= 0", v));
    return v;
  }

  long long Integer(const char* key, long long fallback, bool required, long long lo,
                    long long hi) const {
    const YAML::Node n = node_[key];
    if (!n) {
      if (required) Fail(node_, key, "missing (required)");
      return fallback;
    }
    long long v = 0;
    try {
      v = n.as<long long>();
    } catch (const YAML::Exception&) {
      Fail(n, key, fmt::format("'{}' is not an integer", n.as<std::string>("?")));
    }
    if (v < lo || v > hi) Fail(n, key, fmt::format("({}) must be in [{}, {}]", v, lo, hi));
    return v;
  }

  bool Bool(const char* key, bool fallback) const {
    const YAML::Node n = node_[key];
    if (!n) return fallback;
    try {
      return n.as<bool>();
    } catch (const YAML::Exception&) {
      Fail(n, key, fmt::format("'{}' is not true/false", n.as<std::string>("?")));
    }
  }

  HeadingRule Heading(const char* key, HeadingRule fallback) const {
    const YAML::Node n = node_[key];
    if (!n) return fallback;
    const std::string s = n.as<std::string>("");
    if (s == "start") return HeadingRule::kStart;
    if (s == "midpoint") return HeadingRule::kMidpoint;
    if (s == "exact_arc") return HeadingRule::kExactArc;
    Fail(n, key, fmt::format("'{}' is not one of start, midpoint, exact_arc", s));
  }

  Section Child(const char* key) const {
    const YAML::Node n = node_[key];
    if (!n) Fail(node_, key, "missing (required)");
    return Section(file_, n, Field(key));
  }

  const std::string& file() const { return file_; }
  const YAML::Node& node() const { return node_; }

 private:
  std::string file_;
  YAML::Node node_;
  std::string prefix_;
};

EncoderNode ReadNode(const Section& s, bool with_angle, double* angle_rad) {
  if (with_angle) {
    s.Allow({"node_id", "sign", "angle_deg"});
    *angle_rad = s.Number("angle_deg", 0.0, true, false) * kDegToRad;
  } else {
    s.Allow({"node_id", "sign"});
  }
  EncoderNode n;
  n.node_id = static_cast<int>(s.Integer("node_id", 0, true, 1, 127));
  n.sign = static_cast<int>(s.Integer("sign", 1, false, -1, 1));
  if (n.sign == 0) s.FailHere("sign", "must be +1 or -1");
  return n;
}

void ReadThree(const Section& parent, const char* key, std::array<EncoderNode, 3>& nodes,
               std::array<double, 3>& angles_rad) {
  const YAML::Node list = parent.Node(key);
  if (!list) parent.Fail(parent.node(), key, "missing (required): a list of three wheels");
  if (!list.IsSequence() || list.size() != 3) {
    parent.Fail(list, key, "must be a list of exactly three entries {node_id, sign, angle_deg}");
  }
  for (std::size_t i = 0; i < 3; ++i) {
    const Section s(parent.file(), list[i], fmt::format("{}[{}]", parent.Field(key), i));
    nodes[i] = ReadNode(s, true, &angles_rad[i]);
  }
}

void ReadCanopen(const Section& s, CanopenSettings& c) {
  s.Allow({"boot_timeout_s", "heartbeat_period_s", "heartbeat_timeout_s", "sdo_timeout_s",
           "sdo_retries", "tpdo_transmission_type", "reset_communication_at_start"});
  c.boot_timeout_s = s.Number("boot_timeout_s", c.boot_timeout_s, false, true);
  c.heartbeat_period_s = s.Number("heartbeat_period_s", c.heartbeat_period_s, false, false, true);
  if (c.heartbeat_period_s > 65.535) s.FailHere("heartbeat_period_s", "must be <= 65.535 (u16 ms)");
  c.heartbeat_timeout_s =
      s.Number("heartbeat_timeout_s", c.heartbeat_timeout_s, false, false, true);
  if (c.heartbeat_timeout_s > 0 && c.heartbeat_period_s > 0 &&
      c.heartbeat_timeout_s <= c.heartbeat_period_s) {
    s.FailHere("heartbeat_timeout_s", fmt::format("({}) must exceed heartbeat_period_s ({})",
                                                  c.heartbeat_timeout_s, c.heartbeat_period_s));
  }
  c.sdo_timeout_s = s.Number("sdo_timeout_s", c.sdo_timeout_s, false, true);
  c.sdo_retries = static_cast<int>(s.Integer("sdo_retries", c.sdo_retries, false, 0, 10));
  c.tpdo_transmission_type = static_cast<int>(
      s.Integer("tpdo_transmission_type", c.tpdo_transmission_type, false, 0, 240));
  c.reset_communication_at_start =
      s.Bool("reset_communication_at_start", c.reset_communication_at_start);
}

void ReadSync(const Section& s, SyncSettings& c) {
  s.Allow({"produce", "period_s", "deadline_s"});
  c.produce = s.Bool("produce", c.produce);
  c.period_s = s.Number("period_s", c.period_s, true, true);
  c.deadline_s = s.Number("deadline_s", 0.9 * c.period_s, false, false, true);
  if (c.deadline_s > c.period_s) {
    s.FailHere("deadline_s",
               fmt::format("({}) must be <= period_s ({})", c.deadline_s, c.period_s));
  }
}

std::uint32_t FrameId(const Section& s, const char* key, std::uint32_t fallback, bool required) {
  return static_cast<std::uint32_t>(s.Integer(key, fallback, required, 1, 0x7FF));
}

void ReadPaper000(const Section& s, Paper000Settings& p) {
  s.Allow({"track_width_m", "wheel_radius_m", "counts_per_rev", "counter_bits", "left", "right",
           "calibration_samples", "residual_mean_rad", "residual_sigma_rad", "z", "heading_rule"});
  p.track_width_m = s.Number("track_width_m", 0, true, true);
  p.wheel_radius_m = s.Number("wheel_radius_m", 0, true, true);
  p.counts_per_rev = s.Number("counts_per_rev", 0, true, true);
  p.counter_bits = static_cast<int>(s.Integer("counter_bits", p.counter_bits, false, 1, 32));
  p.left = ReadNode(s.Child("left"), false, nullptr);
  p.right = ReadNode(s.Child("right"), false, nullptr);
  p.calibration_samples =
      static_cast<int>(s.Integer("calibration_samples", 0, false, 0, 1'000'000));
  p.residual_mean_rad = s.Number("residual_mean_rad", 0.0, false, false);
  p.residual_sigma_rad =
      s.Number("residual_sigma_rad", 0.0, p.calibration_samples == 0, false, true);
  if (p.calibration_samples == 0 && !(p.residual_sigma_rad > 0)) {
    s.FailHere("residual_sigma_rad", "must be > 0 when calibration_samples is 0");
  }
  p.z = s.Number("z", p.z, false, true);
  p.heading_rule = s.Heading("heading_rule", p.heading_rule);
}

void ReadPaper001(const Section& s, Paper001Settings& p) {
  s.Allow({"mount_radius_m", "follower_radius_m", "counts_per_rev", "counter_bits", "followers",
           "heading_rule"});
  p.mount_radius_m = s.Number("mount_radius_m", 0, true, true);
  p.follower_radius_m = s.Number("follower_radius_m", 0, true, true);
  p.counts_per_rev = s.Number("counts_per_rev", 0, true, true);
  p.counter_bits = static_cast<int>(s.Integer("counter_bits", p.counter_bits, false, 1, 32));
  ReadThree(s, "followers", p.followers, p.angles_rad);
  p.heading_rule = s.Heading("heading_rule", p.heading_rule);
}

void ReadAxis(const Section& s, Paper002AxisSettings& a) {
  s.Allow({"k11_1_s", "k12_u_s", "k21_1_s2", "k22_u_s2", "boundary_layer_u",
           "disturbance_threshold_u_s2", "recovery_time_s"});
  a.k11_1_s = s.Number("k11_1_s", a.k11_1_s, false, true);
  a.k12_u_s = s.Number("k12_u_s", a.k12_u_s, false, false, true);
  a.k21_1_s2 = s.Number("k21_1_s2", a.k21_1_s2, false, true);
  a.k22_u_s2 = s.Number("k22_u_s2", a.k22_u_s2, false, false, true);
  a.boundary_layer_u = s.Number("boundary_layer_u", a.boundary_layer_u, false, false, true);
  a.disturbance_threshold_u_s2 =
      s.Number("disturbance_threshold_u_s2", a.disturbance_threshold_u_s2, false, true);
  a.recovery_time_s = s.Number("recovery_time_s", a.recovery_time_s, false, true);
}

void ReadPaper002(const Section& s, Paper002Settings& p) {
  s.Allow({"wheel_radius_m", "wheel_mount_radius_m", "counts_per_rev", "counter_bits", "wheels",
           "accel_mount_radius_m", "k_min", "axes"});
  p.wheel_radius_m = s.Number("wheel_radius_m", 0, true, true);
  p.wheel_mount_radius_m = s.Number("wheel_mount_radius_m", 0, true, true);
  p.counts_per_rev = s.Number("counts_per_rev", 0, true, true);
  p.counter_bits = static_cast<int>(s.Integer("counter_bits", p.counter_bits, false, 1, 32));
  ReadThree(s, "wheels", p.wheels, p.angles_rad);
  p.accel_mount_radius_m = s.Number("accel_mount_radius_m", 0, true, true);
  p.k_min = s.Number("k_min", p.k_min, false, true);
  if (p.k_min > 1.0) s.FailHere("k_min", fmt::format("({}) must be in (0, 1]", p.k_min));
  if (s.Has("axes")) {
    const Section axes = s.Child("axes");
    axes.Allow({"x", "y", "theta"});
    const char* names[3] = {"x", "y", "theta"};
    for (int i = 0; i < 3; ++i) {
      if (axes.Has(names[i])) ReadAxis(axes.Child(names[i]), p.axes[i]);
    }
  }
}

void CheckUniqueNodes(const Section& s, const char* key, const std::vector<EncoderNode>& nodes) {
  std::set<int> seen;
  for (const auto& n : nodes) {
    if (!seen.insert(n.node_id).second) {
      s.FailHere(key, fmt::format("node_id {} is used twice", n.node_id));
    }
  }
}

}  // namespace

const char* EstimatorName(EstimatorKind kind) noexcept {
  switch (kind) {
    case EstimatorKind::kPaper000SlipCorrection:
      return "paper000";
    case EstimatorKind::kPaper001FollowerOdometry:
      return "paper001";
    case EstimatorKind::kPaper002Fusion:
      return "paper002";
  }
  return "?";
}

std::vector<EncoderNode> FwConfig::encoder_nodes() const {
  switch (estimator) {
    case EstimatorKind::kPaper000SlipCorrection:
      return {paper000.left, paper000.right};
    case EstimatorKind::kPaper001FollowerOdometry:
      return {paper001.followers.begin(), paper001.followers.end()};
    case EstimatorKind::kPaper002Fusion:
      return {paper002.wheels.begin(), paper002.wheels.end()};
  }
  return {};
}

FwConfig ParseFwConfig(const std::string& text, const std::string& path) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw std::invalid_argument(
        fmt::format("{}:{}:{}: {}", path, e.mark.line + 1, e.mark.column + 1, e.msg));
  }
  if (!root.IsMap()) {
    throw std::invalid_argument(fmt::format("{}: firmware config must be a YAML mapping", path));
  }
  const Section top(path, root, "");
  top.Allow({"estimator", "dbc_dir", "canopen", "sync", "imu", "accel", "paper000", "paper001",
             "paper002"});
  FwConfig cfg;
  cfg.source_path = path;
  const YAML::Node est = root["estimator"];
  if (!est) throw std::invalid_argument(fmt::format("{}: missing field 'estimator'", path));
  const std::string name = est.as<std::string>("");
  if (name == "paper000") {
    cfg.estimator = EstimatorKind::kPaper000SlipCorrection;
  } else if (name == "paper001") {
    cfg.estimator = EstimatorKind::kPaper001FollowerOdometry;
  } else if (name == "paper002") {
    cfg.estimator = EstimatorKind::kPaper002Fusion;
  } else {
    top.Fail(est, "estimator",
             fmt::format("'{}' is not one of paper000, paper001, paper002", name));
  }
  if (root["dbc_dir"]) {
    std::filesystem::path dir = root["dbc_dir"].as<std::string>("");
    if (dir.empty()) top.FailHere("dbc_dir", "must be a directory path");
    if (dir.is_relative()) dir = std::filesystem::path(path).parent_path() / dir;
    cfg.dbc_dir = dir.lexically_normal().string();
  }
  if (root["canopen"]) ReadCanopen(top.Child("canopen"), cfg.canopen);
  ReadSync(top.Child("sync"), cfg.sync);
  if (root["imu"]) {
    const Section s = top.Child("imu");
    s.Allow({"yaw_frame_id", "gyro_bias_rad_s"});
    cfg.imu.enabled = true;
    cfg.imu.yaw_frame_id = FrameId(s, "yaw_frame_id", cfg.imu.yaw_frame_id, false);
    cfg.imu.gyro_bias_rad_s = s.Number("gyro_bias_rad_s", 0.0, false, false);
  }
  if (root["accel"]) {
    const Section s = top.Child("accel");
    s.Allow({"frame_id"});
    cfg.accel.enabled = true;
    cfg.accel.frame_id = FrameId(s, "frame_id", 0, true);
  }
  switch (cfg.estimator) {
    case EstimatorKind::kPaper000SlipCorrection:
      ReadPaper000(top.Child("paper000"), cfg.paper000);
      if (!cfg.imu.enabled) top.Fail(root, "imu", "paper000 needs the yaw-rate IMU section");
      CheckUniqueNodes(top, "paper000", cfg.encoder_nodes());
      break;
    case EstimatorKind::kPaper001FollowerOdometry:
      ReadPaper001(top.Child("paper001"), cfg.paper001);
      CheckUniqueNodes(top, "paper001", cfg.encoder_nodes());
      break;
    case EstimatorKind::kPaper002Fusion:
      ReadPaper002(top.Child("paper002"), cfg.paper002);
      if (!cfg.accel.enabled) top.Fail(root, "accel", "paper002 needs the accel section");
      CheckUniqueNodes(top, "paper002", cfg.encoder_nodes());
      break;
  }
  return cfg;
}

FwConfig LoadFwConfig(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::invalid_argument(fmt::format("{}: cannot open firmware config", path));
  std::stringstream text;
  text << in.rdbuf();
  return ParseFwConfig(text.str(), path);
}

}  // namespace wheelhil::fw
