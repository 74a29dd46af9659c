#include "firmware_stub/fw_config.h"

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <filesystem>
#include <initializer_list>
#include <set>
#include <stdexcept>

#include "bus/yaml_fields.h"

namespace wheelhil::fw {
namespace {

constexpr double kDegToRad = 3.14159265358979323846 / 180.0;

/// One YAML mapping of the config, its fields named "prefix.key" in errors.
class Section {
 public:
  Section(const bus::yaml::FieldReader& reader, YAML::Node node, std::string prefix)
      : reader_(reader), node_(std::move(node)), prefix_(std::move(prefix)) {
    if (!node_.IsDefined() || !node_.IsMap()) Fail(node_, "", "must be a mapping");
  }

  /// Rejects keys not in `allowed` (catches typos such as `trackwidth_m`).
  void Allow(std::initializer_list<const char*> allowed) const {
    reader_.CheckKeys(node_, prefix_, std::set<std::string>(allowed.begin(), allowed.end()));
  }

  bool Has(const char* key) const { return static_cast<bool>(node_[key]); }
  YAML::Node Node(const char* key) const { return bus::yaml::FieldReader::Get(node_, key); }
  std::string Field(const std::string& key) const {
    return bus::yaml::FieldReader::Join(prefix_, key);
  }

  [[noreturn]] void Fail(const YAML::Node& at, const std::string& key,
                         const std::string& problem) const {
    const std::string field = key.empty() ? (prefix_.empty() ? "config" : prefix_) : Field(key);
    reader_.Fail(at, field, problem);
  }
  [[noreturn]] void FailHere(const std::string& key, const std::string& problem) const {
    reader_.FailKey(node_, key, key.empty() ? prefix_ : Field(key), problem);
  }

  /// A finite number; `positive`: > 0, else >= 0 when `non_negative`.
  double Number(const char* key, double fallback, bool required, bool positive,
                bool non_negative = false) const {
    const YAML::Node n = Node(key);
    if (!n.IsDefined()) {
      if (required) Fail(node_, key, "is required");
      return fallback;
    }
    const double v = reader_.ToNumber(n, Field(key));
    if (positive && !(v > 0.0)) Fail(n, key, fmt::format("({}) must be > 0", v));
    if (non_negative && v < 0.0) Fail(n, key, fmt::format("({}) must be >= 0", v));
    return v;
  }

  long long Integer(const char* key, long long fallback, bool required, long long lo,
                    long long hi) const {
    const YAML::Node n = Node(key);
    if (!n.IsDefined()) {
      if (required) Fail(node_, key, "is required");
      return fallback;
    }
    return reader_.ToInteger(n, Field(key), lo, hi);
  }

  bool Bool(const char* key, bool fallback) const {
    const YAML::Node n = Node(key);
    return n.IsDefined() ? reader_.ToBool(n, Field(key)) : fallback;
  }

  HeadingRule Heading(const char* key, HeadingRule fallback) const {
    const YAML::Node n = Node(key);
    if (!n.IsDefined()) return fallback;
    const std::string s = reader_.ToString(n, Field(key));
    if (s == "start") return HeadingRule::kStart;
    if (s == "midpoint") return HeadingRule::kMidpoint;
    if (s == "exact_arc") return HeadingRule::kExactArc;
    Fail(n, key, fmt::format("'{}' is not one of start, midpoint, exact_arc", s));
  }

  Section Child(const char* key) const {
    const YAML::Node n = Node(key);
    if (!n.IsDefined()) Fail(node_, key, "is required");
    return Section(reader_, n, Field(key));
  }

  const bus::yaml::FieldReader& reader() const { return reader_; }
  const YAML::Node& node() const { return node_; }

