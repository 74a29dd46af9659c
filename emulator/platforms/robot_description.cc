#include "emulator/platforms/robot_description.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <console_bridge/console.h>
#include <fmt/format.h>
#include <tinyxml.h>
#include <urdf_parser/urdf_parser.h>
#include <Eigen/Geometry>

namespace wheelhil::emulator::platforms {

namespace {

namespace fs = std::filesystem;
using bus::yaml::FieldReader;
using Eigen::Isometry3d;
using Eigen::Matrix3d;
using Eigen::Vector3d;

constexpr double kAgreement = 1e-9;  // relative: a URDF value and the overlay's are the same

double Nanometres(double m) { return std::round(m * 1e9) / 1e9 + 0.0; }
double NanoDegrees(double deg) { return std::round(deg * 1e9) / 1e9 + 0.0; }

// urdfdom says why a file is no robot through console_bridge's log: kept for the error.
class CapturedLog : public console_bridge::OutputHandler {
 public:
  CapturedLog() : previous_(console_bridge::getOutputHandler()) {
    console_bridge::useOutputHandler(this);
  }
  ~CapturedLog() override { console_bridge::useOutputHandler(previous_); }
  CapturedLog(const CapturedLog&) = delete;
  CapturedLog& operator=(const CapturedLog&) = delete;
  void log(const std::string& text, console_bridge::LogLevel level, const char*, int) override {
    if (level < console_bridge::CONSOLE_BRIDGE_LOG_WARN) return;
    if (!text_.empty()) text_ += "; ";
    text_ += text;
  }
  const std::string& text() const { return text_; }

 private:
  console_bridge::OutputHandler* previous_;
  std::string text_;
};

Isometry3d ToIsometry(const urdf::Pose& p) {
  Isometry3d t = Isometry3d::Identity();
  t.linear() = Eigen::Quaterniond(p.rotation.w, p.rotation.x, p.rotation.y, p.rotation.z)
                   .normalized()
                   .toRotationMatrix();
  t.translation() = Vector3d(p.position.x, p.position.y, p.position.z);
  return t;
}

Vector3d ToVector(const urdf::Vector3& v) { return {v.x, v.y, v.z}; }

// A link's inertia about its own centre of mass, in the link's frame.
Matrix3d InertiaInLinkFrame(const urdf::Inertial& in) {
  Matrix3d i;
  i << in.ixx, in.ixy, in.ixz, in.ixy, in.iyy, in.iyz, in.ixz, in.iyz, in.izz;
  const Matrix3d r = ToIsometry(in.origin).linear();
  return r * i * r.transpose();
}

// Mass, centre of mass and inertia about it of several bodies, in one frame.
struct Lumped {
  double mass = 0;
  Vector3d moment = Vector3d::Zero();  // sum of m * c
  // Sum over bodies of (I_c + m (|c|^2 1 - c c^T)): the inertia about the frame's origin.
  Matrix3d about_origin = Matrix3d::Zero();

  void Add(double m, const Vector3d& c, const Matrix3d& i_c) {
    mass += m;
    moment += m * c;
    about_origin += i_c + m * (c.squaredNorm() * Matrix3d::Identity() - c * c.transpose());
  }
  Vector3d com() const { return mass > 0 ? Vector3d(moment / mass) : Vector3d::Zero(); }
  Matrix3d about_com() const {
    const Vector3d c = com();
    return about_origin - mass * (c.squaredNorm() * Matrix3d::Identity() - c * c.transpose());
  }
};

// The URDF file, parsed, with the line of every link and joint element.
class Urdf {
 public:
  Urdf(std::string path, std::string shown) : path_(std::move(path)), shown_(std::move(shown)) {}

