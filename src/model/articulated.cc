#include "stiffsim/model/articulated.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <sstream>
#include <unsupported/Eigen/AutoDiff>

#include "stiffsim/error.h"
#include "stiffsim/linalg/column_colouring.h"
#include "stiffsim/model/articulated_body_solver.h"
#include "stiffsim/model/bushing.h"
#include "stiffsim/model/composite_rigid_body.h"
#include "stiffsim/model/forest_derivatives.h"
#include "stiffsim/model/forward_kinematics.h"
#include "stiffsim/model/inverse_dynamics.h"
#include "stiffsim/model/joints.h"
#include "stiffsim/model/quaternion.h"
#include "stiffsim/model/rnea_derivatives.h"

namespace stiffsim {
namespace {

// Derivative lanes per pass of the seeded forward-mode differentiation: a
// free body has 13 columns (7 q, 6 v) and a chain's colouring 3 x 13 = 39, so
// 16 lanes take three passes; a wider vector would cost every operation of
// every pass more.
constexpr int kLanes = 16;
using Dual = Eigen::AutoDiffScalar<Eigen::Matrix<double, kLanes, 1>>;

template <typename T>
using VecX = Eigen::Matrix<T, Eigen::Dynamic, 1>;

std::string where(const RigidTree& tree) { return "component '" + tree.name + "'"; }

bool is_free_root(const TreeBody& b) {
  return b.parent < 0 && b.type == JointType::kFloating &&
         b.placement.isApprox(Eigen::Isometry3d::Identity(), 0.0);
}

// The dual numbers' workspace of the automatic differentiation.
struct DualWorkspace {
  explicit DualWorkspace(const ArticulatedModel& model)
      : q(model.nq), v(model.nv), data(model) {}
  VecX<Dual> q, v;
  ArticulatedData<Dual> data;
};

}  // namespace

struct ArticulatedSystem::Data : SystemData {
  Data(const ArticulatedSystem* system, const ArticulatedModel& model)
      : owner(system), inverse_dynamics(model), acceleration(model.nv), crba(model) {}
  const ArticulatedSystem* owner;  // checked in debug builds
  ArticulatedData<double> inverse_dynamics;
  Eigen::VectorXd acceleration;  // momentum_residual()'s dv / h
  CompositeRigidBodyData crba;
  // Made on their first use: a run needs one kind of Jacobian at most, and
  // a run on the articulated-body recursion none.
  std::unique_ptr<DualWorkspace> dual;
  std::unique_ptr<RneaDerivatives> derivatives;
  std::unique_ptr<ForestDerivatives> forest_derivatives;
};

std::unique_ptr<SystemData> ArticulatedSystem::make_data() const {
  return std::make_unique<Data>(this, model_);
}

ArticulatedSystem::Data& ArticulatedSystem::own(SystemData& data) const {
  Data& d = static_cast<Data&>(data);
  assert(d.owner == this && "a SystemData fits only the system that made it");
  return d;
}

ArticulatedSystem::~ArticulatedSystem() = default;

ArticulatedSystem::ArticulatedSystem(RigidTree tree, ArticulatedOptions options)
    : options_(std::move(options)) {
  model_.tree = std::move(tree);
  const int nb = static_cast<int>(model_.tree.bodies.size());
  const std::string w = where(model_.tree);
  if (nb == 0) throw InputError(w + ": the URDF has no moving body");
  for (int i = 0; i < nb; ++i) {
    const TreeBody& b = model_.tree.bodies[i];
    if (b.parent >= i || b.parent < -1) {
      throw InputError(w + ": body '" + b.link + "' comes before its parent");
    }
    model_.q_offset.push_back(dims_.nq);
    model_.v_offset.push_back(dims_.nv);
    dims_.nq += joint_nq(b.type);
    dims_.nv += joint_nv(b.type);
    model_.has_floating |= b.type == JointType::kFloating;
  }
  model_.inertia = body_inertias(model_.tree);
  if (!options_.joint_forces.empty() && static_cast<int>(options_.joint_forces.size()) != nb) {
    throw InputError(w + ": joint forces given for " + std::to_string(options_.joint_forces.size()) +
                     " joints; expected " + std::to_string(nb));
  }
  for (int i = 0; i < static_cast<int>(options_.joint_forces.size()); ++i) {
    const JointForce& jf = options_.joint_forces[i];
    const TreeBody& b = model_.tree.bodies[i];
    if (!std::isfinite(jf.stiffness) || !std::isfinite(jf.rest) || !std::isfinite(jf.damping) ||
        jf.stiffness < 0.0 || jf.damping < 0.0) {
      throw InputError(w + ": joint '" + b.joint +
                       "': joint stiffness and damping must be finite and >= 0");
    }
    if (joint_nv(b.type) != 1 && (jf.stiffness != 0.0 || jf.damping != 0.0)) {
      throw InputError(w + ": joint '" + b.joint + "' is " + joint_type_name(b.type) +
                       "; joint springs and dampers apply to 1-DOF joints only");
    }
  }
  std::vector<bool> driven(nb, false);
  for (const JointDrive& dr : options_.drives) {
    if (dr.body < 0 || dr.body >= nb) {
      throw InputError(w + ": a drive names body " + std::to_string(dr.body) + " of " +
                       std::to_string(nb));
    }
    const TreeBody& b = model_.tree.bodies[dr.body];
    if (!options_.bushings.empty()) {
      throw InputError(w + ": joint '" + b.joint +
                       "': drives need the exact formulation (formulation: exact)");
    }
    if (joint_nv(b.type) != 1) {
      throw InputError(w + ": joint '" + b.joint + "' is " + joint_type_name(b.type) +
                       "; drives act on revolute and prismatic joints");
    }
    if (!std::isfinite(dr.kp) || !std::isfinite(dr.kd) || dr.kp < 0.0 || dr.kd < 0.0) {
      throw InputError(w + ": joint '" + b.joint + "': drive gains kp and kd must be finite and >= 0");
    }
    if (driven[dr.body]) throw InputError(w + ": joint '" + b.joint + "' has two drives");
    driven[dr.body] = true;
  }
  if (options_.root_motion) {
    if (!options_.bushings.empty()) {
      throw InputError(w + ": root_motion needs the exact formulation (formulation: exact)");
    }
    for (const TreeBody& b : model_.tree.bodies) {
      if (b.parent < 0 && (b.type == JointType::kFloating || b.type == JointType::kPlanar)) {
        throw InputError(w + ": root_motion moves a base welded to the world, but link '" + b.link +
                         "' is joined to the world by a " + joint_type_name(b.type) + " joint");
      }
    }
    for (int k = 0; k < 3; ++k) {
      if (!(*options_.root_motion)[k].has_continuous_rate()) {
        throw InputError(w + ": root_motion." + "xyz"[k] +
                         " is keyframed; a base's path needs a continuous rate (a constant or a "
                         "sinusoid): each key would jolt the joints with an impulse");
      }
    }
  }
  for (const Bushing& bu : options_.bushings) {
    for (int body : {bu.parent, bu.child}) {
      if (body < -1 || body >= nb || (body >= 0 && !is_free_root(model_.tree.bodies[body])) ||
          bu.child < 0) {
        throw InputError(w + ": bushing '" + bu.name + "' must join free bodies");
      }
    }
    if (bu.type == JointType::kFloating) {
      throw InputError(w + ": bushing '" + bu.name + "' replaces a floating joint");
    }
  }
  // The force elements. A joint's spring and damper is one element (the
  // URDF's damping plus the scene's); a drive is another on the same
  // coordinate.
  pivot_stiffness_.assign(nb, 0.0);
  pivot_damping_.assign(nb, 0.0);
  for (int i = 0; i < nb; ++i) {
    const TreeBody& b = model_.tree.bodies[i];
    if (joint_nv(b.type) != 1) continue;
    const JointForce jf = options_.joint_forces.empty() ? JointForce{} : options_.joint_forces[i];
    const double c = b.damping + jf.damping;
    if (jf.stiffness == 0.0 && c == 0.0) continue;
    elements_.joint_springs.elements.emplace_back(i, model_.q_offset[i], model_.v_offset[i],
                                                  jf.stiffness, jf.rest, c);
  }
  for (const JointDrive& dr : options_.drives) {
    elements_.drives.elements.emplace_back(dr.body, model_.q_offset[dr.body],
                                           model_.v_offset[dr.body], dr.kp, dr.kd, dr.target);
  }
  for (const Bushing& bu : options_.bushings) {
    elements_.bushings.elements.emplace_back(bu,
                                             bushing_offsets(bu, model_.q_offset, model_.v_offset));
  }
  for_each_element_set([this](const auto& set, int) {
    for (const auto& e : set.elements) {
      if constexpr (std::decay_t<decltype(e)>::kJointLocal) {
        pivot_stiffness_[e.body()] += e.stiffness();
        pivot_damping_[e.body()] += e.damping();
      }
    }
  });
  if (options_.initial_q.size() == 0) {
    options_.initial_q = Eigen::VectorXd::Zero(dims_.nq);
    for (int i = 0; i < nb; ++i) {
      if (model_.tree.bodies[i].type == JointType::kFloating) options_.initial_q[model_.q_offset[i] + 3] = 1.0;
    }
  }
  if (options_.initial_v.size() == 0) options_.initial_v = Eigen::VectorXd::Zero(dims_.nv);
  if (options_.initial_q.size() != dims_.nq || options_.initial_v.size() != dims_.nv ||
      !options_.initial_q.allFinite() || !options_.initial_v.allFinite()) {
    throw InputError(w + ": the initial state needs " + std::to_string(dims_.nq) + " positions and " +
                     std::to_string(dims_.nv) + " velocities, all finite");
  }
  for (int i = 0; i < nb; ++i) {
    if (model_.tree.bodies[i].type != JointType::kFloating) continue;
    auto quat = options_.initial_q.segment<4>(model_.q_offset[i] + 3);
    if (quat.norm() < 1e-12) {
      throw InputError(w + ": joint '" + model_.tree.bodies[i].joint + "': the initial quaternion is zero");
    }
    quat.normalize();
  }

  model_.nq = dims_.nq;
  model_.nv = dims_.nv;
  model_.world_acceleration.tail<3>() = -options_.gravity;
  constant_mass_ = true;
  for (int i = 0; i < nb; ++i) {
    const TreeBody& b = model_.tree.bodies[i];
    model_.inertia_matrix.push_back(model_.inertia[i].matrix());
    const Eigen::Matrix3d K = skew(b.axis), P = b.placement.linear();
    model_.placement_K.push_back(b.type == JointType::kRevolute ? Eigen::Matrix3d(P * K)
                                                                : Eigen::Matrix3d::Zero());
    model_.placement_K2.push_back(b.type == JointType::kRevolute ? Eigen::Matrix3d(P * K * K)
                                                                 : Eigen::Matrix3d::Zero());
    // With its linear velocity in the world and its angular velocity in its
    // own frame, a free body whose origin is its centre of mass has the
    // constant M = diag(m I, I_c); anything else moves M with q.
    constant_mass_ &= is_free_root(b) && b.inertia.com.isZero(0.0);
  }

  PatternBuilder Np(dims_.nq, dims_.nv);
  for (int i = 0; i < nb; ++i) {
    const int qo = model_.q_offset[i], vo = model_.v_offset[i];
    if (model_.tree.bodies[i].type == JointType::kFloating) {
      for (int k = 0; k < 3; ++k) Np.add(qo + k, vo + k);
      for (int r = 3; r < 7; ++r)
        for (int c = 3; c < 6; ++c) Np.add(qo + r, vo + c);
    } else {
      for (int k = 0; k < joint_nv(model_.tree.bodies[i].type); ++k) Np.add(qo + k, vo + k);
    }
  }
  velocity_map_pattern_ = Np.build();

  // A motion that moves no mass (a massless floating root turning about its
  // child's joint axis, a massless leaf) makes M singular; say so here rather
  // than fail in the first Newton solve. The articulated-body pivots are
  // those of an LDL^T factorization of M: O(n), whatever the tree.
  ArticulatedBodySolver pivots(model_, pivot_stiffness_, pivot_damping_);
  if (!pivots.factor(options_.initial_q, 0.0)) {
    throw InputError(w + ": the mass matrix is singular at the initial state: some joint motion moves "
                         "no mass (e.g. a massless floating root turning about its child's joint axis, "
                         "or a massless link at the end of a branch)");
  }
}

const ArticulatedSystem::Patterns& ArticulatedSystem::patterns() const {
  std::call_once(patterns_built_, [this] {
    auto P = std::make_unique<Patterns>();
    const int nb = model_.bodies();
    // Bodies are related when one lies on the other's path to the root; only
    // related bodies share entries of M (branch sparsity), and so, through the
    // Newton-Euler recursion, of K and D. Bushings relate the bodies they join
    // (and the branches above them).
    std::vector<std::vector<int>> related(nb);
    for (int i = 0; i < nb; ++i) {
      for (int j = i; j >= 0; j = model_.tree.bodies[j].parent) related[i].push_back(j);
    }
    PatternBuilder M(dims_.nv, dims_.nv), K(dims_.nv, dims_.nq), D(dims_.nv, dims_.nv);
    auto add_block = [&](PatternBuilder& B, int row0, int rows, int col0, int cols) {
      for (int r = 0; r < rows; ++r)
        for (int c = 0; c < cols; ++c) B.add(row0 + r, col0 + c);
    };
    auto add_pair = [&](int i, int j) {
      const int ni = joint_nv(model_.tree.bodies[i].type), nj = joint_nv(model_.tree.bodies[j].type);
      for (auto [a, b] : {std::pair{i, j}, std::pair{j, i}}) {
        const int na = joint_nv(model_.tree.bodies[a].type);
        add_block(K, model_.v_offset[a], na, model_.q_offset[b], joint_nq(model_.tree.bodies[b].type));
        add_block(D, model_.v_offset[a], na, model_.v_offset[b], joint_nv(model_.tree.bodies[b].type));
      }
      (void)ni, (void)nj;
    };
    for (int i = 0; i < nb; ++i) {
      for (int j : related[i]) {
        add_pair(i, j);
        const int ni = joint_nv(model_.tree.bodies[i].type), nj = joint_nv(model_.tree.bodies[j].type);
        add_block(M, model_.v_offset[i], ni, model_.v_offset[j], nj);
        add_block(M, model_.v_offset[j], nj, model_.v_offset[i], ni);
      }
    }
    for_each_element_set([&](const auto& set, int) {
      set.add_to_patterns([&](int r, int c) { K.add(r, c); }, [&](int r, int c) { D.add(r, c); });
    });
    P->mass = M.build();
    P->jacobians = empty_jacobians(dims_);
    P->jacobians.dF_dq = K.build();
    P->jacobians.dF_dv = D.build();
    for_each_element_set([&](const auto& set, int type) {
      P->element_slots[type] = set.find_slots(P->jacobians.dF_dq, P->jacobians.dF_dv);
    });

    P->mass_slots = composite_rigid_body_slots(model_, P->mass);

    const long dense = static_cast<long>(dims_.nv) * (dims_.nq + dims_.nv);
    if (P->jacobians.dF_dq.nonZeros() + P->jacobians.dF_dv.nonZeros() == dense) {
      // A serial chain in reduced coordinates: every column its own colour,
      // without the greedy colouring's O(rows cols^2) search.
      P->column_colour.resize(dims_.nq + dims_.nv);
      for (int j = 0; j < dims_.nq + dims_.nv; ++j) P->column_colour[j] = j;
      P->colours = dims_.nq + dims_.nv;
    } else {
      const ColumnColouring colouring = colour_columns(
          dims_.nv, dims_.nq + dims_.nv,
          {PatternBlock{&P->jacobians.dF_dq, 0, 0}, PatternBlock{&P->jacobians.dF_dv, 0, dims_.nq}});
      P->column_colour = colouring.colour;
      P->colours = colouring.colours;
    }
    P->jacobian_passes = (P->colours + kLanes - 1) / kLanes;
    patterns_ = std::move(P);
  });
  return *patterns_;
}

Capabilities ArticulatedSystem::capabilities() const {
  Capabilities c;
  c.identity_velocity_map = !model_.has_floating;
  c.has_quaternions = model_.has_floating;
  c.analytic_jacobians = true;
  c.automatic_jacobians = true;
  c.has_energy = true;
  // A drive with a moving target does work on the system.
  c.passive = options_.drives.empty() && !options_.root_motion;
  c.constant_mass_matrix = constant_mass_;
  c.momentum_residual = true;
  return c;
}

State ArticulatedSystem::initial_state() const {
  State s;
  s.x.resize(dims_.nx());
  s.x << options_.initial_q, options_.initial_v;
  return s;
}

std::vector<std::string> ArticulatedSystem::position_names() const {
  std::vector<std::string> names;
  for (const TreeBody& b : model_.tree.bodies) {
    const std::string base = model_.tree.name + "/" + b.joint;
    switch (b.type) {
      case JointType::kFloating:
        for (const char* s : {"x", "y", "z", "qw", "qx", "qy", "qz"}) names.push_back(base + "/" + s);
        break;
      case JointType::kPlanar:
        for (const char* s : {"x", "y", "theta"}) names.push_back(base + "/" + s);
        break;
      default:
        names.push_back(base);
    }
  }
  return names;
}

std::vector<std::string> ArticulatedSystem::velocity_names() const {
  std::vector<std::string> names;
  for (const TreeBody& b : model_.tree.bodies) {
    const std::string base = model_.tree.name + "/" + b.joint;
    switch (b.type) {
      case JointType::kFloating:
        for (const char* s : {"vx", "vy", "vz", "wx", "wy", "wz"}) names.push_back(base + "/" + s);
        break;
      case JointType::kPlanar:
        for (const char* s : {"vx", "vy", "w"}) names.push_back(base + "/" + s);
        break;
      default:
        names.push_back(base);
    }
  }
  return names;
}

void ArticulatedSystem::map_velocity_to_qdot(const ConstVectorRef& q, const ConstVectorRef& v,
                                             VectorRef qdot) const {
  for (int i = 0; i < static_cast<int>(model_.tree.bodies.size()); ++i) {
    const int qo = model_.q_offset[i], vo = model_.v_offset[i];
    if (model_.tree.bodies[i].type == JointType::kFloating) {
      qdot.segment<3>(qo) = v.segment<3>(vo);
      qdot.segment<4>(qo + 3) = quaternion_rate_map(q.segment<4>(qo + 3)) * v.segment<3>(vo + 3);
    } else {
      const int n = joint_nv(model_.tree.bodies[i].type);
      qdot.segment(qo, n) = v.segment(vo, n);
    }
  }
}

void ArticulatedSystem::velocity_map(SystemData&, const ConstVectorRef& q, SparseMatrix* N) const {
  // Column-major storage: fill column by column in the pattern's own order.
  for (int i = 0; i < static_cast<int>(model_.tree.bodies.size()); ++i) {
    const int qo = model_.q_offset[i], vo = model_.v_offset[i];
    if (model_.tree.bodies[i].type == JointType::kFloating) {
      for (int k = 0; k < 3; ++k) N->coeffRef(qo + k, vo + k) = 1.0;
      const Eigen::Matrix<double, 4, 3> G = quaternion_rate_map(q.segment<4>(qo + 3));
      for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 3; ++c) N->coeffRef(qo + 3 + r, vo + 3 + c) = G(r, c);
    } else {
      for (int k = 0; k < joint_nv(model_.tree.bodies[i].type); ++k) N->coeffRef(qo + k, vo + k) = 1.0;
    }
  }
}

