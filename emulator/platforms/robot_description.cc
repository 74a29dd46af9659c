#include "emulator/platforms/robot_description.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>
#include <optional>
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
#include <sdf/sdf.hh>

namespace wheelhil::emulator::platforms {

namespace {

namespace fs = std::filesystem;
using bus::yaml::FieldReader;
using Eigen::Isometry3d;
using Eigen::Matrix3d;
using Eigen::Vector3d;

constexpr double kAgreement = 1e-9;  // relative: the description's value and the overlay's agree

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

// A robot description read from URDF or SDF, as the import needs it: links and the joints
// between them, each with where the file states it ("robot.urdf:12: link 'base_link'").
struct Geometry {
  enum Kind { kOther, kBox, kCylinder, kSphere, kMesh } kind = kOther;
  Vector3d box_size = Vector3d::Zero();
  double radius = 0;
  std::string mesh_uri;
};

struct Link {
  std::string where;
  bool has_inertial = false;
  double mass = 0;
  Vector3d com = Vector3d::Zero();      // in the link's frame
  Matrix3d inertia = Matrix3d::Zero();  // about the centre of mass, in the link's frame
  std::vector<Geometry> collisions;
  std::vector<Geometry> visuals;
  std::string parent_joint;  // "" for a root
  std::vector<std::string> child_links;
  // Gazebo's anisotropic friction on the link's first collision that has it: the direction of
  // mu (fdir1) in the link's frame, mu and mu2 (along fdir1 x normal), where it is stated.
  std::optional<Vector3d> fdir1;
  double mu = 1, mu2 = 1;
  std::string fdir1_where;
};

// The collision a wheel rolls on: the link's first cylinder or sphere with a radius; nullptr
// when it has none.
const Geometry* RollingCollision(const Link& link) {
  for (const Geometry& g : link.collisions) {
    if ((g.kind == Geometry::kCylinder || g.kind == Geometry::kSphere) && g.radius > 0) return &g;
  }
  return nullptr;
}

struct Joint {
  std::string where;
  enum Kind { kFixed, kContinuous, kOther } kind = kOther;
  std::string type;  // as the file names it
  std::string parent, child;
  Isometry3d joint_in_parent = Isometry3d::Identity();  // at the joint's zero position
  Isometry3d child_in_joint = Isometry3d::Identity();   // URDF: the child's frame is the joint's
  Vector3d axis = Vector3d::UnitZ();                    // in the joint's frame
};

struct RobotModel {
  std::string path;    // as opened
  std::string shown;   // as the platform file wrote it
  std::string format;  // "URDF", "SDF"
  std::string name;
  std::string root;  // the link with no parent joint (URDF), the canonical link (SDF)
  std::map<std::string, Link> links;
  std::map<std::string, Joint> joints;
};

// A regular file of bounded size before a byte is read (/dev/zero never ends). "" when fine.
std::string CheckFile(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) return "does not exist";
  if (!fs::is_regular_file(path, ec)) return "is not a regular file (a device, a pipe?)";
  if (fs::file_size(path, ec) > FieldReader::kMaxFileBytes || ec) return "is larger than 16 MiB";
  return {};
}

std::string ReadText(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

Geometry FromUrdf(const urdf::GeometrySharedPtr& g) {
  Geometry out;
  if (!g) return out;
  switch (g->type) {
    case urdf::Geometry::BOX:
      out.kind = Geometry::kBox;
      out.box_size = ToVector(static_cast<const urdf::Box&>(*g).dim);
      break;
    case urdf::Geometry::CYLINDER:
      out.kind = Geometry::kCylinder;
      out.radius = static_cast<const urdf::Cylinder&>(*g).radius;
      break;
    case urdf::Geometry::SPHERE:
      out.kind = Geometry::kSphere;
      out.radius = static_cast<const urdf::Sphere&>(*g).radius;
      break;
    case urdf::Geometry::MESH:
      out.kind = Geometry::kMesh;
      out.mesh_uri = static_cast<const urdf::Mesh&>(*g).filename;
      break;
    default:
      break;
  }
  return out;
}

// Empty on success, else what is wrong (with the line where the XML says it).
std::string LoadUrdf(RobotModel* m) {
  const std::string text = ReadText(m->path);
  TiXmlDocument xml;
  xml.Parse(text.c_str());
  if (xml.Error()) {
    return fmt::format("{}:{}:{}: not well-formed XML: {}", m->shown, xml.ErrorRow(),
                       xml.ErrorCol(), xml.ErrorDesc());
  }
  const TiXmlElement* robot = xml.RootElement();
  if (robot == nullptr || std::string(robot->Value()) != "robot") {
    return fmt::format("{}: the root element is not <robot>", m->shown);
  }
  std::map<std::string, int> link_lines, joint_lines;
  struct GazeboFriction {
    Vector3d fdir1;
    double mu = 1, mu2 = 1;
    int line = 0;
  };
  std::map<std::string, GazeboFriction> gazebo;
  for (const TiXmlElement* e = robot->FirstChildElement(); e != nullptr;
       e = e->NextSiblingElement()) {
    const char* reference = e->Attribute("reference");
    if (std::string(e->Value()) == "gazebo" && reference != nullptr) {
      const TiXmlElement* fdir1 = e->FirstChildElement("fdir1");
      if (fdir1 != nullptr && fdir1->GetText() != nullptr) {
        GazeboFriction g;
        std::istringstream in(fdir1->GetText());
        in >> g.fdir1.x() >> g.fdir1.y() >> g.fdir1.z();
        if (!in) {
          return fmt::format("{}:{}: <gazebo reference='{}'> fdir1 '{}' is not three numbers",
                             m->shown, fdir1->Row(), reference, fdir1->GetText());
        }
        for (const auto& [tag, value] : {std::pair{"mu1", &g.mu}, std::pair{"mu2", &g.mu2}}) {
          const TiXmlElement* mu = e->FirstChildElement(tag);
          if (mu != nullptr && mu->GetText() != nullptr) *value = std::atof(mu->GetText());
        }
        g.line = fdir1->Row();
        gazebo[reference] = g;
      }
    }
    const char* name = e->Attribute("name");
    if (name == nullptr) continue;
    if (std::string(e->Value()) == "link") link_lines.emplace(name, e->Row());
    if (std::string(e->Value()) == "joint") joint_lines.emplace(name, e->Row());
  }
  auto where = [&](const char* what, const std::map<std::string, int>& lines,
                   const std::string& name) {
    const auto it = lines.find(name);
    return it == lines.end() ? fmt::format("{}: {} '{}'", m->shown, what, name)
                             : fmt::format("{}:{}: {} '{}'", m->shown, it->second, what, name);
  };
  CapturedLog log;
  const urdf::ModelInterfaceSharedPtr model = urdf::parseURDF(text);
  if (!model) {
    return fmt::format("{}: urdfdom cannot read it: {}", m->shown,
                       log.text().empty() ? "(no reason given)" : log.text());
  }
  m->format = "URDF";
  m->name = model->getName();
  m->root = model->getRoot()->name;
  for (const auto& [name, l] : model->links_) {
    Link& link = m->links[name];
    link.where = where("link", link_lines, name);
    if (l->inertial) {
      link.has_inertial = true;
      link.mass = l->inertial->mass;
      link.com = ToVector(l->inertial->origin.position);
      link.inertia = InertiaInLinkFrame(*l->inertial);
    }
    for (const auto& c : l->collision_array) {
      if (c) link.collisions.push_back(FromUrdf(c->geometry));
    }
    if (const auto g = gazebo.find(name); g != gazebo.end()) {
      // Gazebo reads these in the link's collision frame.
      const Matrix3d r =
          l->collision ? ToIsometry(l->collision->origin).linear() : Matrix3d(Matrix3d::Identity());
      link.fdir1 = r * g->second.fdir1;
      link.mu = g->second.mu;
      link.mu2 = g->second.mu2;
      link.fdir1_where =
          fmt::format("{}:{}: <gazebo reference='{}'> fdir1", m->shown, g->second.line, name);
    }
    for (const auto& v : l->visual_array) {
      if (v) link.visuals.push_back(FromUrdf(v->geometry));
    }
  }
  for (const auto& [name, j] : model->joints_) {
    Joint& joint = m->joints[name];
    joint.where = where("joint", joint_lines, name);
    joint.kind = j->type == urdf::Joint::FIXED        ? Joint::kFixed
                 : j->type == urdf::Joint::CONTINUOUS ? Joint::kContinuous
                                                      : Joint::kOther;
    joint.type = j->type == urdf::Joint::REVOLUTE    ? "revolute"
                 : j->type == urdf::Joint::PRISMATIC ? "prismatic"
                 : j->type == urdf::Joint::FLOATING  ? "floating"
                 : j->type == urdf::Joint::PLANAR    ? "planar"
                 : j->type == urdf::Joint::FIXED     ? "fixed"
                                                     : "continuous";
    joint.parent = j->parent_link_name;
    joint.child = j->child_link_name;
    joint.joint_in_parent = ToIsometry(j->parent_to_joint_origin_transform);
    joint.axis = ToVector(j->axis);
    m->links[joint.child].parent_joint = name;
    m->links[joint.parent].child_links.push_back(joint.child);
  }
  return {};
}

Isometry3d ToIsometry(const ignition::math::Pose3d& p) {
  Isometry3d t = Isometry3d::Identity();
  const auto& q = p.Rot();
  t.linear() = Eigen::Quaterniond(q.W(), q.X(), q.Y(), q.Z()).normalized().toRotationMatrix();
  t.translation() = Vector3d(p.Pos().X(), p.Pos().Y(), p.Pos().Z());
  return t;
}

Geometry FromSdf(const sdf::Geometry* g) {
  Geometry out;
  if (g == nullptr) return out;
  switch (g->Type()) {
    case sdf::GeometryType::BOX:
      out.kind = Geometry::kBox;
      out.box_size = {g->BoxShape()->Size().X(), g->BoxShape()->Size().Y(),
                      g->BoxShape()->Size().Z()};
      break;
    case sdf::GeometryType::CYLINDER:
      out.kind = Geometry::kCylinder;
      out.radius = g->CylinderShape()->Radius();
      break;
    case sdf::GeometryType::SPHERE:
      out.kind = Geometry::kSphere;
      out.radius = g->SphereShape()->Radius();
      break;
    case sdf::GeometryType::MESH:
      out.kind = Geometry::kMesh;
      out.mesh_uri = g->MeshShape()->Uri();
      break;
    default:
      break;
  }
  return out;
}

// The first of `errors` as "file:line: message".
std::string SdfError(const sdf::Errors& errors, const std::string& shown) {
  const sdf::Error& e = errors.front();
  std::string at = shown;
  if (e.LineNumber()) at += fmt::format(":{}", *e.LineNumber());
  return fmt::format("{}: {}", at, e.Message());
}

std::string LoadSdf(RobotModel* m, const std::string& model_name) {
  sdf::Root root;
  sdf::Console::Instance()->SetQuiet(true);
  const sdf::Errors errors = root.Load(m->path);
  if (!errors.empty()) return "not a valid SDF file: " + SdfError(errors, m->shown);
  const sdf::Model* model = root.Model();
  std::vector<std::string> names;
  for (uint64_t w = 0; w < root.WorldCount(); ++w) {
    const sdf::World* world = root.WorldByIndex(w);
    for (uint64_t i = 0; i < world->ModelCount(); ++i) {
      names.push_back(world->ModelByIndex(i)->Name());
      if (!model_name.empty() && world->ModelByIndex(i)->Name() == model_name) {
        model = world->ModelByIndex(i);
      }
    }
  }
  if (model != nullptr && !model_name.empty() && model->Name() != model_name) model = nullptr;
  if (model == nullptr) {
    std::string list;
    for (const auto& n : names) list += (list.empty() ? "" : ", ") + n;
    return model_name.empty()
               ? fmt::format(
                     "{} holds no top-level <model> (its worlds' models: {}): name one "
                     "with model:",
                     m->shown, list.empty() ? "none" : list)
               : fmt::format("{} has no model '{}' (its models: {})", m->shown, model_name,
                             list.empty() ? (root.Model() ? root.Model()->Name() : "none") : list);
  }
  auto where = [&](const char* what, const sdf::ElementPtr& e, const std::string& name) {
    return e && e->LineNumber()
               ? fmt::format("{}:{}: {} '{}'", m->shown, *e->LineNumber(), what, name)
               : fmt::format("{}: {} '{}'", m->shown, what, name);
  };
  m->format = "SDF";
  m->name = model->Name();
  m->root = model->CanonicalLinkName().empty() && model->LinkCount() > 0
                ? model->LinkByIndex(0)->Name()
                : model->CanonicalLinkName();
  std::map<std::string, Isometry3d> in_model;
  for (uint64_t i = 0; i < model->LinkCount(); ++i) {
    const sdf::Link* l = model->LinkByIndex(i);
    Link& link = m->links[l->Name()];
    link.where = where("link", l->Element(), l->Name());
    ignition::math::Pose3d pose;
    const sdf::Errors pe = l->SemanticPose().Resolve(pose, "__model__");
    if (!pe.empty()) return SdfError(pe, m->shown);
    in_model[l->Name()] = ToIsometry(pose);
    const ignition::math::Inertiald& in = l->Inertial();
    if (l->Element() && l->Element()->HasElement("inertial")) {
      link.has_inertial = true;
      link.mass = in.MassMatrix().Mass();
      const Isometry3d frame = ToIsometry(in.Pose());
      link.com = frame.translation();
      Matrix3d moi;
      const auto& i3 = in.MassMatrix().Moi();
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) moi(r, c) = i3(r, c);
      }
      link.inertia = frame.linear() * moi * frame.linear().transpose();
    }
    for (uint64_t c = 0; c < l->CollisionCount(); ++c) {
      const sdf::Collision* col = l->CollisionByIndex(c);
      link.collisions.push_back(FromSdf(col->Geom()));
      // <surface><friction><ode><fdir1>: in the collision's frame.
      sdf::ElementPtr e = col->Element();
      for (const char* step : {"surface", "friction", "ode"}) {
        e = e && e->HasElement(step) ? e->FindElement(step) : nullptr;
      }
      if (link.fdir1 || !e || !e->HasElement("fdir1")) continue;
      const auto f = e->Get<ignition::math::Vector3d>("fdir1");
      if (f.Length() == 0) continue;
      ignition::math::Pose3d in_link;
      if (!col->SemanticPose().Resolve(in_link, l->Name()).empty()) continue;
      link.fdir1 = ToIsometry(in_link).linear() * Vector3d(f.X(), f.Y(), f.Z());
      link.mu = e->HasElement("mu") ? e->Get<double>("mu") : 1.0;
      link.mu2 = e->HasElement("mu2") ? e->Get<double>("mu2") : 1.0;
      const sdf::ElementPtr fe = e->FindElement("fdir1");
      link.fdir1_where =
          fe && fe->LineNumber()
              ? fmt::format("{}:{}: link '{}' fdir1", m->shown, *fe->LineNumber(), l->Name())
              : fmt::format("{}: link '{}' fdir1", m->shown, l->Name());
    }
    for (uint64_t v = 0; v < l->VisualCount(); ++v) {
      link.visuals.push_back(FromSdf(l->VisualByIndex(v)->Geom()));
    }
  }
  for (uint64_t i = 0; i < model->JointCount(); ++i) {
    const sdf::Joint* j = model->JointByIndex(i);
    Joint& joint = m->joints[j->Name()];
    joint.where = where("joint", j->Element(), j->Name());
    const bool limitless = j->Axis(0) != nullptr &&
                           (std::isinf(j->Axis(0)->Lower()) || std::isinf(j->Axis(0)->Upper()) ||
                            j->Axis(0)->Upper() - j->Axis(0)->Lower() >= 1e15);
    joint.kind = j->Type() == sdf::JointType::FIXED                   ? Joint::kFixed
                 : j->Type() == sdf::JointType::CONTINUOUS            ? Joint::kContinuous
                 : j->Type() == sdf::JointType::REVOLUTE && limitless ? Joint::kContinuous
                                                                      : Joint::kOther;
    joint.type = j->Element() ? j->Element()->Get<std::string>("type") : "?";
    joint.parent = j->ParentLinkName();
    joint.child = j->ChildLinkName();
    if (m->links.count(joint.parent) == 0 || m->links.count(joint.child) == 0) continue;  // world
    // The joint's frame in the child's, and the child's in the parent's at zero position.
    ignition::math::Pose3d in_child;
    const sdf::Errors je = j->SemanticPose().Resolve(in_child, joint.child);
    if (!je.empty()) return SdfError(je, m->shown);
    joint.child_in_joint = ToIsometry(in_child).inverse();
    joint.joint_in_parent =
        in_model[joint.parent].inverse() * in_model[joint.child] * ToIsometry(in_child);
    if (j->Axis(0) != nullptr) {
      ignition::math::Vector3d xyz;
      const sdf::Errors ae = j->Axis(0)->ResolveXyz(xyz, j->Name());
      if (!ae.empty()) return SdfError(ae, m->shown);
      joint.axis = {xyz.X(), xyz.Y(), xyz.Z()};
    }
    m->links[joint.child].parent_joint = j->Name();
    m->links[joint.parent].child_links.push_back(joint.child);
  }
  return {};
}