  // Empty on success, else what is wrong (with the line where the XML says it).
  std::string Load() {
    // A regular file of bounded size before a byte is read (/dev/zero never ends).
    std::error_code ec;
    if (!fs::exists(path_, ec)) return "does not exist";
    if (!fs::is_regular_file(path_, ec)) return "is not a regular file (a device, a pipe?)";
    if (fs::file_size(path_, ec) > FieldReader::kMaxFileBytes || ec) return "is larger than 16 MiB";
    std::ifstream in(path_, std::ios::binary);
    if (!in) return "cannot be read";
    std::ostringstream text;
    text << in.rdbuf();
    TiXmlDocument xml;
    xml.Parse(text.str().c_str());
    if (xml.Error()) {
      return fmt::format("{}:{}:{}: not well-formed XML: {}", shown_, xml.ErrorRow(),
                         xml.ErrorCol(), xml.ErrorDesc());
    }
    const TiXmlElement* robot = xml.RootElement();
    if (robot == nullptr || std::string(robot->Value()) != "robot") {
      return fmt::format("{}: the root element is not <robot>", shown_);
    }
    for (const TiXmlElement* e = robot->FirstChildElement(); e != nullptr;
         e = e->NextSiblingElement()) {
      const char* name = e->Attribute("name");
      if (name == nullptr) continue;
      if (std::string(e->Value()) == "link") link_lines_.emplace(name, e->Row());
      if (std::string(e->Value()) == "joint") joint_lines_.emplace(name, e->Row());
    }
    CapturedLog log;
    model_ = urdf::parseURDF(text.str());
    if (!model_) {
      return fmt::format("{}: urdfdom cannot read it: {}", shown_,
                         log.text().empty() ? "(no reason given)" : log.text());
    }
    return {};
  }

  const urdf::ModelInterface& model() const { return *model_; }
  const std::string& path() const { return path_; }
  const std::string& shown() const { return shown_; }

  std::string Link(const std::string& name) const { return Where("link", link_lines_, name); }
  std::string Joint(const std::string& name) const { return Where("joint", joint_lines_, name); }

 private:
  std::string Where(const char* what, const std::map<std::string, int>& lines,
                    const std::string& name) const {
    const auto it = lines.find(name);
    return it == lines.end() ? fmt::format("{}: {} '{}'", shown_, what, name)
                             : fmt::format("{}:{}: {} '{}'", shown_, it->second, what, name);
  }

  std::string path_;
  std::string shown_;
  urdf::ModelInterfaceSharedPtr model_;
  std::map<std::string, int> link_lines_;
  std::map<std::string, int> joint_lines_;
};

// A wheel the overlay declares, as the URDF places it.
struct WheelInUrdf {
  std::string joint;
  Isometry3d joint_in_base = Isometry3d::Identity();  // the joint frame in the base link frame
  Vector3d axis_base = Vector3d::UnitY();             // the spin axis in the base link frame
  Vector3d axis_joint = Vector3d::UnitY();            // and in the joint's (the child link's)
  std::set<std::string> links;                        // the child link and all under it
};

class Importer {
 public:
  Importer(YAML::Node root, const FieldReader& rd, const Urdf& urdf)
      : root_(std::move(root)), rd_(rd), urdf_(urdf), model_(urdf.model()) {}

  void Run() {
    ChooseBase();
    const YAML::Node wheels = FieldReader::Get(root_, "wheels");
    if (wheels.IsDefined() && !wheels.IsSequence()) rd_.Fail(wheels, "wheels", "must be a list");
    std::vector<std::pair<YAML::Node, WheelInUrdf>> declared;
    if (wheels.IsDefined()) {
      for (std::size_t i = 0; i < wheels.size(); ++i) {
        YAML::Node entry = wheels[i];
        const YAML::Node joint = FieldReader::Get(entry, "joint");
        if (!FieldReader::Present(joint)) continue;
        declared.emplace_back(entry, Locate(entry, joint, fmt::format("wheels[{}]", i)));
      }
    }
    std::set<std::string> wheel_links;
    for (const auto& [entry, w] : declared) wheel_links.insert(w.links.begin(), w.links.end());
    FillChassis(wheel_links);
    for (std::size_t k = 0; k < declared.size(); ++k) {
      FillWheel(declared[k].first, declared[k].second);
    }
    if (!FieldReader::Present(FieldReader::Get(root_, "name"))) root_["name"] = model_.getName();
    root_.remove("urdf");
    root_.remove("base_link");
    root_.remove("package_paths");
  }