bool ArticulatedSystem::project_positions(VectorRef q) const {
  bool changed = false;
  for (int i = 0; i < static_cast<int>(model_.tree.bodies.size()); ++i) {
    if (model_.tree.bodies[i].type != JointType::kFloating) continue;
    auto quat = q.segment<4>(model_.q_offset[i] + 3);
    const double n = quat.norm();
    if (n > 0.0 && n != 1.0) {
      quat /= n;
      changed = true;
    }
  }
  return changed;
}

void ArticulatedSystem::mass_matrix(SystemData& data, const ConstVectorRef& q,
                                    SparseMatrix* M) const {
  composite_rigid_body(model_, q, patterns().mass_slots, &own(data).crba, M);
}

template <typename T, typename Positions, typename Velocities>
void ArticulatedSystem::generalized_forces(double t, const Positions& q, const Velocities& v,
                                           const double* acceleration,
                                           ArticulatedData<T>* data) const {
  data->world_acceleration = world_acceleration_at(t);
  inverse_dynamics<T>(model_, q, v, acceleration, data);
  for_each_element_set(
      [&](const auto& set, int) { set.template add_forces<T>(t, q, v, &data->F); });
}

void ArticulatedSystem::forces(SystemData& data, double t, const ConstVectorRef& q,
                               const ConstVectorRef& v, const ConstVectorRef& z,
                               VectorRef F) const {
  (void)z;
  ArticulatedData<double>& id = own(data).inverse_dynamics;
  generalized_forces<double>(t, q, v, nullptr, &id);
  F = id.F;
}