// The pose of `link`'s frame in the frame of link `top` above it, through the joints between
// at their zero positions; false when `link` is not under `top`. `moving`: the joints passed
// that are not fixed.
bool LinkInFrameOf(const RobotModel& m, const std::string& top, const std::string& link,
                   Isometry3d* pose, std::vector<std::string>* moving) {
  Isometry3d t = Isometry3d::Identity();
  std::string at = link;
  for (std::size_t depth = 0; at != top; ++depth) {
    const auto l = m.links.find(at);
    if (l == m.links.end() || l->second.parent_joint.empty() || depth > m.links.size()) {
      return false;
    }
    const Joint& j = m.joints.at(l->second.parent_joint);
    if (j.kind != Joint::kFixed && moving != nullptr) moving->push_back(l->second.parent_joint);
    t = j.joint_in_parent * j.child_in_joint * t;
    at = j.parent;
  }
  *pose = t;
  return true;
}

// A wheel the overlay declares, as the description places it.
struct WheelInModel {
  std::string joint;
  Isometry3d joint_in_base = Isometry3d::Identity();  // the joint frame in the base link frame
  Vector3d axis_base = Vector3d::UnitY();             // the spin axis in the base link frame
  Vector3d axis_joint = Vector3d::UnitY();            // and in the joint's
  std::set<std::string> links;                        // the child link and all under it
};