 private:
  void ChooseBase() {
    const YAML::Node base = FieldReader::Get(root_, "base_link");
    if (FieldReader::Present(base)) {
      const std::string name = rd_.ToString(base, "base_link");
      base_ = model_.getLink(name);
      if (!base_) {
        rd_.Fail(base, "base_link", fmt::format("{} has no link '{}'", urdf_.shown(), name));
      }
    } else {
      base_ = model_.getRoot();
    }
  }

  // The pose of `link`'s frame in the base link's frame, through the joints above it at their
  // zero positions; false when `link` is not under the base link. `moving`: the joints passed
  // that are not fixed.
  bool LinkInBase(const urdf::LinkConstSharedPtr& link, Isometry3d* pose,
                  std::vector<std::string>* moving) const {
    return LinkIn(base_->name, link, pose, moving);
  }

  // The same in the frame of link `top` above it.
  bool LinkIn(const std::string& top, const urdf::LinkConstSharedPtr& link, Isometry3d* pose,
              std::vector<std::string>* moving) const {
    Isometry3d t = Isometry3d::Identity();
    urdf::LinkConstSharedPtr at = link;
    while (at->name != top) {
      const urdf::JointConstSharedPtr j = at->parent_joint;
      if (!j) return false;
      if (j->type != urdf::Joint::FIXED && moving != nullptr) moving->push_back(j->name);
      t = ToIsometry(j->parent_to_joint_origin_transform) * t;
      at = model_.getLink(j->parent_link_name);
      if (!at) return false;
    }
    *pose = t;
    return true;
  }

  static void Subtree(const urdf::LinkConstSharedPtr& link, std::set<std::string>* out) {
    out->insert(link->name);
    for (const auto& child : link->child_links) Subtree(child, out);
  }

  WheelInUrdf Locate(const YAML::Node& entry, const YAML::Node& joint_node,
                     const std::string& field) const {
    const std::string f = field + ".joint";
    const std::string name = rd_.ToString(joint_node, f);
    const urdf::JointConstSharedPtr j = model_.getJoint(name);
    if (!j) {
      std::string known;
      for (const auto& [n, joint] : model_.joints_) {
        if (joint->type == urdf::Joint::CONTINUOUS) known += (known.empty() ? "" : ", ") + n;
      }
      rd_.Fail(joint_node, f,
               fmt::format("{} has no joint '{}' (its continuous joints: {})", urdf_.shown(), name,
                           known.empty() ? "none" : known));
    }
    if (j->type != urdf::Joint::CONTINUOUS) {
      rd_.Fail(joint_node, f,
               fmt::format("{} is not a continuous joint: a wheel spins without limits",
                           urdf_.Joint(name)));
    }
    const urdf::LinkConstSharedPtr parent = model_.getLink(j->parent_link_name);
    const urdf::LinkConstSharedPtr child = model_.getLink(j->child_link_name);
    WheelInUrdf w;
    w.joint = name;
    Isometry3d parent_in_base;
    std::vector<std::string> moving;
    if (!parent || !child || !LinkInBase(parent, &parent_in_base, &moving)) {
      rd_.Fail(joint_node, f,
               fmt::format("{} is not under the base link '{}'", urdf_.Joint(name), base_->name));
    }
    const std::string kind = WheelKind(entry);
    if (!moving.empty() && kind != "caster") {
      rd_.Fail(joint_node, f,
               fmt::format("{} hangs from the chassis through joint '{}', which moves: only a "
                           "caster's wheel may (its swivel)",
                           urdf_.Joint(name), moving.front()));
    }
    w.joint_in_base = parent_in_base * ToIsometry(j->parent_to_joint_origin_transform);
    const Vector3d axis = ToVector(j->axis);
    if (axis.norm() < 1e-12) {
      rd_.Fail(joint_node, f, fmt::format("{} has a zero axis", urdf_.Joint(name)));
    }
    w.axis_joint = axis.normalized();
    w.axis_base = w.joint_in_base.linear() * w.axis_joint;
    if (std::abs(w.axis_base.z()) > 1e-6) {
      rd_.Fail(joint_node, f,
               fmt::format("{}: its axis in the base link's frame ({:.6g}, {:.6g}, {:.6g}) is "
                           "not horizontal; wheelhil's wheels spin about a horizontal axle",
                           urdf_.Joint(name), w.axis_base.x(), w.axis_base.y(), w.axis_base.z()));
    }
    Subtree(child, &w.links);
    return w;
  }