void ArticulatedSystem::momentum_residual(SystemData& data, double t, const ConstVectorRef& q,
                                          const ConstVectorRef& v, const ConstVectorRef& z,
                                          const ConstVectorRef& dv, double h, VectorRef r) const {
  // F - M(q) a at a = dv / h is -(M dv - h F) / h.
  (void)z;
  Data& d = own(data);
  d.acceleration = dv / h;
  generalized_forces<double>(t, q, v, d.acceleration.data(), &d.inverse_dynamics);
  r = -h * d.inverse_dynamics.F;
}

std::unique_ptr<StructuredNewtonMatrix> ArticulatedSystem::make_structured_newton_matrix() const {
  // Bushings couple free bodies through stiffness the recursion cannot fold
  // into joint-space pivots; their systems assemble the sparse matrix.
  if (!options_.bushings.empty()) return nullptr;
  return std::make_unique<ArticulatedBodySolver>(model_, pivot_stiffness_, pivot_damping_);
}

void ArticulatedSystem::exact_jacobians(Data& workspace, double t, const ConstVectorRef& q,
                                        const ConstVectorRef& v, const double* acceleration,
                                        ForceJacobians* J) const {
  // Seeded forward mode: the columns of one colour share no row of [K D], so
  // they can share a derivative lane; each pass carries kLanes colours.
  const int nq = dims_.nq, nv = dims_.nv;
  const Patterns& P = patterns();
  if (!workspace.dual) workspace.dual = std::make_unique<DualWorkspace>(model_);
  VecX<Dual>& qd = workspace.dual->q;
  VecX<Dual>& vd = workspace.dual->v;
  ArticulatedData<Dual>& data = workspace.dual->data;
  const VecX<Dual>& Fd = data.F;
  SparseMatrix& K = J->dF_dq;
  SparseMatrix& D = J->dF_dv;
  for (int pass = 0; pass < P.jacobian_passes; ++pass) {
    const int first = pass * kLanes;
    auto seed = [&](int column, double value, Dual* x) {
      *x = Dual(value);
      x->derivatives().setZero();
      const int lane = P.column_colour[column] - first;
      if (P.column_colour[column] >= 0 && lane >= 0 && lane < kLanes) x->derivatives()[lane] = 1.0;
    };
    for (int j = 0; j < nq; ++j) seed(j, q[j], &qd[j]);
    for (int j = 0; j < nv; ++j) seed(nq + j, v[j], &vd[j]);
    generalized_forces<Dual>(t, qd, vd, acceleration, &data);
    auto store = [&](SparseMatrix& A, int column_offset) {
      for (int j = 0; j < A.outerSize(); ++j) {
        const int lane = P.column_colour[column_offset + j] - first;
        if (lane < 0 || lane >= kLanes) continue;
        for (SparseMatrix::InnerIterator it(A, j); it; ++it) {
          it.valueRef() = Fd[it.row()].derivatives()[lane];
        }
      }
    };
    store(K, 0);
    store(D, nq);
  }
  J->approximated_terms = 0;
}

