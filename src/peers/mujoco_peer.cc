// MuJoCo as a peer (include/stiffsim/peers/mujoco_peer.h).
//
// MuJoCo reads URDF itself (mj_loadXML converts <robot> to its own model).
// Before it sees the file, the text is changed in memory (a one-file mjVFS,
// nothing is written next to the user's URDF):
// - <visual> and <collision> elements are removed: their meshes (package://
//   URIs) do not exist here and geometry does not affect the dynamics;
//   with no geoms, MuJoCo takes every body's mass and inertia from the
//   URDF's <inertial> as given (inertiafromgeom never has a geom to use);
// - a <mujoco><compiler .../></mujoco> block keeps every link as its own
//   body (fusestatic="false": a fixed joint becomes a body without joints,
//   welded to its parent, which is what stiffsim's welding computes too) and
//   leaves inertias unchanged (balanceinertia="false", no bounds). Only
//   when MuJoCo refuses a tensor whose principal moments break the triangle
//   inequality A + B >= C (no mass distribution has such moments, but
//   stiffsim needs only a positive semidefinite tensor, and published
//   robots carry them on dummy links) is the file loaded again with
//   balanceinertia="true", which replaces the moments of such bodies by
//   their mean; PeerRun::settings then says so;
// - for a floating base, a link named "world" and a joint of type floating
//   from it to the root link: MuJoCo's URDF import takes the link "world"
//   as its world body and makes a free joint of a floating one, which
//   leaves the root link's frame where it is (no <origin>), as stiffsim's
//   floating_base does. A free joint's qpos and qvel are stiffsim's floating
//   coordinates: mj_integratePos adds qvel[0:3] to the position and turns
//   the quaternion by qvel[3:6] on its right (mju_quatIntegrate), i.e. in
//   the body frame.
// Everything else is set on the compiled mjModel: gravity, time step,
// integrator, contacts and limits off, armature and frictionloss 0, the
// joint springs and total damping of the problem.

#include "stiffsim/peers/mujoco_peer.h"

#include <chrono>
#include <cmath>
#include <cstring>
#include <fstream>
#include <memory>
#include <sstream>
#include <stdexcept>

#ifdef STIFFSIM_HAVE_MUJOCO
#include <mujoco/mujoco.h>
#endif

#include "stiffsim/error.h"
#include "stiffsim/model/articulated.h"