  std::string WheelKind(const YAML::Node& entry) const {
    YAML::Node kind = FieldReader::Get(entry, "kind");
    if (!kind.IsDefined())
      kind = FieldReader::Get(FieldReader::Get(root_, "wheel_defaults"), "kind");
    return kind.IsDefined() && kind.IsScalar() ? kind.Scalar() : std::string();
  }

  // Writes `value` at map[key] unless the overlay has it there already: then the two must
  // agree (`degrees`: as angles, modulo 360), or the error names both.
  void Provide(YAML::Node map, const std::string& key, const std::string& field, double value,
               const std::string& source, bool degrees = false) const {
    const YAML::Node given = FieldReader::Get(map, key);
    if (FieldReader::Present(given)) {
      const double v = rd_.ToNumber(given, field);
      const double diff = degrees ? std::remainder(v - value, 360.0) : v - value;
      if (std::abs(diff) > kAgreement * std::max(1.0, std::abs(value))) {
        rd_.Fail(given, field,
                 fmt::format("{} here, but {} says {}: say it in one place", v, source, value));
      }
      return;
    }
    map[key] = fmt::format("{}", value);
  }

  void Provide3(YAML::Node map, const std::string& key, const std::string& field,
                const Vector3d& value, const std::string& source) const {
    const YAML::Node given = FieldReader::Get(map, key);
    if (FieldReader::Present(given)) {
      if (!given.IsSequence() || given.size() != 3) rd_.Fail(given, field, "must be [x, y, z]");
      for (int i = 0; i < 3; ++i) {
        const double v = rd_.ToNumber(given[i], fmt::format("{}[{}]", field, i));
        if (std::abs(v - value[i]) > kAgreement * std::max(1.0, std::abs(value[i]))) {
          rd_.Fail(
              given[i], fmt::format("{}[{}]", field, i),
              fmt::format("{} here, but {} says {}: say it in one place", v, source, value[i]));
        }
      }
      return;
    }
    YAML::Node seq(YAML::NodeType::Sequence);
    seq.SetStyle(YAML::EmitterStyle::Flow);
    for (int i = 0; i < 3; ++i) seq.push_back(fmt::format("{}", value[i]));
    map[key] = seq;
  }

  YAML::Node Section(const char* key) {
    YAML::Node n = root_[key];
    if (!n.IsDefined() || n.IsNull()) {
      root_[key] = YAML::Node(YAML::NodeType::Map);
      n = root_[key];
    }
    if (!n.IsMap()) rd_.Fail(n, key, "must be a mapping");
    return n;
  }