void ArticulatedSystem::force_jacobians(SystemData& data, double t, const ConstVectorRef& q,
                                        const ConstVectorRef& v, const ConstVectorRef& z,
                                        const JacobianRequest& request, ForceJacobians* J) const {
  (void)z;
  Data& d = own(data);
  if (!options_.bushings.empty()) {
    if (!d.forest_derivatives) d.forest_derivatives = std::make_unique<ForestDerivatives>(*this);
    d.forest_derivatives->compute(q, v, request.acceleration, &J->dF_dq, &J->dF_dv);
    add_element_jacobians(t, q, v, J);
    J->approximated_terms = 0;
    return;
  }
  if (!d.derivatives)
    d.derivatives = std::make_unique<RneaDerivatives>(make_rnea_derivatives(*this));
  const Vec6<double> world_acceleration = world_acceleration_at(t);
  d.derivatives->compute(q, v, request.acceleration, &J->dF_dq, &J->dF_dv, &world_acceleration);
  add_element_jacobians(t, q, v, J);
  J->approximated_terms = 0;
}

void ArticulatedSystem::add_element_jacobians(double t, const ConstVectorRef& q,
                                              const ConstVectorRef& v, ForceJacobians* J) const {
  const Patterns& P = patterns();
  for_each_element_set(
      [&](const auto& set, int type) { set.add_jacobians(t, q, v, P.element_slots[type], J); });
}