class Importer {
 public:
  Importer(YAML::Node root, const FieldReader& rd, const RobotModel& model)
      : root_(std::move(root)), rd_(rd), m_(model) {}

  void Run() {
    ChooseBase();
    const YAML::Node wheels = FieldReader::Get(root_, "wheels");
    if (wheels.IsDefined() && !wheels.IsSequence()) rd_.Fail(wheels, "wheels", "must be a list");
    std::vector<std::pair<YAML::Node, WheelInModel>> declared;
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
    for (auto& [entry, w] : declared) FillWheel(entry, w);
    if (!FieldReader::Present(FieldReader::Get(root_, "name"))) root_["name"] = m_.name;
    for (const char* key : {"urdf", "sdf", "model", "base_link", "package_paths"}) {
      root_.remove(key);
    }
  }

 private:
  const Link& LinkNamed(const std::string& name) const { return m_.links.at(name); }

  YAML::Node FileNode() const {
    const YAML::Node u = FieldReader::Get(root_, "urdf");
    return u.IsDefined() ? u : FieldReader::Get(root_, "sdf");
  }
  std::string FileField() const {
    return FieldReader::Get(root_, "urdf").IsDefined() ? "urdf" : "sdf";
  }

  void ChooseBase() {
    const YAML::Node base = FieldReader::Get(root_, "base_link");
    base_ = m_.root;
    if (FieldReader::Present(base)) {
      base_ = rd_.ToString(base, "base_link");
      if (m_.links.count(base_) == 0) {
        rd_.Fail(base, "base_link", fmt::format("{} has no link '{}'", m_.shown, base_));
      }
    }
  }