  void FillChassis(const std::set<std::string>& wheel_links) {
    Lumped body;
    std::string massless;
    std::vector<urdf::LinkSharedPtr> links;
    model_.getLinks(links);
    for (const auto& link : links) {
      if (wheel_links.count(link->name) != 0) continue;
      Isometry3d pose;
      if (!LinkInBase(link, &pose, nullptr)) continue;  // above the base link
      if (!link->inertial) continue;
      const urdf::Inertial& in = *link->inertial;
      const Vector3d c = pose * ToVector(in.origin.position);
      body.Add(in.mass, c, pose.linear() * InertiaInLinkFrame(in) * pose.linear().transpose());
    }
    const YAML::Node base_node = FieldReader::Get(root_, "base_link");
    const YAML::Node at = base_node.IsDefined() ? base_node : FieldReader::Get(root_, "urdf");
    if (body.mass <= 0) {
      rd_.Fail(at, "urdf",
               fmt::format("{} and the links fixed to it have no <inertial> mass: the chassis "
                           "needs one",
                           urdf_.Link(base_->name)));
    }
    com_ = body.com();
    const Matrix3d i = body.about_com();
    YAML::Node chassis = Section("chassis");
    const std::string source =
        fmt::format("{} (with the links under it but the wheels)", urdf_.Link(base_->name));
    Provide(chassis, "mass_kg", "chassis.mass_kg", body.mass, source);
    const double off = std::max({std::abs(i(0, 1)), std::abs(i(0, 2)), std::abs(i(1, 2))});
    const bool principal = off <= 1e-6 * i.diagonal().maxCoeff();
    if (principal) {
      Provide3(chassis, "inertia_kg_m2", "chassis.inertia_kg_m2", i.diagonal(), source);
    } else if (!FieldReader::Present(FieldReader::Get(chassis, "inertia_kg_m2"))) {
      rd_.Fail(at, "urdf",
               fmt::format("{}: the chassis' inertia about its centre of mass has products of "
                           "inertia (Ixy {:.6g}, Ixz {:.6g}, Iyz {:.6g} kg*m^2), which wheelhil "
                           "cannot take as principal moments along the body axes: give "
                           "chassis.inertia_kg_m2 in this file",
                           source, i(0, 1), i(0, 2), i(1, 2)));
    }
    for (const auto& collision : base_->collision_array) {
      if (collision && collision->geometry && collision->geometry->type == urdf::Geometry::BOX) {
        const auto& box = static_cast<const urdf::Box&>(*collision->geometry);
        const Vector3d half(Nanometres(0.5 * box.dim.x), Nanometres(0.5 * box.dim.y),
                            Nanometres(0.5 * box.dim.z));
        Provide3(chassis, "half_extents_m", "chassis.half_extents_m", half,
                 urdf_.Link(base_->name) + " collision box");
        break;
      }
    }
    const std::string mesh = ChassisMesh();
    if (!mesh.empty() && !FieldReader::Present(FieldReader::Get(chassis, "mesh"))) {
      chassis["mesh"] = mesh;
    }
  }

  // The base link's collision mesh (else its visual mesh), resolved; "" when it has none.
  std::string ChassisMesh() const {
    auto mesh_of = [](const urdf::GeometrySharedPtr& g) -> const urdf::Mesh* {
      return g && g->type == urdf::Geometry::MESH ? static_cast<const urdf::Mesh*>(g.get())
                                                  : nullptr;
    };
    const urdf::Mesh* mesh = nullptr;
    for (const auto& c : base_->collision_array) {
      if (c && (mesh = mesh_of(c->geometry)) != nullptr) break;
    }
    if (mesh == nullptr) {
      for (const auto& v : base_->visual_array) {
        if (v && (mesh = mesh_of(v->geometry)) != nullptr) break;
      }
    }
    return mesh == nullptr ? std::string() : ResolveUri(mesh->filename);
  }

  std::string ResolveUri(const std::string& uri) const {
    const fs::path urdf_dir = fs::path(urdf_.path()).parent_path();
    std::vector<fs::path> tried;
    auto found = [&](const fs::path& p) {
      tried.push_back(p);
      std::error_code ec;
      return fs::is_regular_file(p, ec);
    };
    const std::string package = "package://";
    const std::string file = "file://";
    if (uri.rfind(package, 0) == 0) {
      const std::string rest = uri.substr(package.size());
      const std::size_t slash = rest.find('/');
      const std::string name = rest.substr(0, slash);
      const std::string inside = slash == std::string::npos ? "" : rest.substr(slash + 1);
      for (const fs::path& dir : PackagePaths()) {
        if (found(dir / name / inside)) return (dir / name / inside).lexically_normal();
        if (dir.filename() == name && found(dir / inside)) return (dir / inside).lexically_normal();
      }
    } else if (uri.rfind(file, 0) == 0) {
      if (found(uri.substr(file.size()))) return uri.substr(file.size());
    } else if (found(urdf_dir / uri)) {
      return (urdf_dir / uri).lexically_normal();
    }
    std::string list;
    for (const auto& p : tried) list += (list.empty() ? "" : ", ") + p.string();
    rd_.Fail(FieldReader::Get(root_, "urdf"), "urdf",
             fmt::format("{}: its mesh '{}' is not found (looked at: {}){}",
                         urdf_.Link(base_->name), uri, list.empty() ? "nothing" : list,
                         uri.rfind(package, 0) == 0
                             ? "; package_paths lists the directories that hold packages"
                             : ""));
  }