Vec6<double> ArticulatedSystem::world_acceleration_at(double t) const {
  Vec6<double> a = model_.world_acceleration;
  if (options_.root_motion) {
    // In the base's translating frame gravity is g - d''(t).
    for (int k = 0; k < 3; ++k) a[3 + k] += (*options_.root_motion)[k].acceleration(t);
  }
  return a;
}

Eigen::Vector3d ArticulatedSystem::root_displacement(double t) const {
  Eigen::Vector3d d = Eigen::Vector3d::Zero();
  if (options_.root_motion) {
    for (int k = 0; k < 3; ++k) d[k] = (*options_.root_motion)[k].value(t);
  }
  return d;
}

Eigen::Vector3d ArticulatedSystem::root_velocity(double t) const {
  Eigen::Vector3d d = Eigen::Vector3d::Zero();
  if (options_.root_motion) {
    for (int k = 0; k < 3; ++k) d[k] = (*options_.root_motion)[k].rate(t);
  }
  return d;
}

void ArticulatedSystem::automatic_force_jacobians(SystemData& data, double t,
                                                  const ConstVectorRef& q, const ConstVectorRef& v,
                                                  const ConstVectorRef& z,
                                                  const JacobianRequest& request,
                                                  ForceJacobians* J) const {
  (void)z;
  exact_jacobians(own(data), t, q, v, request.acceleration, J);
}

