// URDF components of a scene file: the tree, its formulation, initial
// state, joint springs, drives and root motion.

#include <algorithm>
#include <filesystem>
#include <optional>

#include "component_builders.h"
#include "stiffsim/model/articulated.h"
#include "stiffsim/model/compliant.h"
#include "stiffsim/model/urdf.h"

namespace stiffsim {
namespace scene_file {
namespace {

// The body moved by the joint named by `key` in `where`; a fixed joint
// (welded away) and an unknown name each get their own message.
int body_of_joint(const Section& c, const YAML::Node& key, const RigidTree& tree,
                  const std::string& where) {
  const std::string joint = key.Scalar();
  for (std::size_t i = 0; i < tree.bodies.size(); ++i) {
    if (tree.bodies[i].joint == joint) return static_cast<int>(i);
  }
  const auto& fixed = tree.fixed_joints;
  if (std::find(fixed.begin(), fixed.end(), joint) != fixed.end()) {
    c.fail(key, "joint '" + joint + "' in " + where + " is a fixed joint of " + tree.file +
                    " (welded into its parent link): only moving joints take it");
  }
  c.fail(key, "unknown joint '" + joint + "' in " + where + " (not a joint of " + tree.file + ")");
}

// A per-joint setting given as one number for every 1-DOF joint or as a map
// joint name -> number; `index` maps the URDF's moving joint names to bodies.
std::vector<double> per_joint(const Section& c, const std::string& key, Range range,
                              const RigidTree& tree, double fallback) {
  std::vector<double> values(tree.bodies.size(), fallback);
  if (!c.has(key)) return values;
  const YAML::Node n = c.get(key);
  auto one_dof = [&](std::size_t i) { return joint_nv(tree.bodies[i].type) == 1; };
  if (n.IsScalar()) {
    const double x = c.number_value(n, c.label(key), range);
    for (std::size_t i = 0; i < values.size(); ++i) {
      if (one_dof(i)) values[i] = x;
    }
    return values;
  }
  if (!n.IsMap())
    c.fail(n,
           c.label(key) + " must be a number or a map joint name -> number, got " + node_kind(n));
  for (const auto& entry : n) {
    const std::string joint = entry.first.Scalar();
    const std::string what = c.label(key) + "." + joint;
    const std::size_t i = body_of_joint(c, entry.first, tree, c.label(key));
    if (!one_dof(i)) {
      c.fail(entry.first, what + ": joint '" + joint + "' is " +
                              joint_type_name(tree.bodies[i].type) +
                              "; only 1-DOF joints take this setting");
    }
    values[i] = c.number_value(entry.second, what, range);
  }
  return values;
}

// Values of one joint in `initial`: a number for a 1-DOF joint, a list of
// `size` numbers otherwise.
void read_joint_values(const Section& c, const YAML::Node& value, const std::string& what, int size,
                       Eigen::Ref<Eigen::VectorXd> out) {
  if (size == 1 && value.IsScalar()) {
    out[0] = c.number_value(value, what, Range::kFinite);
    return;
  }
  if (!value.IsSequence() || static_cast<int>(value.size()) != size) {
    c.fail(value, what + " must be " +
                      (size == 1 ? std::string("a number")
                                 : "a list of " + std::to_string(size) + " numbers") +
                      ", got " + node_kind(value));
  }
  for (int k = 0; k < size; ++k)
    out[k] = c.number_value(value[k], what + "[" + std::to_string(k) + "]", Range::kFinite);
}

// `drives`: a list of {joint, kp, kd, target} (JointDrive).
std::vector<JointDrive> read_drives(const Section& c, const RigidTree& tree) {
  std::vector<JointDrive> drives;
  if (!c.has("drives")) return drives;
  const YAML::Node list = c.get("drives");
  if (!list.IsSequence()) {
    c.fail(list, "drives must be a list of {joint, kp, kd, target}, got " + node_kind(list));
  }
  for (std::size_t k = 0; k < list.size(); ++k) {
    const std::string what = "drives[" + std::to_string(k) + "]";
    const Section d(c.doc(), list[k], c.context(), what + ".", {"joint", "kp", "kd", "target"});
    const YAML::Node joint = d.require("joint");
    const std::size_t i = body_of_joint(d, joint, tree, what);
    if (joint_nv(tree.bodies[i].type) != 1) {
      d.fail(joint, what + ": joint '" + joint.Scalar() + "' is " +
                        joint_type_name(tree.bodies[i].type) +
                        "; drives act on revolute and prismatic joints");
    }
    for (const JointDrive& other : drives) {
      if (other.body == static_cast<int>(i)) {
        d.fail(joint, what + ": joint '" + joint.Scalar() + "' already has a drive");
      }
    }
    JointDrive drive;
    drive.body = static_cast<int>(i);
    drive.kp = d.number("kp", Range::kNonNegative);
    drive.kd = d.number_or("kd", Range::kNonNegative, 0.0);
    drive.target = read_path(d, d.require("target"), what + ".target");
    drives.push_back(std::move(drive));
  }
  return drives;
}

// `root_motion`: {x, y, z}, each axis a path (read_path) of the base's
// displacement; keyframes are refused where they are written, since their
// rate jumps at every key (articulated.h, ArticulatedOptions::root_motion).
std::optional<std::array<ScalarPath, 3>> read_root_motion(const Section& c) {
  if (!c.has("root_motion")) return std::nullopt;
  const Section m(c.doc(), c.get("root_motion"), c.context(), "root_motion.", {"x", "y", "z"});
  std::array<ScalarPath, 3> paths{ScalarPath::constant(0.0), ScalarPath::constant(0.0),
                                  ScalarPath::constant(0.0)};
  const char* axes[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    if (!m.has(axes[a])) continue;
    const std::string what = std::string("root_motion.") + axes[a];
    paths[a] = read_path(m, m.get(axes[a]), what);
    if (!paths[a].has_continuous_rate()) {
      m.fail(m.get(axes[a]), what +
                                 " is keyframed; a base's path needs a continuous rate (a "
                                 "constant or a sinusoid): each key would jolt the joints "
                                 "with an impulse");
    }
  }
  return paths;
}

std::unique_ptr<System> build_urdf(const Section& c, const std::string& name,
                                   const Eigen::Vector3d& g, const std::filesystem::path& base_dir,
                                   std::vector<std::string>* notes) {
  const std::string file = c.text("file");
  std::filesystem::path resolved(file);
  if (resolved.is_relative()) resolved = base_dir / resolved;
  std::error_code error;
  if (!std::filesystem::is_regular_file(resolved, error)) {
    c.fail(c.get("file"), "URDF file '" + file + "' not found (looked for " +
                              resolved.lexically_normal().string() + ")");
  }
  UrdfOptions uo;
  uo.component_name = name;
  uo.floating_base = c.boolean_or("floating_base", false);
  RigidTree tree;
  try {
    tree = load_urdf(resolved.lexically_normal().string(), uo, notes);
  } catch (const InputError& e) {
    c.fail(c.get("file"), e.what());
  }
  const std::string formulation = c.choice_or("formulation", {"exact", "compliant"}, "exact");

  ArticulatedOptions o;
  o.gravity = g;
  const std::vector<double> k = per_joint(c, "joint_stiffness", Range::kNonNegative, tree, 0.0);
  const std::vector<double> rest = per_joint(c, "joint_rest", Range::kFinite, tree, 0.0);
  const std::vector<double> damping = per_joint(c, "joint_damping", Range::kNonNegative, tree, 0.0);
  o.joint_forces.resize(tree.bodies.size());
  for (std::size_t i = 0; i < tree.bodies.size(); ++i)
    o.joint_forces[i] = JointForce{k[i], rest[i], damping[i]};

  // Offsets of the exact formulation's coordinates, in which `initial` is given.
  std::vector<int> qo, vo;
  int nq = 0, nv = 0;
  for (const TreeBody& b : tree.bodies) {
    qo.push_back(nq);
    vo.push_back(nv);
    nq += joint_nq(b.type);
    nv += joint_nv(b.type);
  }
  o.initial_q = Eigen::VectorXd::Zero(nq);
  o.initial_v = Eigen::VectorXd::Zero(nv);
  for (std::size_t i = 0; i < tree.bodies.size(); ++i) {
    if (tree.bodies[i].type == JointType::kFloating) o.initial_q[qo[i] + 3] = 1.0;
  }
  if (c.has("initial")) {
    const Section init(c.doc(), c.get("initial"), c.context(), "initial.",
                       {"all_joints", "joints", "velocities"});
    if (init.has("all_joints")) {
      const double a = init.number("all_joints", Range::kFinite);
      for (std::size_t i = 0; i < tree.bodies.size(); ++i) {
        if (joint_nq(tree.bodies[i].type) == 1) o.initial_q[qo[i]] = a;
      }
    }
    for (const char* key : {"joints", "velocities"}) {
      if (!init.has(key)) continue;
      const YAML::Node m = init.get(key);
      const bool positions = std::string(key) == "joints";
      if (!m.IsMap())
        init.fail(m, init.label(key) + " must be a map joint name -> value, got " + node_kind(m));
      for (const auto& entry : m) {
        const int i = body_of_joint(init, entry.first, tree, init.label(key));
        const JointType type = tree.bodies[i].type;
        const int size = positions ? joint_nq(type) : joint_nv(type);
        Eigen::VectorXd& target = positions ? o.initial_q : o.initial_v;
        read_joint_values(init, entry.second, init.label(key) + "." + entry.first.Scalar(), size,
                          target.segment(positions ? qo[i] : vo[i], size));
      }
    }
  }
  o.drives = read_drives(c, tree);
  o.root_motion = read_root_motion(c);
  if (formulation == "exact") {
    if (c.has("bushing"))
      c.fail(c.get("bushing"), "bushing applies to formulation: compliant only");
    return with_location(c, name, [&] {
      return std::make_unique<ArticulatedSystem>(std::move(tree), std::move(o));
    });
  }
  if (!o.drives.empty()) {
    c.fail(c.get("drives"),
           "drives need formulation: exact (the compliant formulation's joints "
           "are bushings)");
  }
  if (o.root_motion) {
    c.fail(c.get("root_motion"),
           "root_motion needs formulation: exact (the compliant "
           "formulation's bodies are free)");
  }
  BushingParameters bp;
  if (c.has("bushing")) {
    const Section b(c.doc(), c.get("bushing"), c.context(), "bushing.",
                    {"k_lin", "c_lin", "k_ang", "c_ang"});
    bp.k_lin = b.number_or("k_lin", Range::kNonNegative, bp.k_lin);
    bp.c_lin = b.number_or("c_lin", Range::kNonNegative, bp.c_lin);
    bp.k_ang = b.number_or("k_ang", Range::kNonNegative, bp.k_ang);
    bp.c_ang = b.number_or("c_ang", Range::kNonNegative, bp.c_ang);
  }
  return with_location(c, name, [&] { return make_compliant(tree, o, bp); });
}

}  // namespace

std::unique_ptr<System> build_urdf_component(const Section& c, const std::string& name,
                                             const BuildContext& context,
                                             std::vector<std::array<int, 3>>* surface) {
  surface->clear();
  return build_urdf(c, name, context.gravity, context.base_dir, context.notes);
}

}  // namespace scene_file
}  // namespace stiffsim