  // package_paths, relative to the platform file; the URDF's directory and its parent last.
  std::vector<fs::path> PackagePaths() const {
    const fs::path here = fs::path(rd_.file()).parent_path();
    std::vector<fs::path> out;
    const YAML::Node paths = FieldReader::Get(root_, "package_paths");
    if (FieldReader::Present(paths)) {
      if (!paths.IsSequence()) rd_.Fail(paths, "package_paths", "must be a list of directories");
      for (std::size_t i = 0; i < paths.size(); ++i) {
        const fs::path p = rd_.ToString(paths[i], fmt::format("package_paths[{}]", i));
        out.push_back(p.is_absolute() ? p : here / p);
      }
    }
    const fs::path urdf_dir = fs::path(urdf_.path()).parent_path();
    out.push_back(urdf_dir);
    out.push_back(urdf_dir.parent_path());
    return out;
  }

  // The suspension's max_length_m of this wheel (its own, else wheel_defaults').
  double MaxLength(const YAML::Node& entry, const std::string& field) const {
    const YAML::Node own = FieldReader::Get(FieldReader::Get(entry, "suspension"), "max_length_m");
    const YAML::Node dflt = FieldReader::Get(
        FieldReader::Get(FieldReader::Get(root_, "wheel_defaults"), "suspension"), "max_length_m");
    const YAML::Node n = FieldReader::Present(own) ? own : dflt;
    if (!FieldReader::Present(n)) {
      rd_.Fail(entry, field + ".suspension.max_length_m",
               "is required: the URDF's wheel centre is where the wheel hangs, max_length_m "
               "below its mount");
    }
    return rd_.ToNumber(n, field + ".suspension.max_length_m", 1e-4, 2);
  }

  void FillWheel(YAML::Node entry, const WheelInUrdf& w) {
    const std::string field = WheelField(entry);
    const std::string joint = urdf_.Joint(w.joint);
    const urdf::LinkConstSharedPtr child =
        model_.getLink(model_.getJoint(w.joint)->child_link_name);
    if (!FieldReader::Present(FieldReader::Get(entry, "name"))) entry["name"] = w.joint;
    // Mount: max_length_m above the wheel centre, in B (origin at the chassis' centre of mass).
    const Vector3d centre = w.joint_in_base.translation() - com_;
    const double lift = MaxLength(entry, field);
    const Vector3d mount(Nanometres(centre.x()), Nanometres(centre.y()),
                         Nanometres(centre.z() + lift));
    Provide3(entry, "mount_m", field + ".mount_m", mount, joint + " origin");
    // Positive rotation about the axle a rolls along f = a x z: heading atan2(-a_x, a_y).
    const Vector3d& a = w.axis_base;
    const double heading =
        NanoDegrees(std::atan2(a.x() == 0 ? 0.0 : -a.x(), a.y()) * 180.0 / std::numbers::pi);
    if (WheelKind(entry) != "caster") {
      Provide(entry, "heading_deg", field + ".heading_deg", heading, joint + " axis", true);
    }
    // Radius: the child link's collision cylinder or sphere.
    for (const auto& c : child->collision_array) {
      if (!c || !c->geometry) continue;
      double r = -1;
      std::string what;
      if (c->geometry->type == urdf::Geometry::CYLINDER) {
        r = static_cast<const urdf::Cylinder&>(*c->geometry).radius;
        what = "collision cylinder";
      } else if (c->geometry->type == urdf::Geometry::SPHERE) {
        r = static_cast<const urdf::Sphere&>(*c->geometry).radius;
        what = "collision sphere";
      }
      if (r > 0) {
        Provide(entry, "radius_m", field + ".radius_m", Nanometres(r),
                urdf_.Link(child->name) + " " + what);
        break;
      }
    }
    // Mass and inertia about the spin axis: the child link and everything under it.
    Lumped wheel;
    double about_axis = 0;
    const Vector3d& axis_j = w.axis_joint;
    for (const std::string& name : w.links) {
      const urdf::LinkConstSharedPtr link = model_.getLink(name);
      if (!link->inertial) continue;
      Isometry3d in_joint;  // the child link's frame is the joint's
      if (!LinkIn(child->name, link, &in_joint, nullptr)) continue;
      const urdf::Inertial& in = *link->inertial;
      const Vector3d c = in_joint * ToVector(in.origin.position);
      const Matrix3d i_c =
          in_joint.linear() * InertiaInLinkFrame(in) * in_joint.linear().transpose();
      const Vector3d off_axis = c - c.dot(axis_j) * axis_j;
      about_axis += axis_j.dot(i_c * axis_j) + in.mass * off_axis.squaredNorm();
      wheel.Add(in.mass, c, i_c);
    }
    if (wheel.mass > 0) {
      const std::string source = urdf_.Link(child->name) + " <inertial>";
      Provide(entry, "inertia_kg_m2", field + ".inertia_kg_m2", about_axis, source);
      YAML::Node susp = entry["suspension"];
      if (!susp.IsDefined() || susp.IsNull()) {
        entry["suspension"] = YAML::Node(YAML::NodeType::Map);
        susp = entry["suspension"];
      }
      Provide(susp, "hub_mass_kg", field + ".suspension.hub_mass_kg", wheel.mass, source);
    }
    entry.remove("joint");
  }