std::vector<Pose<double>> ArticulatedSystem::world_poses(const Eigen::VectorXd& q) const {
  std::vector<Pose<double>> world;
  forward_kinematics(model_.tree, q, nullptr, &world, nullptr);
  return world;
}

std::vector<Vec6<double>> ArticulatedSystem::body_velocities(const Eigen::VectorXd& q,
                                                             const Eigen::VectorXd& v) const {
  std::vector<Pose<double>> world;
  std::vector<Vec6<double>> V;
  forward_kinematics(model_.tree, q, &v, &world, &V);
  return V;
}

Vec6<double> ArticulatedSystem::world_momentum(const Eigen::VectorXd& q, const Eigen::VectorXd& v) const {
  const std::vector<Pose<double>> world = world_poses(q);
  const std::vector<Vec6<double>> V = body_velocities(q, v);
  Vec6<double> total = Vec6<double>::Zero();
  for (int i = 0; i < static_cast<int>(world.size()); ++i) {
    total += force_to_parent<double>(world[i], model_.inertia[i].apply<double>(V[i]));
  }
  return total;
}

double ArticulatedSystem::kinetic_energy(const Eigen::VectorXd& q, const Eigen::VectorXd& v) const {
  const std::vector<Vec6<double>> V = body_velocities(q, v);
  double e = 0.0;
  for (int i = 0; i < static_cast<int>(V.size()); ++i) e += 0.5 * V[i].dot(model_.inertia[i].apply<double>(V[i]));
  return e;
}