  // The pose of `link`'s frame in the frame of link `top` above it, through the joints between
  // at their zero positions; false when `link` is not under `top`. `moving`: the joints passed
  // that are not fixed.
  bool LinkIn(const std::string& top, const std::string& link, Isometry3d* pose,
              std::vector<std::string>* moving) const {
    return LinkInFrameOf(m_, top, link, pose, moving);
  }

  void Subtree(const std::string& link, std::set<std::string>* out) const {
    if (!out->insert(link).second) return;
    for (const auto& child : LinkNamed(link).child_links) Subtree(child, out);
  }

  WheelInModel Locate(const YAML::Node& entry, const YAML::Node& joint_node,
                      const std::string& field) const {
    const std::string f = field + ".joint";
    const std::string name = rd_.ToString(joint_node, f);
    const auto found = m_.joints.find(name);
    if (found == m_.joints.end()) {
      std::string known;
      for (const auto& [n, joint] : m_.joints) {
        if (joint.kind == Joint::kContinuous) known += (known.empty() ? "" : ", ") + n;
      }
      rd_.Fail(joint_node, f,
               fmt::format("{} has no joint '{}' (its continuous joints: {})", m_.shown, name,
                           known.empty() ? "none" : known));
    }
    const Joint& j = found->second;
    if (j.kind != Joint::kContinuous) {
      rd_.Fail(joint_node, f,
               fmt::format("{} is {}, not a continuous joint: a wheel spins without limits",
                           j.where, j.type));
    }
    WheelInModel w;
    w.joint = name;
    Isometry3d parent_in_base;
    std::vector<std::string> moving;
    if (m_.links.count(j.parent) == 0 || !LinkIn(base_, j.parent, &parent_in_base, &moving)) {
      rd_.Fail(joint_node, f, fmt::format("{} is not under the base link '{}'", j.where, base_));
    }
    if (!moving.empty() && WheelKind(entry) != "caster") {
      rd_.Fail(joint_node, f,
               fmt::format("{} hangs from the chassis through joint '{}', which moves: only a "
                           "caster's wheel may (its swivel)",
                           j.where, moving.front()));
    }
    w.joint_in_base = parent_in_base * j.joint_in_parent;
    if (j.axis.norm() < 1e-12) rd_.Fail(joint_node, f, fmt::format("{} has a zero axis", j.where));
    w.axis_joint = j.axis.normalized();
    w.axis_base = w.joint_in_base.linear() * w.axis_joint;
    if (std::abs(w.axis_base.z()) > 1e-6) {
      rd_.Fail(joint_node, f,
               fmt::format("{}: its axis in the base link's frame ({:.6g}, {:.6g}, {:.6g}) is "
                           "not horizontal; wheelhil's wheels spin about a horizontal axle",
                           j.where, w.axis_base.x(), w.axis_base.y(), w.axis_base.z()));
    }
    Subtree(j.child, &w.links);
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
               const std::string& source, bool degrees = false, double period = 360.0) const {
    const YAML::Node given = FieldReader::Get(map, key);
    if (FieldReader::Present(given)) {
      const double v = rd_.ToNumber(given, field);
      const double diff =
          degrees || period != 360.0 ? std::remainder(v - value, period) : v - value;
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
    for (const auto& [name, link] : m_.links) {
      if (wheel_links.count(name) != 0 || !link.has_inertial) continue;
      Isometry3d pose;
      if (!LinkIn(base_, name, &pose, nullptr)) continue;  // above the base link
      body.Add(link.mass, pose * link.com,
               pose.linear() * link.inertia * pose.linear().transpose());
    }
    const Link& base = LinkNamed(base_);
    const YAML::Node base_node = FieldReader::Get(root_, "base_link");
    const YAML::Node at = base_node.IsDefined() ? base_node : FileNode();
    const std::string at_field = base_node.IsDefined() ? "base_link" : FileField();
    if (body.mass <= 0) {
      rd_.Fail(at, at_field,
               fmt::format("{} and the links fixed to it have no <inertial> mass: the chassis "
                           "needs one",
                           base.where));
    }
    com_ = body.com();
    const Matrix3d i = body.about_com();
    YAML::Node chassis = Section("chassis");
    const std::string source =
        fmt::format("{} (with the links under it but the wheels)", base.where);
    Provide(chassis, "mass_kg", "chassis.mass_kg", body.mass, source);
    const double off = std::max({std::abs(i(0, 1)), std::abs(i(0, 2)), std::abs(i(1, 2))});
    const bool principal = off <= 1e-6 * i.diagonal().maxCoeff();
    if (principal) {
      Provide3(chassis, "inertia_kg_m2", "chassis.inertia_kg_m2", i.diagonal(), source);
    } else if (!FieldReader::Present(FieldReader::Get(chassis, "inertia_kg_m2"))) {
      rd_.Fail(at, at_field,
               fmt::format("{}: the chassis' inertia about its centre of mass has products of "
                           "inertia (Ixy {:.6g}, Ixz {:.6g}, Iyz {:.6g} kg*m^2), which wheelhil "
                           "cannot take as principal moments along the body axes: give "
                           "chassis.inertia_kg_m2 in this file",
                           source, i(0, 1), i(0, 2), i(1, 2)));
    }
    for (const Geometry& g : base.collisions) {
      if (g.kind != Geometry::kBox) continue;
      const Vector3d half(Nanometres(0.5 * g.box_size.x()), Nanometres(0.5 * g.box_size.y()),
                          Nanometres(0.5 * g.box_size.z()));
      Provide3(chassis, "half_extents_m", "chassis.half_extents_m", half,
               base.where + " collision box");
      break;
    }
    const std::string mesh = ChassisMesh(base);
    if (!mesh.empty() && !FieldReader::Present(FieldReader::Get(chassis, "mesh"))) {
      chassis["mesh"] = mesh;
    }
  }

  // The base link's collision mesh (else its visual mesh), resolved; "" when it has none.
  std::string ChassisMesh(const Link& base) const {
    for (const auto* list : {&base.collisions, &base.visuals}) {
      for (const Geometry& g : *list) {
        if (g.kind == Geometry::kMesh) return ResolveUri(g.mesh_uri, base);
      }
    }
    return {};
  }

  std::string ResolveUri(const std::string& uri, const Link& base) const {
    const fs::path file_dir = fs::path(m_.path).parent_path();
    std::vector<fs::path> tried;
    auto found = [&](const fs::path& p) {
      tried.push_back(p);
      std::error_code ec;
      return fs::is_regular_file(p, ec);
    };
    const std::string package = "package://";
    const std::string model = "model://";
    const std::string file = "file://";
    const bool by_package = uri.rfind(package, 0) == 0 || uri.rfind(model, 0) == 0;
    if (by_package) {
      const std::string rest = uri.substr(uri.find("://") + 3);
      const std::size_t slash = rest.find('/');
      const std::string name = rest.substr(0, slash);
      const std::string inside = slash == std::string::npos ? "" : rest.substr(slash + 1);
      for (const fs::path& dir : PackagePaths()) {
        if (found(dir / name / inside)) return (dir / name / inside).lexically_normal();
        if (dir.filename() == name && found(dir / inside)) return (dir / inside).lexically_normal();
      }
    } else if (uri.rfind(file, 0) == 0) {
      if (found(uri.substr(file.size()))) return uri.substr(file.size());
    } else if (found(file_dir / uri)) {
      return (file_dir / uri).lexically_normal();
    }
    std::string list;
    for (const auto& p : tried) list += (list.empty() ? "" : ", ") + p.string();
    rd_.Fail(
        FileNode(), FileField(),
        fmt::format("{}: its mesh '{}' is not found (looked at: {}){}", base.where, uri,
                    list.empty() ? "nothing" : list,
                    by_package ? "; package_paths lists the directories that hold packages" : ""));
  }

  // package_paths, relative to the platform file; the description's directory and its parent
  // last.
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
    const fs::path file_dir = fs::path(m_.path).parent_path();
    out.push_back(file_dir);
    out.push_back(file_dir.parent_path());
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
               fmt::format("is required: the {}'s wheel centre is where the wheel hangs, "
                           "max_length_m below its mount",
                           m_.format));
    }
    return rd_.ToNumber(n, field + ".suspension.max_length_m", 1e-4, 2);
  }

  void FillWheel(YAML::Node entry, const WheelInModel& w) {
    const std::string field = WheelField(entry);
    const Joint& joint = m_.joints.at(w.joint);
    const Link& child = LinkNamed(joint.child);
    if (!FieldReader::Present(FieldReader::Get(entry, "name"))) entry["name"] = w.joint;
    // Mount: max_length_m above the wheel centre, in B (origin at the chassis' centre of mass).
    const Vector3d centre = w.joint_in_base.translation() - com_;
    const double lift = MaxLength(entry, field);
    const Vector3d mount(Nanometres(centre.x()), Nanometres(centre.y()),
                         Nanometres(centre.z() + lift));
    Provide3(entry, "mount_m", field + ".mount_m", mount, joint.where + " origin");
    // Positive rotation about the axle a rolls along f = a x z: heading atan2(-a_x, a_y).
    const Vector3d& a = w.axis_base;
    const double heading =
        NanoDegrees(std::atan2(a.x() == 0 ? 0.0 : -a.x(), a.y()) * 180.0 / std::numbers::pi);
    if (WheelKind(entry) != "caster") {
      Provide(entry, "heading_deg", field + ".heading_deg", heading, joint.where + " axis", true);
    }
    // Radius: the child link's collision cylinder or sphere.
    if (const Geometry* g = RollingCollision(child)) {
      Provide(entry, "radius_m", field + ".radius_m", Nanometres(g->radius),
              child.where +
                  (g->kind == Geometry::kCylinder ? " collision cylinder" : " collision sphere"));
    }
    // A Mecanum wheel modelled Gazebo's way (a sphere or cylinder whose friction acts along
    // fdir1 only, or across it only): that direction is the roller axis.
    if (WheelKind(entry) == "mecanum" && child.fdir1) {
      const bool along = child.mu2 <= 1e-3 * child.mu;
      const bool across = child.mu <= 1e-3 * child.mu2;
      if (along || across) {
        const Vector3d z = Vector3d::UnitZ();
        Vector3d u = w.joint_in_base.linear() * (joint.child_in_joint.linear() * *child.fdir1);
        if (across) u = z.cross(u);
        const Vector3d f = w.axis_base.cross(z);
        double alpha = std::atan2(u.dot(f), u.dot(w.axis_base)) * 180.0 / std::numbers::pi;
        if (alpha > 90) alpha -= 180;
        if (alpha <= -90) alpha += 180;
        Provide(entry, "roller_angle_deg", field + ".roller_angle_deg", NanoDegrees(alpha),
                child.fdir1_where + (along ? " (mu along it, mu2 0)" : " (mu 0, mu2 across it)"),
                false, 180.0);
      }
    }
    // Mass and inertia about the spin axis: the child link and everything under it, in the
    // joint's frame (where the axis is stated, so an inertia about it arrives bit for bit).
    double mass = 0;
    double about_axis = 0;
    const Vector3d& axis = w.axis_joint;
    for (const std::string& name : w.links) {
      const Link& link = LinkNamed(name);
      if (!link.has_inertial) continue;
      Isometry3d in_child;
      if (!LinkIn(joint.child, name, &in_child, nullptr)) continue;
      const Isometry3d in_joint = joint.child_in_joint * in_child;
      const Vector3d c = in_joint * link.com;
      const Matrix3d i_c = in_joint.linear() * link.inertia * in_joint.linear().transpose();
      const Vector3d off_axis = c - c.dot(axis) * axis;
      about_axis += axis.dot(i_c * axis) + link.mass * off_axis.squaredNorm();
      mass += link.mass;
    }
    if (mass > 0) {
      const std::string source = child.where + " <inertial>";
      Provide(entry, "inertia_kg_m2", field + ".inertia_kg_m2", about_axis, source);
      YAML::Node susp = entry["suspension"];
      if (!susp.IsDefined() || susp.IsNull()) {
        entry["suspension"] = YAML::Node(YAML::NodeType::Map);
        susp = entry["suspension"];
      }
      Provide(susp, "hub_mass_kg", field + ".suspension.hub_mass_kg", mass, source);
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
  const RobotModel& m_;
  std::string base_;
  Vector3d com_ = Vector3d::Zero();  // the chassis' centre of mass in the base link frame
};

}  // namespace