  std::string WheelField(const YAML::Node& entry) const {
    const YAML::Node wheels = root_["wheels"];
    for (std::size_t i = 0; i < wheels.size(); ++i) {
      if (wheels[i].is(entry)) return fmt::format("wheels[{}]", i);
    }
    return "wheels[?]";
  }

  YAML::Node root_;
  const FieldReader& rd_;
  const Urdf& urdf_;
  const urdf::ModelInterface& model_;
  urdf::LinkConstSharedPtr base_;
  Vector3d com_ = Vector3d::Zero();  // the chassis' centre of mass in the base link frame
};

}  // namespace

void ImportRobotDescription(YAML::Node root, const FieldReader& rd) {
  const YAML::Node urdf_node = FieldReader::Get(root, "urdf");
  if (!FieldReader::Present(urdf_node)) {
    for (const char* key : {"base_link", "package_paths"}) {
      const YAML::Node n = FieldReader::Get(root, key);
      if (n.IsDefined()) rd.Fail(n, key, "only with urdf: (a platform read from a URDF file)");
    }
    const YAML::Node wheels = FieldReader::Get(root, "wheels");
    for (std::size_t i = 0; wheels.IsSequence() && i < wheels.size(); ++i) {
      const YAML::Node joint = FieldReader::Get(wheels[i], "joint");
      if (joint.IsDefined()) {
        rd.Fail(joint, fmt::format("wheels[{}].joint", i),
                "only with urdf: (the joint of a URDF file this wheel is)");
      }
    }
    return;
  }
  const std::string written = rd.ToString(urdf_node, "urdf");
  const fs::path path = fs::path(written).is_absolute()
                            ? fs::path(written)
                            : fs::path(rd.file()).parent_path() / written;
  Urdf urdf(path.lexically_normal().string(), written);
  if (const std::string problem = urdf.Load(); !problem.empty()) {
    // Problems of the file itself say where it was looked for; those of its text carry its name.
    const bool of_file = problem.rfind(urdf.shown(), 0) != 0;
    rd.Fail(urdf_node, "urdf",
            of_file ? fmt::format("{} ({}) {}", written, path.lexically_normal().string(), problem)
                    : problem);
  }
  Importer(root, rd, urdf).Run();
}

}  // namespace wheelhil::emulator::platforms