double ArticulatedSystem::energy(SystemData&, const State& s) const {
  const Eigen::VectorXd q = s.q(dims_), v = s.v(dims_);
  double e = kinetic_energy(q, v);
  const std::vector<Pose<double>> world = world_poses(q);
  for (int i = 0; i < static_cast<int>(world.size()); ++i) {
    e -= model_.inertia[i].mass * options_.gravity.dot(world[i].R * model_.inertia[i].com + world[i].p);
  }
  for_each_element_set([&](const auto& set, int) { e += set.energy(s.t, q); });
  return e;
}

int ArticulatedSystem::point_elements() const { return model_.bodies(); }

int ArticulatedSystem::point_dofs(int body) const {
  int dofs = 0;
  for (int i = body; i >= 0; i = model_.tree.bodies[i].parent) {
    dofs += joint_nv(model_.tree.bodies[i].type);
  }
  return dofs;
}

void ArticulatedSystem::point_kinematics(double t, int body, const Eigen::Vector3d& local,
                                         const ConstVectorRef& q, const ConstVectorRef& v,
                                         PointKinematics* out) const {
  // The bodies from the root down to `body`, first collected upwards. Each
  // joint is one or more elementary dofs, each a translation along a world
  // direction or a turn about a world axis through a world point: a
  // revolute or prismatic joint one; a planar joint three (in-plane
  // translations e1 and e2, then the turn about its normal through the
  // translated origin); a floating joint six (translations along its
  // frame's axes, then turns about the body's own axes through its origin)
  // and its quaternion's four coordinates (point_kinematics.h).
  std::vector<int>& dofs = out->dofs;
  dofs.clear();
  out->J.clear();
  out->axis.clear();
  out->quaternion.clear();
  for (int i = body; i >= 0; i = model_.tree.bodies[i].parent) dofs.push_back(i);
  std::reverse(dofs.begin(), dofs.end());
  const int bodies = static_cast<int>(dofs.size());
  // World poses down the path. A URDF child frame is its joint's frame, so
  // body i's world origin and axis are its joint's. J holds each turn's
  // origin until p is known, and a quaternion coordinate's dp the origin of
  // its body; axis is zero for a translation.
  Pose<double> world;
  for (int k = 0; k < bodies; ++k) {
    const int i = dofs[k];
    const TreeBody& b = model_.tree.bodies[i];
    const auto qi = q.segment(model_.q_offset[i], joint_nq(b.type));
    const Pose<double> next = compose(world, body_joint_motion<double>(model_, i, qi).pose);
    const Eigen::Matrix3d frame = world.R * b.placement.linear();
    switch (b.type) {
      case JointType::kRevolute:
        out->axis.push_back(next.R * b.axis);
        out->J.push_back(next.p);
        break;
      case JointType::kPrismatic:
        out->axis.push_back(Eigen::Vector3d::Zero());
        out->J.push_back(next.R * b.axis);
        break;
      case JointType::kPlanar: {
        Eigen::Vector3d e1, e2;
        planar_basis(b.axis, &e1, &e2);
        out->axis.push_back(Eigen::Vector3d::Zero());
        out->J.push_back(frame * e1);
        out->axis.push_back(Eigen::Vector3d::Zero());
        out->J.push_back(frame * e2);
        out->axis.push_back(frame * b.axis);
        out->J.push_back(next.p);
        break;
      }
      case JointType::kFloating: {
        for (int a = 0; a < 3; ++a) {
          out->axis.push_back(Eigen::Vector3d::Zero());
          out->J.push_back(frame.col(a));
        }
        const int first = static_cast<int>(out->J.size());
        for (int a = 0; a < 3; ++a) {
          out->axis.push_back(next.R.col(a));
          out->J.push_back(next.p);
        }
        // G = frame dR/dq_m R^T frame^T, dR/dq_m by forward mode on the
        // one definition of R(q) (it normalizes q, so G q = 0).
        using Dual = Eigen::AutoDiffScalar<Eigen::Vector4d>;
        Eigen::Matrix<Dual, 4, 1> quat;
        for (int m = 0; m < 4; ++m) quat[m] = Dual(qi[3 + m], 4, m);
        const Eigen::Matrix<Dual, 3, 3> R = quaternion_rotation<Dual>(quat);
        Eigen::Matrix3d R0, dR;
        for (int r = 0; r < 3; ++r)
          for (int c = 0; c < 3; ++c) R0(r, c) = R(r, c).value();
        for (int m = 0; m < 4; ++m) {
          for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 3; ++c) dR(r, c) = R(r, c).derivatives()[m];
          QuaternionCoordinate qc;
          qc.q_index = model_.q_offset[i] + 3 + m;
          qc.G = frame * dR * R0.transpose() * frame.transpose();
          qc.dp = next.p;
          qc.first = first;
          out->quaternion.push_back(qc);
        }
        break;
      }
    }
    world = next;
  }
  out->p = world.R * local + world.p;  // in the base frame until the end
  out->p_dot = root_velocity(t);
  for (QuaternionCoordinate& qc : out->quaternion) qc.dp = qc.G * (out->p - qc.dp);
  // dofs held the bodies; it now receives their velocity indices, filled
  // from the back so no body is overwritten before it is read (a body's
  // first column is at or after its own position in the list).
  int column = static_cast<int>(out->J.size());
  dofs.resize(column);
  out->q_index.resize(column);
  for (int k = bodies - 1; k >= 0; --k) {
    const int i = dofs[k];
    const JointType type = model_.tree.bodies[i].type;
    for (int j = joint_nv(type) - 1; j >= 0; --j) {
      --column;
      dofs[column] = model_.v_offset[i] + j;
      // A floating joint's angular velocity has no coordinate of its own.
      out->q_index[column] = type == JointType::kFloating && j >= 3 ? -1 : model_.q_offset[i] + j;
      if (!out->axis[column].isZero()) {
        out->J[column] = out->axis[column].cross(out->p - out->J[column]);
      }
      out->p_dot += out->J[column] * v[dofs[column]];
    }
  }
  out->p += root_displacement(t);
}

double ArticulatedSystem::bushing_coordinate(int k, const Eigen::VectorXd& q) const {
  const Bushing& bu = options_.bushings.at(k);
  const Eigen::VectorXd v = Eigen::VectorXd::Zero(dims_.nv);
  const BushingFrames<double> fr =
      bushing_frames<double>(bu, q, v, bushing_offsets(bu, model_.q_offset, model_.v_offset));
  if (bu.type == JointType::kPrismatic) return fr.n.dot(fr.b.pose.p - fr.xJ);
  return bushing_angle<double>(bu, fr, nullptr);
}

}  // namespace stiffsim