void ImportRobotDescription(YAML::Node root, const FieldReader& rd) {
  rd.DeclareKeys("", {"urdf", "sdf", "model", "base_link", "package_paths"});
  if (const YAML::Node wheels = FieldReader::Get(root, "wheels"); wheels.IsSequence()) {
    for (std::size_t i = 0; i < wheels.size(); ++i) {
      rd.DeclareKeys(fmt::format("wheels[{}]", i), {"joint"});
    }
  }
  const YAML::Node urdf_node = FieldReader::Get(root, "urdf");
  const YAML::Node sdf_node = FieldReader::Get(root, "sdf");
  const bool urdf = FieldReader::Present(urdf_node);
  const bool sdf = FieldReader::Present(sdf_node);
  if (urdf && sdf) rd.Fail(sdf_node, "sdf", "a platform reads one description: urdf: or sdf:");
  if (!urdf && !sdf) {
    for (const char* key : {"base_link", "package_paths", "model"}) {
      const YAML::Node n = FieldReader::Get(root, key);
      if (n.IsDefined()) {
        rd.Fail(n, key, "only with urdf: or sdf: (a platform read from a robot description)");
      }
    }
    const YAML::Node wheels = FieldReader::Get(root, "wheels");
    for (std::size_t i = 0; wheels.IsSequence() && i < wheels.size(); ++i) {
      const YAML::Node joint = FieldReader::Get(wheels[i], "joint");
      if (joint.IsDefined()) {
        rd.Fail(joint, fmt::format("wheels[{}].joint", i),
                "only with urdf: or sdf: (the joint of the robot description this wheel is)");
      }
    }
    return;
  }
  const YAML::Node model_node = FieldReader::Get(root, "model");
  if (urdf && model_node.IsDefined()) {
    rd.Fail(model_node, "model", "only with sdf: (a URDF file holds one robot)");
  }
  const char* field = urdf ? "urdf" : "sdf";
  const YAML::Node node = urdf ? urdf_node : sdf_node;
  const std::string written = rd.ToString(node, field);
  const fs::path path = fs::path(written).is_absolute()
                            ? fs::path(written)
                            : fs::path(rd.file()).parent_path() / written;
  RobotModel model;
  model.path = path.lexically_normal().string();
  model.shown = written;
  if (const std::string problem = CheckFile(model.path); !problem.empty()) {
    rd.Fail(node, field, fmt::format("{} ({}) {}", written, model.path, problem));
  }
  const std::string model_name =
      FieldReader::Present(model_node) ? rd.ToString(model_node, "model") : std::string();
  const std::string problem = urdf ? LoadUrdf(&model) : LoadSdf(&model, model_name);
  if (!problem.empty()) rd.Fail(node, field, problem);
  if (model.links.count(model.root) == 0) {
    rd.Fail(node, field, fmt::format("{} has no links", written));
  }
  Importer(root, rd, model).Run();
}

