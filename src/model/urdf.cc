#include "stiffsim/model/urdf.h"

#include <console_bridge/console.h>
#include <tinyxml.h>
#include <urdf_parser/urdf_parser.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <set>
#include <sstream>
#include <system_error>

#include "stiffsim/error.h"

namespace stiffsim {

namespace {

// Far beyond any robot description, small enough that reading one cannot
// exhaust memory before urdfdom has even looked at it.
constexpr std::uintmax_t kMaxFileBytes = std::uintmax_t{64} << 20;
// URDF content sits at depth 4 at most (robot/link/visual/geometry/mesh is
// 5); tinyxml parses recursively, so absurd nesting would overflow the stack
// before it could report anything.
constexpr int kMaxXmlDepth = 100;

[[noreturn]] void fail(const std::string& source, const std::string& what) {
  throw InputError(source + ": " + what);
}

std::string quoted(const std::string& kind, const std::string& name) {
  return kind + " '" + name + "'";
}

// urdfdom's messages may span lines; ours must not.
std::string one_line(const std::string& text) {
  std::string out;
  bool space = false;
  for (char ch : text) {
    if (ch == '\n' || ch == '\r' || ch == '\t' || ch == ' ') {
      space = !out.empty();
      continue;
    }
    if (space) out += ' ';
    space = false;
    out += ch;
  }
  return out;
}

std::string join(const std::vector<std::string>& parts, const char* separator) {
  std::string out;
  for (const std::string& part : parts) {
    if (!out.empty()) out += separator;
    out += part;
  }
  return out;
}

// urdfdom reports through console_bridge, whose default handler prints to
// stderr. While a capture lives, what urdfdom says is collected instead, so
// that it ends up in the InputError (or nowhere, on success). The handler is
// process-global, hence the lock: two loaders on two threads must not
// restore each other's handlers.
class UrdfdomLogCapture {
 public:
  UrdfdomLogCapture() : lock_(mutex()) {
    handler().errors.clear();
    level_ = console_bridge::getLogLevel();
    // Errors must reach the handler even if someone silenced console_bridge.
    console_bridge::setLogLevel(console_bridge::CONSOLE_BRIDGE_LOG_WARN);
    console_bridge::useOutputHandler(&handler());
  }
  ~UrdfdomLogCapture() {
    console_bridge::restorePreviousOutputHandler();
    console_bridge::setLogLevel(level_);
  }
  UrdfdomLogCapture(const UrdfdomLogCapture&) = delete;
  UrdfdomLogCapture& operator=(const UrdfdomLogCapture&) = delete;

  const std::vector<std::string>& errors() const { return handler().errors; }
  void add_error(const std::string& text) { handler().errors.push_back(one_line(text)); }

 private:
  struct Handler : console_bridge::OutputHandler {
    void log(const std::string& text, console_bridge::LogLevel level, const char*, int) override {
      if (level >= console_bridge::CONSOLE_BRIDGE_LOG_ERROR) errors.push_back(one_line(text));
    }
    std::vector<std::string> errors;
  };
  // Never destroyed: restorePreviousOutputHandler() swaps, so console_bridge
  // keeps this handler as its "previous" one after the capture ends, and
  // whoever restores next must not find a dangling pointer there.
  static Handler& handler() {
    static Handler* const h = new Handler;
    return *h;
  }
  static std::mutex& mutex() {
    static std::mutex m;
    return m;
  }