namespace stiffsim {

MujocoProblem mujoco_problem(const ArticulatedSystem& system, const std::string& urdf_path) {
  if (!system.options().bushings.empty())
    throw std::invalid_argument("MuJoCo peer: '" + system.name() +
                                "' has bushings; only exact trees map to MuJoCo's joints");
  const ArticulatedModel& model = system.model();
  const ArticulatedOptions& options = system.options();
  // A constant root displacement leaves q and v as they are; a moving base
  // would need MuJoCo's world to move, which the peer does not do, and
  // comparing against a fixed base would report a false disagreement.
  if (options.root_motion) {
    for (const ScalarPath& axis : *options.root_motion) {
      if (!axis.is_constant())
        throw std::invalid_argument("MuJoCo peer: '" + system.name() +
                                    "' has a moving root (root_motion); MuJoCo's base stays put");
    }
  }
  // Per body, the sum of k rest over its joint's spring and drives: a drive
  // with a constant target p adds kp p, so the joint's springs add up to
  // one about (k rest + kp p) / (k + kp). A moving target would need
  // MuJoCo's actuators and controls, which the peer does not set.
  std::vector<double> moment(model.bodies(), 0.0);
  for (const JointSpringElement& e : system.joint_springs().elements) {
    moment[e.body()] += e.stiffness() * e.rest();
  }
  for (const JointDriveElement& e : system.drives().elements) {
    if (!e.target().is_constant() && (e.stiffness() != 0.0 || e.damping() != 0.0))
      throw std::invalid_argument("MuJoCo peer: joint '" + model.tree.bodies[e.body()].joint +
                                  "' of '" + system.name() + "' has a drive with a moving target");
    moment[e.body()] += e.stiffness() * e.target().value(0.0);
  }
  MujocoProblem problem;
  problem.urdf_path = urdf_path;
  for (int k = 0; k < 3; ++k) problem.gravity[k] = options.gravity[k];
  for (int b = 0; b < model.bodies(); ++b) {
    const TreeBody& body = model.tree.bodies[b];
    const int qo = model.q_offset[b], vo = model.v_offset[b];
    // load_urdf's floating base: the root link's own frame, free in the world.
    if (body.type == JointType::kFloating && b == 0 && body.parent < 0 &&
        body.joint == "floating_base" && body.placement.matrix() == Eigen::Matrix4d::Identity()) {
      problem.floating_base_link = body.link;
      for (int k = 0; k < 7; ++k) problem.initial_base_q[k] = options.initial_q[qo + k];
      for (int k = 0; k < 6; ++k) problem.initial_base_v[k] = options.initial_v[vo + k];
      continue;
    }
    if (body.type != JointType::kRevolute && body.type != JointType::kPrismatic)
      throw std::invalid_argument(
          std::string("MuJoCo peer: joint '") + body.joint + "' of '" + system.name() + "' is " +
          joint_type_name(body.type) +
          "; expected revolute or prismatic (or load_urdf's floating base)");
    problem.joints.push_back(body.joint);
    problem.initial_q.push_back(options.initial_q[qo]);
    problem.initial_v.push_back(options.initial_v[vo]);
    // MuJoCo's joint has one spring and one damper: the joint-local
    // elements' sums (the articulated-body pivots'), about their common rest.
    const double stiffness = system.pivot_stiffness()[b];
    problem.stiffness.push_back(stiffness);
    problem.rest.push_back(stiffness > 0.0 ? moment[b] / stiffness : 0.0);
    problem.damping.push_back(system.pivot_damping()[b]);
  }
  return problem;
}

#ifndef STIFFSIM_HAVE_MUJOCO

bool mujoco_available() { return false; }

PeerRun run_mujoco(const MujocoProblem&) {
  throw std::runtime_error("stiffsim was built without MuJoCo");
}

#else

bool mujoco_available() { return true; }

namespace {

// Position of the next `<name` tag (followed by white space, '>' or '/')
// at or after `from`, skipping XML comments; npos when there is none.
size_t find_tag(const std::string& xml, const std::string& name, size_t from) {
  const std::string open = "<" + name;
  size_t pos = from;
  while (pos < xml.size()) {
    const size_t comment = xml.find("<!--", pos);
    const size_t tag = xml.find(open, pos);
    if (tag == std::string::npos) return std::string::npos;
    if (comment != std::string::npos && comment < tag) {
      const size_t end = xml.find("-->", comment + 4);
      if (end == std::string::npos) return std::string::npos;
      pos = end + 3;
      continue;
    }
    const size_t after = tag + open.size();
    if (after < xml.size()) {
      const char c = xml[after];
      if (c == '>' || c == '/' || c == ' ' || c == '\t' || c == '\n' || c == '\r') return tag;
    }
    pos = after;
  }
  return std::string::npos;
}

// Removes every <name .../> and <name ...>...</name> element (not nested in
// itself, as URDF's visual and collision never are).
void strip_elements(std::string* xml, const std::string& name) {
  size_t pos = 0;
  while ((pos = find_tag(*xml, name, pos)) != std::string::npos) {
    const size_t tag_end = xml->find('>', pos);
    if (tag_end == std::string::npos) return;  // broken XML: MuJoCo will say so
    size_t end;
    if ((*xml)[tag_end - 1] == '/') {
      end = tag_end + 1;
    } else {
      const std::string close = "</" + name;
      const size_t c = xml->find(close, tag_end);
      if (c == std::string::npos) return;
      const size_t ce = xml->find('>', c);
      if (ce == std::string::npos) return;
      end = ce + 1;
    }
    xml->erase(pos, end - pos);
  }
}

// `text` as an XML attribute value.
std::string xml_attribute(const std::string& text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

// The name of the free joint added for a floating base (not "floating_base",
// which a URDF may use itself).
const char kFreeJointName[] = "stiffsim_floating_base";

std::string prepare_urdf(const std::string& path, const std::string& floating_base_link,
                         bool balance_inertia) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("MuJoCo peer: cannot read URDF file '" + path + "'");
  std::ostringstream text;
  text << in.rdbuf();
  std::string xml = text.str();
  strip_elements(&xml, "visual");
  strip_elements(&xml, "collision");
  const size_t robot = find_tag(xml, "robot", 0);
  if (robot == std::string::npos)
    throw std::runtime_error("MuJoCo peer: '" + path + "' has no <robot> element");
  const size_t robot_end = xml.find('>', robot);
  if (robot_end == std::string::npos || xml[robot_end - 1] == '/')
    throw std::runtime_error("MuJoCo peer: '" + path + "' has an empty <robot> element");
  if (find_tag(xml, "mujoco", robot_end) == std::string::npos) {
    const std::string balance = balance_inertia ? "true" : "false";
    xml.insert(
        robot_end + 1,
        "\n  <mujoco><compiler discardvisual=\"true\" fusestatic=\"false\" balanceinertia=\"" +
            balance + "\" boundmass=\"0\" boundinertia=\"0\" angle=\"radian\"/></mujoco>\n");
  }
  if (!floating_base_link.empty()) {
    if (floating_base_link == "world")
      throw std::runtime_error("MuJoCo peer: '" + path +
                               "': a root link named 'world' is MuJoCo's world body and cannot "
                               "float");
    const size_t robot_close = xml.rfind("</robot");
    if (robot_close == std::string::npos)
      throw std::runtime_error("MuJoCo peer: '" + path + "' has no </robot>");
    xml.insert(robot_close, std::string("  <link name=\"world\"/>\n  <joint name=\"") +
                                kFreeJointName + "\" type=\"floating\"><parent link=\"world\"/>" +
                                "<child link=\"" + xml_attribute(floating_base_link) +
                                "\"/></joint>\n");
  }
  return xml;
}

struct ModelDeleter {
  void operator()(mjModel* m) const { mj_deleteModel(m); }
};
struct DataDeleter {
  void operator()(mjData* d) const { mj_deleteData(d); }
};
struct VfsDeleter {
  void operator()(mjVFS* v) const {
    mj_deleteVFS(v);
    delete v;
  }
};

// The model of URDF text `xml`, or null with MuJoCo's message in *error.
mjModel* load_model(const std::string& xml, std::string* error) {
  std::unique_ptr<mjVFS, VfsDeleter> vfs(new mjVFS);
  mj_defaultVFS(vfs.get());
  const char* kName = "stiffsim_mujoco_peer.urdf";
  if (mj_makeEmptyFileVFS(vfs.get(), kName, static_cast<int>(xml.size())) != 0) {
    *error = "cannot make a virtual file";
    return nullptr;
  }
  const int file = mj_findFileVFS(vfs.get(), kName);
  if (file < 0) {
    *error = "virtual file lost";
    return nullptr;
  }
  std::memcpy(vfs->filedata[file], xml.data(), xml.size());
  char text[1024] = "";
  mjModel* model = nullptr;
  try {
    model = mj_loadXML(kName, vfs.get(), text, sizeof text);
  } catch (const std::runtime_error& e) {
    *error = e.what();
    return nullptr;
  }
  if (!model) *error = text;
  return model;
}

// The first warning MuJoCo raised that makes the run meaningless, or "".
std::string bad_warning(const mjData* d) {
  static const struct {
    int index;
    const char* text;
  } kWarnings[] = {{mjWARN_BADQACC, "bad qacc (non-finite or huge acceleration)"},
                   {mjWARN_BADQPOS, "bad qpos"},
                   {mjWARN_BADQVEL, "bad qvel"},
                   {mjWARN_INERTIA, "(near) singular inertia matrix"}};
  for (const auto& w : kWarnings)
    if (d->warning[w.index].number > 0) return w.text;
  return "";
}

// MuJoCo reports through two process-wide hooks. Its default warning hook
// prints and appends to MUJOCO_LOG.TXT in the working directory, its default
// error hook exits the process. While run_mujoco runs, warnings are collected
// into the failure message and errors become std::runtime_error; the previous
// hooks come back afterwards. (So run_mujoco is not for concurrent use from
// several threads.)
thread_local std::string* g_warnings = nullptr;

void collect_warning(const char* text) {
  if (!g_warnings) return;
  std::string line(text ? text : "");
  while (!line.empty() && (line.back() == '\n' || line.back() == ' ')) line.pop_back();
  if (!g_warnings->empty()) *g_warnings += "; ";
  *g_warnings += line;
}

[[noreturn]] void throw_error(const char* text) {
  throw std::runtime_error(std::string("MuJoCo error: ") + (text ? text : ""));
}

class MujocoHooks {
 public:
  explicit MujocoHooks(std::string* warnings)
      : warning_(mju_user_warning), error_(mju_user_error), previous_(g_warnings) {
    g_warnings = warnings;
    mju_user_warning = collect_warning;
    mju_user_error = throw_error;
  }
  ~MujocoHooks() {
    mju_user_warning = warning_;
    mju_user_error = error_;
    g_warnings = previous_;
  }
  MujocoHooks(const MujocoHooks&) = delete;
  MujocoHooks& operator=(const MujocoHooks&) = delete;