std::vector<WheelJoint> FindWheelJoints(const std::string& path, const std::string& model_name,
                                        bool* base_has_box) {
  RobotModel model;
  model.path = path;
  model.shown = path;
  if (const std::string problem = CheckFile(path); !problem.empty()) {
    throw std::invalid_argument(fmt::format("{}: {}", path, problem));
  }
  const bool sdf = fs::path(path).extension() == ".sdf" || fs::path(path).extension() == ".world";
  const std::string problem = sdf ? LoadSdf(&model, model_name) : LoadUrdf(&model);
  if (!problem.empty()) throw std::invalid_argument(problem);
  *base_has_box = false;
  if (const auto base = model.links.find(model.root); base != model.links.end()) {
    for (const Geometry& g : base->second.collisions) *base_has_box |= g.kind == Geometry::kBox;
  }
  std::vector<WheelJoint> out;
  for (const auto& [name, j] : model.joints) {
    if (j.kind != Joint::kContinuous) continue;
    const auto child = model.links.find(j.child);
    if (child == model.links.end()) continue;
    const Geometry* rolling = RollingCollision(child->second);
    Isometry3d parent_in_base;
    std::vector<std::string> moving;
    if (rolling == nullptr ||
        !LinkInFrameOf(model, model.root, j.parent, &parent_in_base, &moving)) {
      continue;
    }
    const Isometry3d joint_in_base = parent_in_base * j.joint_in_parent;
    const Eigen::Vector3d axis = joint_in_base.linear() * j.axis.normalized();
    if (std::abs(axis.z()) > 1e-6) continue;  // a swivel or a steering joint
    WheelJoint w;
    w.joint = name;
    w.centre_m = joint_in_base.translation();
    w.axis = axis;
    w.radius_m = Nanometres(rolling->radius);
    w.below_moving_joint = !moving.empty();
    out.push_back(w);
  }
  return out;
}

}  // namespace wheelhil::emulator::platforms