  std::lock_guard<std::mutex> lock_;
  console_bridge::LogLevel level_;
};

int line_of(const std::string& text, size_t offset) {
  return 1 + static_cast<int>(std::count(text.begin(), text.begin() + offset, '\n'));
}

// Rejects what is not XML text before tinyxml sees it: binary files (tinyxml
// would report some confusing syntax error, or none) and nesting deep enough
// to exhaust tinyxml's recursion.
void check_text(const std::string& xml, const std::string& source) {
  if (xml.find_first_not_of(" \t\r\n") == std::string::npos) {
    fail(source, "empty file; expected URDF XML with a <robot> element");
  }
  for (size_t i = 0; i < xml.size(); ++i) {
    const unsigned char ch = static_cast<unsigned char>(xml[i]);
    if ((ch < 0x20 && ch != '\t' && ch != '\n' && ch != '\r') || ch == 0x7f) {
      char hex[8];
      std::snprintf(hex, sizeof hex, "0x%02x", ch);
      fail(source + ":" + std::to_string(line_of(xml, i)),
           std::string("not a text file (control byte ") + hex + "); expected URDF XML");
    }
  }
  // An upper bound of the element depth: comments, CDATA, declarations and
  // quoted attribute values are skipped so that a '<' or '/>' in them does
  // not count.
  int depth = 0;
  size_t i = 0;
  auto skip_past = [&](const char* end) {
    const size_t at = xml.find(end, i);
    i = at == std::string::npos ? xml.size() : at + std::strlen(end);
  };
  while ((i = xml.find('<', i)) != std::string::npos) {
    const size_t start = i;
    if (xml.compare(i, 4, "<!--") == 0) {
      skip_past("-->");
    } else if (xml.compare(i, 9, "<![CDATA[") == 0) {
      skip_past("]]>");
    } else if (xml.compare(i, 2, "<?") == 0) {
      skip_past("?>");
    } else if (xml.compare(i, 2, "<!") == 0) {
      skip_past(">");
    } else if (xml.compare(i, 2, "</") == 0) {
      // Never below zero: stray end tags must not buy depth for what follows.
      depth = std::max(depth - 1, 0);
      skip_past(">");
    } else {
      ++i;
      char quote = 0;
      while (i < xml.size() && (quote || xml[i] != '>')) {
        if (quote && xml[i] == quote) {
          quote = 0;
        } else if (!quote && (xml[i] == '"' || xml[i] == '\'')) {
          quote = xml[i];
        }
        ++i;
      }
      if (xml[i - 1] != '/') ++depth;
      if (depth > kMaxXmlDepth) {
        fail(source + ":" + std::to_string(line_of(xml, start)),
             "XML elements nested more than " + std::to_string(kMaxXmlDepth) +
                 " deep; expected URDF (links and joints directly under <robot>)");
      }
      if (i < xml.size()) ++i;
    }
  }
}

// What the loader drops before urdfdom parses the file, for the note.
struct Ignored {
  int links_with_geometry = 0;  // visual or collision
  int materials = 0;            // top-level <material>
  int transmissions = 0;
  int gazebo = 0;
  // Joints with each element that is not simulated.
  int limits = 0, mimic = 0, safety = 0, calibration = 0;
  std::set<std::string> other;  // any other element under <robot> or <link>
};

// A joint as the file states it, before urdfdom reads it.
struct XmlJoint {
  std::string name, parent, child;  // empty when absent (urdfdom then objects)
};

std::string attribute(const TiXmlElement* element, const char* name) {
  const char* value = element ? element->Attribute(name) : nullptr;
  return value ? value : "";
}

// urdfdom lets a later joint overwrite a link's parent, and a loop of joints
// makes its links own each other (shared pointers in a cycle, leaked), so the
// tree shape is checked on the XML first: one parent joint per link, no
// link its own ancestor.
void check_tree_shape(const std::vector<XmlJoint>& joints, const std::string& source) {
  struct Parent {
    std::string joint, link;
  };
  std::map<std::string, Parent> parent_of;  // by child link
  for (const XmlJoint& joint : joints) {
    if (joint.parent.empty() || joint.child.empty()) continue;
    const auto [it, inserted] = parent_of.emplace(joint.child, Parent{joint.name, joint.parent});
    if (!inserted) {
      fail(source, quoted("link", joint.child) + " is the child of two joints ('" +
                       it->second.joint + "' and '" + joint.name +
                       "'); expected a tree (one parent joint per link)");
    }
  }
  for (const XmlJoint& joint : joints) {
    if (joint.parent.empty() || joint.child.empty()) continue;
    // With one parent per link the walk up either reaches a root or enters
    // a loop; a loop that does not pass through this joint's child is
    // reported from one of its own joints, so the walk is bounded.
    std::vector<std::string> loop = {joint.name};
    std::string link = joint.parent;
    for (size_t steps = 0; steps <= parent_of.size(); ++steps) {
      if (link == joint.child) {
        std::reverse(loop.begin(), loop.end());
        std::vector<std::string> names;
        for (const std::string& name : loop) names.push_back("'" + name + "'");
        fail(source, (names.size() == 1 ? "joint " : "joints ") + join(names, ", ") +
                         (names.size() == 1 ? " forms" : " form") + " a cycle (" +
                         quoted("link", joint.child) + " is its own ancestor); expected a tree");
      }
      const auto up = parent_of.find(link);
      if (up == parent_of.end()) break;
      loop.push_back(up->second.joint);
      link = up->second.link;
    }
  }
}

// Removes from a joint what is not simulated: limits, mimic, safety
// controllers and calibration. urdfdom would fail the whole file over one of
// them malformed, or over a revolute or prismatic joint without a <limit> or
// with one that lacks effort or velocity, all of which Drake and MuJoCo
// accept. Such a joint gets a neutral limit instead, only so that urdfdom
// reads it; the note counts the joints that had their own.
void strip_joint(TiXmlElement* joint, Ignored* ignored) {
  bool limit = false, mimic = false, safety = false, calibration = false;
  std::vector<TiXmlNode*> drop;
  for (TiXmlElement* c = joint->FirstChildElement(); c; c = c->NextSiblingElement()) {
    const std::string tag = c->ValueStr();
    if (tag == "limit") {
      limit = true;
    } else if (tag == "mimic") {
      mimic = true;
    } else if (tag == "safety_controller") {
      safety = true;
    } else if (tag == "calibration") {
      calibration = true;
    } else {
      continue;
    }
    drop.push_back(c);
  }
  for (TiXmlNode* c : drop) joint->RemoveChild(c);
  ignored->limits += limit;
  ignored->mimic += mimic;
  ignored->safety += safety;
  ignored->calibration += calibration;
  const std::string type = attribute(joint, "type");
  if (type == "revolute" || type == "prismatic") {
    TiXmlElement neutral("limit");
    neutral.SetAttribute("effort", "0");
    neutral.SetAttribute("velocity", "0");
    neutral.SetAttribute("lower", "0");
    neutral.SetAttribute("upper", "0");
    joint->InsertEndChild(neutral);
  }
}

// Removes from <robot> everything but links and joints, and from links
// everything but the inertial: geometry, materials, transmissions and gazebo
// blocks do not change the dynamics, and urdfdom would fail the whole file
// over a malformed mesh element or an undefined material in them (joints:
// strip_joint). Returns the joints in file order (urdfdom keeps them in a
// map, sorted by name).
std::vector<XmlJoint> strip(TiXmlElement* robot, Ignored* ignored) {
  std::vector<XmlJoint> joints;
  std::vector<TiXmlNode*> drop;
  for (TiXmlElement* e = robot->FirstChildElement(); e; e = e->NextSiblingElement()) {
    const std::string tag = e->ValueStr();
    if (tag == "link") {
      std::vector<TiXmlNode*> drop_in_link;
      bool geometry = false;
      for (TiXmlElement* c = e->FirstChildElement(); c; c = c->NextSiblingElement()) {
        const std::string inner = c->ValueStr();
        if (inner == "inertial") continue;
        if (inner == "visual" || inner == "collision") {
          geometry = true;
        } else {
          ignored->other.insert("<" + inner + "> in links");
        }
        drop_in_link.push_back(c);
      }
      for (TiXmlNode* c : drop_in_link) e->RemoveChild(c);
      ignored->links_with_geometry += geometry;
    } else if (tag == "joint") {
      XmlJoint joint;
      joint.name = attribute(e, "name");
      joint.parent = attribute(e->FirstChildElement("parent"), "link");
      joint.child = attribute(e->FirstChildElement("child"), "link");
      joints.push_back(joint);
      strip_joint(e, ignored);
    } else {
      if (tag == "material") {
        ++ignored->materials;
      } else if (tag == "transmission") {
        ++ignored->transmissions;
      } else if (tag == "gazebo") {
        ++ignored->gazebo;
      } else {
        ignored->other.insert("<" + tag + ">");
      }
      drop.push_back(e);
    }
  }
  for (TiXmlNode* e : drop) robot->RemoveChild(e);
  return joints;
}

std::string count(int n, const char* singular, const char* plural) {
  return std::to_string(n) + " " + (n == 1 ? singular : plural);
}

Eigen::Isometry3d to_isometry(const urdf::Pose& pose, const std::string& source,
                              const std::string& element, const char* what) {
  const urdf::Vector3& p = pose.position;
  const urdf::Rotation& r = pose.rotation;
  const double values[7] = {p.x, p.y, p.z, r.w, r.x, r.y, r.z};
  for (double v : values) {
    if (!std::isfinite(v)) fail(source, element + ": " + what + " is not finite; expected finite xyz and rpy");
  }
  Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
  out.translation() = Eigen::Vector3d(p.x, p.y, p.z);
  out.linear() = Eigen::Quaterniond(r.w, r.x, r.y, r.z).normalized().toRotationMatrix();
  return out;
}

// Principal moments of an inertia tensor, ascending, and how messages quote
// them.
Eigen::Vector3d principal_moments(const Eigen::Matrix3d& tensor) {
  return Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(tensor, Eigen::EigenvaluesOnly)
      .eigenvalues();
}

std::string eigenvalues_text(const Eigen::Vector3d& moments) {
  return "eigenvalues " + format_number(moments(0)) + ", " + format_number(moments(1)) + ", " +
         format_number(moments(2));
}

// The link's mass properties in its own frame, checked for what every link
// needs: a finite mass >= 0 and a tensor about the COM that is positive
// semidefinite (a point mass has all-zero moments). Whether a body that moves
// has enough inertia is decided on the body with its welded links
// (check_moving_inertia), not here: welded into its parent, a point mass is
// physically fine.
RigidInertia link_inertia(const urdf::Link& link, const std::string& source) {
  RigidInertia out;
  if (!link.inertial) return out;
  const urdf::Inertial& in = *link.inertial;
  const std::string element = quoted("link", link.name);
  if (!std::isfinite(in.mass) || in.mass < 0.0) {
    fail(source,
         element + ": mass is " + format_number(in.mass) + "; expected a finite value >= 0");
  }
  const double entries[6] = {in.ixx, in.iyy, in.izz, in.ixy, in.ixz, in.iyz};
  for (double v : entries) {
    if (!std::isfinite(v)) fail(source, element + ": inertia is not finite; expected finite ixx..iyz");
  }
  Eigen::Matrix3d tensor;
  tensor << in.ixx, in.ixy, in.ixz, in.ixy, in.iyy, in.iyz, in.ixz, in.iyz, in.izz;
  const Eigen::Vector3d moments = principal_moments(tensor);
  // A moment that is zero up to rounding passes. The margin is 1e-12 of the
  // largest moment or of m (1 m)^2, whichever is larger: 1e-12 m (1 m)^2 is
  // m (1 um)^2, the moment of the mass at one micron, below what any robot
  // description resolves, so a point mass written with noise (1e-20 entries
  // from a CAD export) counts as zero.
  const double unit_length_squared = 1.0;  // m^2
  const double scale = std::max(moments.cwiseAbs().maxCoeff(), in.mass * unit_length_squared);
  if (moments.minCoeff() < -1e-12 * scale) {
    fail(source, element + ": inertia tensor is not positive semidefinite (" +
                     eigenvalues_text(moments) +
                     "); expected non-negative principal moments about the centre of mass");
  }
  const Eigen::Isometry3d frame = to_isometry(in.origin, source, element, "inertial origin");
  out.mass = in.mass;
  out.inertia = tensor;
  return transform(out, frame);
}

// A body that moves on its own joint and has mass needs a positive definite
// inertia about its centre of mass, its welded links included. Then its
// spatial inertia is positive definite, and a tree of such bodies has M(q)
// positive definite at every q, not only at the initial state that
// ArticulatedSystem checks. A point mass on its own joint fails here (MuJoCo
// rejects it too); welded to a body with inertia it passes. Massless moving
// bodies are left to the subtree-mass check. `welded[i]` counts the links
// with mass welded into body i.
void check_moving_inertia(const RigidTree& tree, const std::vector<int>& welded,
                          const std::string& source) {
  for (size_t i = 0; i < tree.bodies.size(); ++i) {
    const TreeBody& body = tree.bodies[i];
    if (!(body.inertia.mass > 0.0)) continue;
    const Eigen::Vector3d moments = principal_moments(body.inertia.inertia);
    // A relative margin, so that a tensor tiny but positive in every
    // direction passes while one that is zero up to rounding does not.
    const double largest = moments.cwiseAbs().maxCoeff();
    if (moments.minCoeff() > 1e-12 * largest && largest > 0.0) continue;
    const std::string with =
        welded[i] ? " (with the " + count(welded[i], "link", "links") + " welded to it)" : "";
    fail(source, quoted("link", body.link) + with + ": inertia tensor is not positive definite (" +
                     eigenvalues_text(moments) +
                     "); expected positive principal moments about the centre of mass, since it "
                     "moves (joint '" +
                     body.joint + "')");
  }
}

// The ignored-features note: one line, only what the file actually has.
std::string ignored_note(const urdf::ModelInterface& model, const Ignored& ignored,
                         const std::string& source) {
  int friction = 0;
  for (const auto& entry : model.joints_) {
    const urdf::Joint& joint = *entry.second;
    friction += joint.dynamics && joint.dynamics->friction != 0.0;
  }
  auto joints = [](int n) { return count(n, "joint", "joints"); };
  std::vector<std::string> parts;
  if (ignored.limits) parts.push_back("joint limits (" + joints(ignored.limits) + ")");
  if (ignored.mimic) parts.push_back("mimic (" + joints(ignored.mimic) + ")");
  if (friction) parts.push_back("friction (" + joints(friction) + ")");
  if (ignored.safety) parts.push_back("safety controllers (" + joints(ignored.safety) + ")");
  if (ignored.calibration) parts.push_back("calibration (" + joints(ignored.calibration) + ")");
  if (ignored.links_with_geometry) {
    parts.push_back("visual/collision geometry (" +
                    count(ignored.links_with_geometry, "link", "links") + ")");
  }
  if (ignored.materials) parts.push_back("materials (" + std::to_string(ignored.materials) + ")");
  if (ignored.transmissions) {
    parts.push_back("transmissions (" + std::to_string(ignored.transmissions) + ")");
  }
  if (ignored.gazebo) parts.push_back("gazebo blocks (" + std::to_string(ignored.gazebo) + ")");
  for (const std::string& tag : ignored.other) parts.push_back(tag);
  if (parts.empty()) return "";
  return source + ": ignored (no effect on the dynamics here): " + join(parts, ", ");
}

}  // namespace

RigidTree parse_urdf(const std::string& xml, const std::string& source_name,
                     const UrdfOptions& options, std::vector<std::string>* notes) {
  const std::string& source = source_name;
  check_text(xml, source);

  TiXmlDocument doc;
  doc.Parse(xml.c_str(), nullptr, TIXML_ENCODING_UTF8);
  if (doc.Error()) {
    fail(source + ":" + std::to_string(std::max(doc.ErrorRow(), 1)) + ":" +
             std::to_string(std::max(doc.ErrorCol(), 1)),
         std::string("malformed XML: ") + one_line(doc.ErrorDesc()));
  }
  TiXmlElement* robot = doc.RootElement();
  if (robot == nullptr) fail(source, "no XML element; expected a <robot> element");
  if (robot->ValueStr() != "robot") {
    fail(source, "the root element is <" + robot->ValueStr() + ">; expected <robot>");
  }
  Ignored ignored;
  const std::vector<XmlJoint> xml_joints = strip(robot, &ignored);
  check_tree_shape(xml_joints, source);
  TiXmlPrinter printer;
  doc.Accept(&printer);

  urdf::ModelInterfaceSharedPtr model;
  {
    UrdfdomLogCapture capture;
    try {
      model = urdf::parseURDF(printer.Str());
    } catch (const std::exception& e) {
      capture.add_error(e.what());
    }
    // urdfdom returns a model even after some errors (an inertial it could
    // not read is left at zero), so any error it logged rejects the file.
    if (!capture.errors().empty()) {
      fail(source, "invalid URDF: " + join(capture.errors(), "; "));
    }
    if (!model) fail(source, "invalid URDF (urdfdom rejected it without saying why)");
  }

  // urdfdom sorts joints by name; the file order keeps the body order the
  // author's.
  std::map<std::string, size_t> file_index;
  for (size_t i = 0; i < xml_joints.size(); ++i) file_index.emplace(xml_joints[i].name, i);
  auto by_file_order = [&](const urdf::JointSharedPtr& a, const urdf::JointSharedPtr& b) {
    return file_index[a->name] < file_index[b->name];
  };

  const urdf::LinkConstSharedPtr root = model->getRoot();
  if (!root) fail(source, "invalid URDF: no root link");

  RigidTree tree;
  tree.name = options.component_name.empty() ? model->getName() : options.component_name;
  tree.file = source;

  // Each link's frame is carried by an owner: the body it is welded into, or
  // the world (-1) when it is fixed to the welded root.
  struct Pending {
    urdf::JointSharedPtr joint;
    int owner;
    Eigen::Isometry3d parent_pose;  // parent link frame in the owner's frame
  };
  std::vector<Pending> stack;
  std::set<std::string> visited{root->name};
  auto push_children = [&](const urdf::Link& link, int owner, const Eigen::Isometry3d& pose) {
    std::vector<urdf::JointSharedPtr> children = link.child_joints;
    std::stable_sort(children.begin(), children.end(), by_file_order);
    for (auto it = children.rbegin(); it != children.rend(); ++it) {
      stack.push_back({*it, owner, pose});
    }
  };

  const RigidInertia root_inertia = link_inertia(*root, source);
  std::vector<int> welded;  // per body: links with mass welded into it
  int root_owner = -1;
  if (options.floating_base) {
    TreeBody body;
    body.link = root->name;
    body.joint = "floating_base";
    body.type = JointType::kFloating;
    body.inertia = root_inertia;
    tree.bodies.push_back(body);
    welded.push_back(0);
    root_owner = 0;
  }
  push_children(*root, root_owner, Eigen::Isometry3d::Identity());

  while (!stack.empty()) {
    const Pending pending = stack.back();
    stack.pop_back();
    const urdf::Joint& joint = *pending.joint;
    const std::string element = quoted("joint", joint.name);
    const urdf::LinkConstSharedPtr child = model->getLink(joint.child_link_name);
    if (!child) fail(source, element + ": child link '" + joint.child_link_name + "' not found");
    if (!visited.insert(child->name).second) {
      fail(source, quoted("link", child->name) + " is reached twice; expected a tree");
    }
    const Eigen::Isometry3d placement =
        pending.parent_pose *
        to_isometry(joint.parent_to_joint_origin_transform, source, element, "origin");
    const RigidInertia inertia = link_inertia(*child, source);
    double damping = 0.0;
    if (joint.dynamics) {
      damping = joint.dynamics->damping;
      if (!std::isfinite(damping) || damping < 0.0) {
        fail(source,
             element + ": damping is " + format_number(damping) + "; expected a finite value >= 0");
      }
    }

    if (joint.type == urdf::Joint::FIXED) {
      tree.fixed_joints.push_back(joint.name);
      // Welded to the world, the link's mass never moves and drops out.
      if (pending.owner >= 0) {
        TreeBody& owner = tree.bodies[pending.owner];
        owner.inertia = combine(owner.inertia, transform(inertia, placement));
        welded[pending.owner] += inertia.mass > 0.0;
      }
      push_children(*child, pending.owner, placement);
      continue;
    }

    TreeBody body;
    body.link = child->name;
    body.joint = joint.name;
    body.parent = pending.owner;
    body.placement = placement;
    body.inertia = inertia;
    body.damping = damping;
    switch (joint.type) {
      case urdf::Joint::REVOLUTE:
      case urdf::Joint::CONTINUOUS:
        body.type = JointType::kRevolute;
        break;
      case urdf::Joint::PRISMATIC:
        body.type = JointType::kPrismatic;
        break;
      case urdf::Joint::FLOATING:
        body.type = JointType::kFloating;
        break;
      case urdf::Joint::PLANAR:
        body.type = JointType::kPlanar;
        break;
      default:
        fail(source, element +
                         ": unsupported joint type; expected revolute, continuous, prismatic, "
                         "fixed, floating or planar");
    }
    if (body.type != JointType::kFloating) {
      const Eigen::Vector3d axis(joint.axis.x, joint.axis.y, joint.axis.z);
      if (!axis.allFinite()) fail(source, element + ": axis is not finite; expected a non-zero vector");
      if (axis.norm() < 1e-12) fail(source, element + ": axis is zero; expected a non-zero vector");
      body.axis = axis.normalized();
    }
    tree.bodies.push_back(body);
    welded.push_back(0);
    push_children(*child, static_cast<int>(tree.bodies.size()) - 1, Eigen::Isometry3d::Identity());
  }

  // With one parent per link and one root, links the walk from the root did
  // not reach can only be joined to each other in a cycle.
  if (visited.size() != model->links_.size()) {
    for (const auto& entry : model->links_) {
      if (!visited.count(entry.first)) {
        fail(source, quoted("link", entry.first) + " is not connected to the root link '" +
                         root->name + "' (its joints form a cycle); expected a tree");
      }
    }
  }

  // A moving body whose whole subtree is massless gives M a zero row.
  std::vector<double> subtree_mass(tree.bodies.size());
  for (size_t i = tree.bodies.size(); i-- > 0;) {
    subtree_mass[i] += tree.bodies[i].inertia.mass;
    if (tree.bodies[i].parent >= 0) subtree_mass[tree.bodies[i].parent] += subtree_mass[i];
  }
  for (size_t i = 0; i < tree.bodies.size(); ++i) {
    if (!(subtree_mass[i] > 0.0)) {
      fail(source, quoted("link", tree.bodies[i].link) + " moves (joint '" + tree.bodies[i].joint +
                       "') but carries no mass in its subtree; give it an <inertial>");
    }
  }
  check_moving_inertia(tree, welded, source);

  const std::string note = ignored_note(*model, ignored, source);
  if (notes != nullptr && !note.empty()) notes->push_back(note);
  return tree;
}

RigidTree load_urdf(const std::string& path, const UrdfOptions& options,
                    std::vector<std::string>* notes) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::file_status status = fs::status(path, ec);
  if (!fs::exists(status)) fail(path, "cannot read URDF file (no such file)");
  if (fs::is_directory(status)) fail(path, "cannot read URDF file (it is a directory)");
  // A FIFO or device would block or never end.
  if (!fs::is_regular_file(status)) fail(path, "cannot read URDF file (not a regular file)");
  const std::uintmax_t size = fs::file_size(path, ec);
  if (ec) fail(path, "cannot read URDF file (" + ec.message() + ")");
  if (size > kMaxFileBytes) {
    fail(path, "URDF file is too large (" + std::to_string(size) +
                   " bytes; expected at most 64 MiB)");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path, std::string("cannot read URDF file (") + std::strerror(errno) + ")");
  std::string text(static_cast<size_t>(size), '\0');
  in.read(text.data(), static_cast<std::streamsize>(size));
  if (in.bad() || static_cast<std::uintmax_t>(in.gcount()) != size) {
    fail(path, "cannot read URDF file (read error)");
  }
  return parse_urdf(text, path, options, notes);
}

}  // namespace stiffsim