 private:
  void (*warning_)(const char*);
  void (*error_)(const char*);
  std::string* previous_;
};

}  // namespace

PeerRun run_mujoco(const MujocoProblem& problem) {
  std::string warnings;
  MujocoHooks hooks(&warnings);
  const size_t n = problem.joints.size();
  auto check_size = [&](const std::vector<double>& values, const char* what) {
    if (values.size() != n)
      throw std::runtime_error(std::string("MuJoCo peer: ") + what + " has " +
                               std::to_string(values.size()) + " values for " + std::to_string(n) +
                               " joints");
  };
  check_size(problem.initial_q, "initial_q");
  check_size(problem.initial_v, "initial_v");
  check_size(problem.stiffness, "stiffness");
  check_size(problem.rest, "rest");
  check_size(problem.damping, "damping");
  if (!(problem.step > 0.0) || !std::isfinite(problem.step))
    throw std::runtime_error("MuJoCo peer: the step must be positive");

  int integrator;
  std::string integrator_text, method;
  if (problem.integrator == "implicit") {
    integrator = mjINT_IMPLICIT;
    integrator_text = "implicit (joint springs explicit, damping implicit)";
    method = "mujoco-implicit";
  } else if (problem.integrator == "RK4" || problem.integrator == "rk4") {
    integrator = mjINT_RK4;
    integrator_text = "RK4";
    method = "mujoco-rk4";
  } else if (problem.integrator == "Euler" || problem.integrator == "euler") {
    integrator = mjINT_EULER;
    integrator_text = "Euler (semi-implicit; damping implicit)";
    method = "mujoco-euler";
  } else {
    throw std::runtime_error("MuJoCo peer: unknown integrator '" + problem.integrator +
                             "' (implicit, RK4, Euler)");
  }

  // Load the URDF from memory.
  const bool floating = !problem.floating_base_link.empty();
  std::string error;
  std::string balanced;  // what balanceinertia changed, when it had to be on
  std::unique_ptr<mjModel, ModelDeleter> model(
      load_model(prepare_urdf(problem.urdf_path, problem.floating_base_link, false), &error));
  if (!model && error.find("A + B >= C") != std::string::npos) {
    const size_t object = error.find("Object name = ");
    balanced = object == std::string::npos
                   ? std::string("a body")
                   : error.substr(object + 14, error.find(',', object) - object - 14);
    model.reset(
        load_model(prepare_urdf(problem.urdf_path, problem.floating_base_link, true), &error));
  }
  if (!model)
    throw std::runtime_error("MuJoCo could not load '" + problem.urdf_path + "': " + error);
  mjModel* m = model.get();

  // Joints.
  std::vector<int> qadr(n), dadr(n);
  for (size_t i = 0; i < n; ++i) {
    const std::string& name = problem.joints[i];
    const int j = mj_name2id(m, mjOBJ_JOINT, name.c_str());
    if (j < 0)
      throw std::runtime_error("MuJoCo peer: joint '" + name + "' of '" + problem.urdf_path +
                               "' is not in MuJoCo's model");
    if (m->jnt_type[j] != mjJNT_HINGE && m->jnt_type[j] != mjJNT_SLIDE)
      throw std::runtime_error("MuJoCo peer: joint '" + name + "' of '" + problem.urdf_path +
                               "' is not a 1-DOF hinge or slide joint in MuJoCo's model");
    qadr[i] = m->jnt_qposadr[j];
    dadr[i] = m->jnt_dofadr[j];
    m->jnt_stiffness[j] = problem.stiffness[i];
    m->jnt_limited[j] = 0;
    m->qpos_spring[qadr[i]] = problem.rest[i];
    m->dof_damping[dadr[i]] = problem.damping[i];
  }
  int base_qadr = 0, base_dadr = 0;
  if (floating) {
    const int j = mj_name2id(m, mjOBJ_JOINT, kFreeJointName);
    if (j < 0 || m->jnt_type[j] != mjJNT_FREE)
      throw std::runtime_error("MuJoCo peer: no free joint on link '" + problem.floating_base_link +
                               "' of '" + problem.urdf_path + "'");
    base_qadr = m->jnt_qposadr[j];
    base_dadr = m->jnt_dofadr[j];
  }
  for (int k = 0; k < m->nv; ++k) {
    m->dof_armature[k] = 0.0;
    m->dof_frictionloss[k] = 0.0;
  }
  for (int k = 0; k < 3; ++k) m->opt.gravity[k] = problem.gravity[k];
  m->opt.timestep = problem.step;
  m->opt.integrator = integrator;
  // Equality constraints too: MuJoCo makes one of every URDF <mimic>, which
  // stiffsim ignores.
  m->opt.disableflags |= mjDSBL_CONTACT | mjDSBL_LIMIT | mjDSBL_FRICTIONLOSS | mjDSBL_EQUALITY;

  std::unique_ptr<mjData, DataDeleter> data(mj_makeData(m));
  if (!data) throw std::runtime_error("MuJoCo peer: mj_makeData failed");
  mjData* d = data.get();
  mj_resetData(m, d);
  if (floating) {
    for (int k = 0; k < 7; ++k) d->qpos[base_qadr + k] = problem.initial_base_q[k];
    for (int k = 0; k < 6; ++k) d->qvel[base_dadr + k] = problem.initial_base_v[k];
  }
  for (size_t i = 0; i < n; ++i) {
    d->qpos[qadr[i]] = problem.initial_q[i];
    d->qvel[dadr[i]] = problem.initial_v[i];
  }
  mj_forward(m, d);

  PeerRun run;
  run.method = method;
  {
    std::ostringstream s;
    s << "MuJoCo " << mj_versionString() << " " << integrator_text
      << ", h = " << format_number(problem.step)
      << ", contacts, limits, frictionloss and equality constraints (URDF mimic) off, armature 0,"
         " URDF geometry stripped"
         " (inertias from <inertial>"
      << (balanced.empty()
              ? std::string()
              : "; balanceinertia on, MuJoCo refused the moments of '" + balanced + "' (A + B < C)")
      << ")" << (floating ? ", free joint on '" + problem.floating_base_link + "'" : std::string())
      << ", " << m->nq << " qpos / " << m->nv << " dofs";
    run.settings = s.str();
  }

  // stiffsim's order: the floating base is body 0, so its coordinates lead.
  const int base_nq = floating ? 7 : 0, base_nv = floating ? 6 : 0;
  const int nq = base_nq + static_cast<int>(n);
  auto record = [&](double t) {
    Eigen::VectorXd x(nq + base_nv + static_cast<int>(n));
    for (int k = 0; k < base_nq; ++k) x[k] = d->qpos[base_qadr + k];
    for (int k = 0; k < base_nv; ++k) x[nq + k] = d->qvel[base_dadr + k];
    for (size_t i = 0; i < n; ++i) {
      x[base_nq + i] = d->qpos[qadr[i]];
      x[nq + base_nv + i] = d->qvel[dadr[i]];
    }
    run.times.push_back(t);
    run.samples.push_back(std::move(x));
  };
  auto state_finite = [&]() {
    for (int k = 0; k < m->nq; ++k)
      if (!std::isfinite(d->qpos[k])) return false;
    for (int k = 0; k < m->nv; ++k)
      if (!std::isfinite(d->qvel[k])) return false;
    return true;
  };

  const double h = problem.step;
  size_t next_sample = 0;
  // Samples before the start are never reached.
  while (next_sample < problem.sample_times.size() &&
         problem.sample_times[next_sample] < d->time - 0.5 * h)
    ++next_sample;
  const double t_end = problem.t_final;

  const auto start = std::chrono::steady_clock::now();
  for (;;) {
    while (next_sample < problem.sample_times.size() &&
           std::abs(d->time - problem.sample_times[next_sample]) < 0.5 * h) {
      record(problem.sample_times[next_sample]);
      ++next_sample;
    }
    // Sample times that fall between steps by more than h/2 of either end
    // are skipped: a run reports only times it reached.
    while (next_sample < problem.sample_times.size() &&
           problem.sample_times[next_sample] < d->time - 0.5 * h)
      ++next_sample;
    if (d->time >= t_end - 0.5 * h) break;
    const double t_before = d->time;
    mj_step(m, d);
    ++run.steps;
    const std::string warning = bad_warning(d);
    if (!warning.empty() || !state_finite()) {
      run.failed = true;
      std::ostringstream s;
      s << "MuJoCo " << integrator_text << " failed in the step from t = " << t_before
        << " to t = " << t_before + h << ": "
        << (warning.empty() ? std::string("non-finite qpos/qvel") : "warning: " + warning);
      if (!warnings.empty()) s << " (MuJoCo: " << warnings << ")";
      run.message = s.str();
      break;
    }
  }
  run.wall_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  // RK4 makes four evaluations of the dynamics per step; Euler and implicit one.
  run.rhs_evaluations = run.steps * (integrator == mjINT_RK4 ? 4 : 1);
  if (integrator == mjINT_IMPLICIT) {
    run.jacobian_evaluations = run.steps;
    run.linear_setups = run.steps;
  }
  return run;
}

#endif  // STIFFSIM_HAVE_MUJOCO

}  // namespace stiffsim