 private:
  const bus::yaml::FieldReader& reader_;
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
  if (!list.IsDefined()) parent.Fail(parent.node(), key, "is required: a list of three wheels");
  if (!list.IsSequence() || list.size() != 3) {
    parent.Fail(list, key, "must be a list of exactly three entries {node_id, sign, angle_deg}");
  }
  for (std::size_t i = 0; i < 3; ++i) {
    const Section s(parent.reader(), list[i], fmt::format("{}[{}]", parent.Field(key), i));
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

void ReadDrives(const Section& s, DriveSettings& d) {
  s.Allow({"velocity_unit", "gear_ratio", "counts_per_rev", "wheel_radius_m",
           "max_wheel_speed_rad_s", "mode", "abort_connection_option", "quick_stop_option",
           "master_node_id", "tracking_error_rad_s", "tracking_error_time_s", "master_heartbeat_s",
           "drive_heartbeat_timeout_s", "nodes"});
  d.enabled = true;
  if (s.Has("velocity_unit")) {
    const std::string u = s.reader().ToString(s.Node("velocity_unit"), s.Field("velocity_unit"));
    if (u != "rpm" && u != "counts_per_s") {
      s.FailHere("velocity_unit", fmt::format("'{}' is not one of rpm, counts_per_s", u));
    }
    d.velocity_rpm = u == "rpm";
  }
  d.gear_ratio = s.Number("gear_ratio", d.gear_ratio, false, true);
  d.counts_per_rev = s.Number("counts_per_rev", 0.0, !d.velocity_rpm, true);
  d.wheel_radius_m = s.Number("wheel_radius_m", 0, true, true);
  d.max_wheel_speed_rad_s = s.Number("max_wheel_speed_rad_s", 0.0, false, false, true);
  if (s.Has("mode")) {
    const std::string m = s.reader().ToString(s.Node("mode"), s.Field("mode"));
    if (m != "csv" && m != "pv") s.FailHere("mode", fmt::format("'{}' is not one of csv, pv", m));
    d.mode = m == "csv" ? 9 : 3;
  }
  d.abort_connection_option = static_cast<int>(
      s.Integer("abort_connection_option", d.abort_connection_option, false, 0, 3));
  d.quick_stop_option =
      static_cast<int>(s.Integer("quick_stop_option", d.quick_stop_option, false, 0, 8));
  d.master_node_id = static_cast<int>(s.Integer("master_node_id", d.master_node_id, false, 1, 127));
  d.tracking_error_rad_s =
      s.Number("tracking_error_rad_s", d.tracking_error_rad_s, false, false, true);
  d.tracking_error_time_s = s.Number("tracking_error_time_s", d.tracking_error_time_s, false, true);
  d.master_heartbeat_s = s.Number("master_heartbeat_s", d.master_heartbeat_s, false, false, true);
  d.drive_heartbeat_timeout_s = s.Number("drive_heartbeat_timeout_s", 0.0, false, false, true);
  if (d.drive_heartbeat_timeout_s > 65.535) {
    s.FailHere("drive_heartbeat_timeout_s", "must be <= 65.535 (u16 ms)");
  }
  const YAML::Node list = s.Node("nodes");
  if (!list.IsDefined() || !list.IsSequence() || list.size() == 0) {
    s.Fail(list.IsDefined() ? list : s.node(), "nodes",
           "must be a list of drives {node_id, x_m, y_m, roller_angle_deg?, sign?}");
  }
  for (std::size_t i = 0; i < list.size(); ++i) {
    const Section n(s.reader(), list[i], fmt::format("{}[{}]", s.Field("nodes"), i));
    n.Allow({"node_id", "x_m", "y_m", "heading_deg", "roller_angle_deg", "sign"});
    DriveNodeSettings dn;
    dn.node_id = static_cast<int>(n.Integer("node_id", 0, true, 1, 127));
    dn.x_m = n.Number("x_m", 0.0, true, false);
    dn.y_m = n.Number("y_m", 0.0, true, false);
    dn.heading_rad = n.Number("heading_deg", 0.0, false, false) * kDegToRad;
    if (n.Has("roller_angle_deg")) {
      dn.has_rollers = true;
      dn.roller_angle_rad = n.Number("roller_angle_deg", 0.0, true, false) * kDegToRad;
      if (std::abs(std::sin(dn.roller_angle_rad)) < 0.1) {
        n.FailHere("roller_angle_deg", "must not be near 0 (a roller parallel to the axle)");
      }
    }
    dn.sign = static_cast<int>(n.Integer("sign", 1, false, -1, 1));
    if (dn.sign == 0) n.FailHere("sign", "must be +1 or -1");
    d.nodes.push_back(dn);
  }
}

void ReadPath(const Section& s, PathSettings& p) {
  s.Allow({"waypoints", "speed_m_s", "accel_m_s2", "lookahead_m", "tolerance_m",
           "heading_tolerance_deg", "yaw_rate_deg_s", "heading_gain_1_s", "start_delay_s",
           "steer_from"});
  p.enabled = true;
  const YAML::Node list = s.Node("waypoints");
  if (!list.IsDefined() || !list.IsSequence() || list.size() == 0) {
    s.Fail(list.IsDefined() ? list : s.node(), "waypoints",
           "must be a list of [x_m, y_m] or [x_m, y_m, theta_deg]");
  }
  for (std::size_t i = 0; i < list.size(); ++i) {
    const std::string field = fmt::format("{}[{}]", s.Field("waypoints"), i);
    const YAML::Node w = list[i];
    if (!w.IsSequence() || (w.size() != 2 && w.size() != 3)) {
      s.reader().Fail(w, field, "must be [x_m, y_m] or [x_m, y_m, theta_deg]");
    }
    Waypoint wp;
    wp.x_m = s.reader().ToNumber(w[0], field + "[0]");
    wp.y_m = s.reader().ToNumber(w[1], field + "[1]");
    if (w.size() == 3) {
      wp.has_theta = true;
      wp.theta_rad = s.reader().ToNumber(w[2], field + "[2]") * kDegToRad;
    }
    p.waypoints.push_back(wp);
  }
  p.speed_m_s = s.Number("speed_m_s", p.speed_m_s, false, true);
  p.accel_m_s2 = s.Number("accel_m_s2", p.accel_m_s2, false, true);
  p.lookahead_m = s.Number("lookahead_m", p.lookahead_m, false, true);
  p.tolerance_m = s.Number("tolerance_m", p.tolerance_m, false, true);
  p.heading_tolerance_rad =
      s.Number("heading_tolerance_deg", p.heading_tolerance_rad / kDegToRad, false, true) *
      kDegToRad;
  p.yaw_rate_rad_s =
      s.Number("yaw_rate_deg_s", p.yaw_rate_rad_s / kDegToRad, false, true) * kDegToRad;
  p.heading_gain_1_s = s.Number("heading_gain_1_s", p.heading_gain_1_s, false, true);
  p.start_delay_s = s.Number("start_delay_s", p.start_delay_s, false, false, true);
  if (s.Has("steer_from")) {
    const std::string v = s.reader().ToString(s.Node("steer_from"), s.Field("steer_from"));
    if (v != "corrected" && v != "raw") {
      s.FailHere("steer_from", fmt::format("'{}' is not one of corrected, raw", v));
    }
    p.steer_from = v == "raw" ? SteerFrom::kRaw : SteerFrom::kCorrected;
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

namespace {

FwConfig ReadFwConfig(const bus::yaml::FieldReader& reader, const YAML::Node& root) {
  const std::string& path = reader.file();
  const Section top(reader, root, "");
  top.Allow({"estimator", "dbc_dir", "canopen", "sync", "imu", "accel", "paper000", "paper001",
             "paper002", "drives", "path"});
  FwConfig cfg;
  cfg.source_path = path;
  const YAML::Node est = top.Node("estimator");
  if (!est.IsDefined()) top.Fail(root, "estimator", "is required");
  const std::string name = reader.ToString(est, "estimator");
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
  if (top.Has("dbc_dir")) {
    std::filesystem::path dir = reader.ToString(top.Node("dbc_dir"), "dbc_dir");
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
  if (root["drives"]) {
    ReadDrives(top.Child("drives"), cfg.drives);
    std::set<int> used;
    for (const auto& n : cfg.encoder_nodes()) used.insert(n.node_id);
    for (const auto& d : cfg.drives.nodes) {
      if (!used.insert(d.node_id).second) {
        top.FailHere("drives", fmt::format("node_id {} is used twice (drives and encoders "
                                           "are separate CANopen nodes)",
                                           d.node_id));
      }
    }
    if (used.count(cfg.drives.master_node_id) != 0) {
      top.FailHere("drives",
                   fmt::format("master_node_id {} is also a node's id", cfg.drives.master_node_id));
    }
  }
  if (root["path"]) {
    if (!cfg.drives.enabled) top.Fail(root["path"], "path", "needs a drives section to follow it");
    ReadPath(top.Child("path"), cfg.path);
    if (cfg.path.steer_from == SteerFrom::kRaw &&
        cfg.estimator != EstimatorKind::kPaper000SlipCorrection) {
      top.Fail(root["path"]["steer_from"], "path.steer_from",
               "raw odometry exists only for paper000 (its uncorrected pose)");
    }
  }
  return cfg;
}

}  // namespace

FwConfig ParseFwConfig(const std::string& text, const std::string& path) {
  const bus::yaml::FieldReader reader(path);
  return reader.Guard([&] {
    const YAML::Node root = reader.Parse(text);
    if (!root.IsMap()) reader.Fail(root, "(document)", "a firmware config must be a mapping");
    return ReadFwConfig(reader, root);
  });
}

FwConfig LoadFwConfig(const std::string& path) {
  return ParseFwConfig(bus::yaml::FieldReader(path).ReadFile(), path);
}

}  // namespace wheelhil::fw
