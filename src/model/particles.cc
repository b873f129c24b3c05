#include "stiffsim/model/particles.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <unsupported/Eigen/AutoDiff>
#include <utility>

#include "stiffsim/error.h"

namespace stiffsim {

namespace {

// Same bound as the builders: a typo in a node count must fail with a message,
// not try to allocate terabytes (and 3 * nodes must fit in an int index).
constexpr long kMaxNodes = 10'000'000;

// Below this length a spring counts as collapsed: its direction is undefined
// and L/l would overflow. Far below any physical length, far above underflow.
constexpr double kCollapsedLength = 1e-100;

// Block order inside spring_slots_ (and the sign of each block in K and D).
enum Block { kAA = 0, kAB = 1, kBA = 2, kBB = 3 };
constexpr double kBlockSign[4] = {-1.0, +1.0, +1.0, -1.0};

std::string node_range(int n) {
  std::ostringstream s;
  s << "[0, " << n << ")";
  return s.str();
}

[[noreturn]] void fail(const std::string& component, const std::string& what) {
  throw InputError((component.empty() ? std::string("particles") : component) + ": " + what);
}

std::string str(double x) {
  std::ostringstream s;
  s << x;
  return s.str();
}

template <typename Scalar>
using Vector3 = Eigen::Matrix<Scalar, 3, 1>;

// Geometry of one spring at the current positions. A collapsed spring gets
// u = 0, so both its elastic and damping forces vanish (the direction of
// k (l - L) u is undefined there), and collapsed = true so the Jacobian can
// pick a finite value.
template <typename Scalar>
struct SpringFrame {
  Vector3<Scalar> u;
  Scalar l;
  bool collapsed;
};

// A value without its derivatives (the identity on doubles).
inline double constant(double x) { return x; }
template <typename Derivatives>
Eigen::AutoDiffScalar<Derivatives> constant(const Eigen::AutoDiffScalar<Derivatives>& x) {
  return Eigen::AutoDiffScalar<Derivatives>(x.value());
}

template <typename Scalar>
SpringFrame<Scalar> spring_frame(const Vector3<Scalar>& xa, const Vector3<Scalar>& xb) {
  const Vector3<Scalar> d = xb - xa;
  const Scalar l = d.norm();
  // The derivative of |d| at d = 0 is NaN, and NaN * (u = 0) would leak into
  // dual numbers: a collapsed l is a constant.
  if (!(l > kCollapsedLength)) return {Vector3<Scalar>::Zero(), constant(l), true};
  return {d / l, l, false};
}

// f_a of MODELS.md, f_b = -f_a, with vab = v_b - v_a. The one definition of
// the spring force: forces() runs it on doubles, automatic_force_jacobians()
// on dual numbers, so the two can never disagree.
template <typename Scalar>
Vector3<Scalar> spring_force_on_a(const Spring& sp, const Vector3<Scalar>& xa,
                                  const Vector3<Scalar>& xb, const Vector3<Scalar>& vab) {
  const SpringFrame<Scalar> f = spring_frame(xa, xb);
  return (sp.k * (f.l - sp.rest_length) + sp.c * vab.dot(f.u)) * f.u;
}

// Derivative lanes of one spring: positions and velocities of its two nodes.
// Fixed size, so the dual numbers live on the stack and the automatic
// Jacobian costs O(springs), never O(springs * dofs).
enum Lane { kXa = 0, kXb = 3, kVa = 6, kVb = 9, kLanes = 12 };
using SpringDual = Eigen::AutoDiffScalar<Eigen::Matrix<double, kLanes, 1>>;

Vector3<SpringDual> seeded(const Eigen::Vector3d& value, int first_lane) {
  Vector3<SpringDual> x;
  for (int i = 0; i < 3; ++i) x[i] = SpringDual(value[i], kLanes, first_lane + i);
  return x;
}

}  // namespace

ParticleSystem::ParticleSystem(ParticleDescription description) : desc_(std::move(description)) {
  const std::string& who = desc_.name;
  const long n = static_cast<long>(desc_.positions.size());
  if (n == 0) fail(who, "has no nodes");
  if (n > kMaxNodes) {
    fail(who, std::to_string(n) + " nodes exceed the limit of " + std::to_string(kMaxNodes));
  }
  const int nodes = static_cast<int>(n);
  if (desc_.masses.size() != desc_.positions.size()) {
    fail(who, std::to_string(desc_.masses.size()) + " masses given for " + std::to_string(nodes) +
                  " nodes");
  }
  if (!desc_.lattice.empty() && desc_.lattice.size() != desc_.positions.size()) {
    fail(who, std::to_string(desc_.lattice.size()) + " lattice coordinates given for " +
                  std::to_string(nodes) + " nodes");
  }
  if (!desc_.velocities.empty() && desc_.velocities.size() != desc_.positions.size()) {
    fail(who, std::to_string(desc_.velocities.size()) + " velocities given for " +
                  std::to_string(nodes) + " nodes");
  }
  for (std::size_t i = 0; i < desc_.velocities.size(); ++i) {
    if (!desc_.velocities[i].allFinite()) {
      fail(who, "velocity of node " + std::to_string(i) + " is not finite");
    }
  }
  for (int i = 0; i < nodes; ++i) {
    if (!desc_.positions[i].allFinite()) {
      fail(who, "position of node " + std::to_string(i) + " is not finite");
    }
    const double m = desc_.masses[i];
    if (!(std::isfinite(m) && m > 0.0)) {
      fail(who,
           "mass of node " + std::to_string(i) + " must be finite and > 0 (got " + str(m) + ")");
    }
  }
  for (size_t s = 0; s < desc_.springs.size(); ++s) {
    const Spring& sp = desc_.springs[s];
    const std::string tag = "spring " + std::to_string(s) + ": ";
    for (int end : {sp.a, sp.b}) {
      if (end < 0 || end >= nodes) {
        fail(who, tag + "node " + std::to_string(end) + " out of range " + node_range(nodes));
      }
    }
    if (sp.a == sp.b) fail(who, tag + "connects node " + std::to_string(sp.a) + " to itself");
    if (!(std::isfinite(sp.k) && sp.k >= 0.0)) {
      fail(who, tag + "stiffness k must be finite and >= 0 (got " + str(sp.k) + ")");
    }
    if (!(std::isfinite(sp.c) && sp.c >= 0.0)) {
      fail(who, tag + "damping c must be finite and >= 0 (got " + str(sp.c) + ")");
    }
    // Zero is legal (a zero-rest-length spring, even between coincident
    // nodes): its force k d is smooth everywhere.
    if (!(std::isfinite(sp.rest_length) && sp.rest_length >= 0.0)) {
      fail(who, tag + "rest length must be finite and >= 0 (got " + str(sp.rest_length) + ")");
    }
  }
  for (int p : desc_.pinned) {
    if (p < 0 || p >= nodes) {
      fail(who, "pinned node " + std::to_string(p) + " out of range " + node_range(nodes));
    }
  }
  motion_of_node_.assign(nodes, -1);
  for (std::size_t k = 0; k < desc_.pin_motions.size(); ++k) {
    const int p = desc_.pin_motions[k].node;
    if (p < 0 || p >= nodes) {
      fail(who, "moving pin " + std::to_string(p) + " out of range " + node_range(nodes));
    }
    if (std::find(desc_.pinned.begin(), desc_.pinned.end(), p) == desc_.pinned.end()) {
      fail(who, "moving pin " + std::to_string(p) + " is not a pinned node");
    }
    if (motion_of_node_[p] >= 0) fail(who, "node " + std::to_string(p) + " has two motions");
    motion_of_node_[p] = static_cast<int>(k);
  }
  if (!desc_.gravity.allFinite()) fail(who, "gravity is not finite");
  if (!(std::isfinite(desc_.drag) && desc_.drag >= 0.0)) {
    fail(who, "drag must be finite and >= 0 (got " + str(desc_.drag) + ")");
  }

  // DOFs: free nodes in node order (duplicate pins are harmless).
  std::vector<char> is_pinned(nodes, 0);
  for (int p : desc_.pinned) is_pinned[p] = 1;
  dof_of_node_.assign(nodes, -1);
  for (int i = 0; i < nodes; ++i) {
    if (!is_pinned[i]) dof_of_node_[i] = 3 * free_nodes_++;
  }
  const int nv = 3 * free_nodes_;

  PatternBuilder mass(nv, nv);
  mass.add_diagonal(0, nv);
  mass_pattern_ = mass.build();

  // K and D share one pattern: the 3x3 diagonal block of every free node
  // (drag and springs to pinned nodes land there) and both off-diagonal
  // blocks of every spring between two free nodes.
  PatternBuilder jac(nv, nv);
  for (int i = 0; i < nodes; ++i) {
    if (dof_of_node_[i] >= 0) jac.add_block(dof_of_node_[i], dof_of_node_[i], 3, 3);
  }
  for (const Spring& sp : desc_.springs) {
    const int da = dof_of_node_[sp.a], db = dof_of_node_[sp.b];
    if (da >= 0 && db >= 0) {
      jac.add_block(da, db, 3, 3);
      jac.add_block(db, da, 3, 3);
    }
  }
  jacobian_pattern_ = empty_jacobians(dimensions());
  jacobian_pattern_.dF_dq = jac.build();
  jacobian_pattern_.dF_dv = jacobian_pattern_.dF_dq;

  const SparseMatrix& K = jacobian_pattern_.dF_dq;
  auto block_slots = [&K](int row0, int col0, int* out) {
    for (int c = 0; c < 3; ++c) {
      for (int r = 0; r < 3; ++r) out[r + 3 * c] = slot_of(K, row0 + r, col0 + c);
    }
  };
  spring_slots_.resize(desc_.springs.size());
  for (size_t s = 0; s < desc_.springs.size(); ++s) {
    std::array<int, 36>& slots = spring_slots_[s];
    slots.fill(-1);
    const int da = dof_of_node_[desc_.springs[s].a], db = dof_of_node_[desc_.springs[s].b];
    if (da >= 0) block_slots(da, da, &slots[9 * kAA]);
    if (da >= 0 && db >= 0) {
      block_slots(da, db, &slots[9 * kAB]);
      block_slots(db, da, &slots[9 * kBA]);
    }
    if (db >= 0) block_slots(db, db, &slots[9 * kBB]);
  }
  diagonal_slots_.resize(nv);
  for (int i = 0; i < nv; ++i) diagonal_slots_[i] = slot_of(K, i, i);
  free_mass_.resize(nv);
  for (int i = 0; i < nodes; ++i) {
    if (dof_of_node_[i] >= 0) free_mass_.segment<3>(dof_of_node_[i]).setConstant(desc_.masses[i]);
  }
}

Dimensions ParticleSystem::dimensions() const {
  Dimensions d;
  d.nq = d.nv = 3 * free_nodes_;
  return d;
}

Capabilities ParticleSystem::capabilities() const {
  Capabilities c;
  c.identity_velocity_map = true;
  c.constant_mass_matrix = true;
  c.diagonal_mass_matrix = true;
  c.symmetric_jacobians = true;
  c.analytic_jacobians = true;
  c.automatic_jacobians = true;
  c.has_energy = true;
  // Springs and gravity conserve, dampers and drag dissipate; a moving pin
  // does work.
  c.passive = desc_.pin_motions.empty();
  return c;
}

State ParticleSystem::initial_state() const {
  const Dimensions d = dimensions();
  State s(0.0, Eigen::VectorXd::Zero(d.nx()));
  for (int i = 0; i < node_count(); ++i) {
    const int di = dof_of_node_[i];
    if (di < 0) continue;
    s.x.segment<3>(di) = desc_.positions[i];
    if (!desc_.velocities.empty()) s.x.segment<3>(d.nq + di) = desc_.velocities[i];
  }
  return s;
}

std::vector<std::string> ParticleSystem::position_names() const {
  static const char* const kAxes[3] = {"x", "y", "z"};
  std::vector<std::string> names;
  names.reserve(3 * free_nodes_);
  for (int i = 0; i < node_count(); ++i) {
    if (dof_of_node_[i] < 0) continue;
    for (const char* axis : kAxes)
      names.push_back(desc_.name + "/n" + std::to_string(i) + "/" + axis);
  }
  return names;
}

// Velocities carry the same names; the CSV tells them apart by "q:" / "v:".
std::vector<std::string> ParticleSystem::velocity_names() const { return position_names(); }

const SparseMatrix& ParticleSystem::mass_matrix_pattern() const { return mass_pattern_; }

void ParticleSystem::mass_matrix(const ConstVectorRef& q, SparseMatrix* M) const {
  (void)q;
  if (M->rows() != free_mass_.size() || M->nonZeros() != free_mass_.size()) {
    throw std::logic_error(name() + ": mass_matrix() needs a matrix with mass_matrix_pattern()");
  }
  // A diagonal pattern stores exactly one entry per column, in column order.
  std::copy(free_mass_.data(), free_mass_.data() + free_mass_.size(), M->valuePtr());
}

Eigen::Vector3d ParticleSystem::pinned_position(int node, double t) const {
  Eigen::Vector3d x = desc_.positions[node];
  const int m = motion_of_node_[node];
  if (m >= 0) {
    for (int k = 0; k < 3; ++k) x[k] += desc_.pin_motions[m].displacement[k].value(t);
  }
  return x;
}

Eigen::Vector3d ParticleSystem::pinned_velocity(int node, double t) const {
  Eigen::Vector3d v = Eigen::Vector3d::Zero();
  const int m = motion_of_node_[node];
  if (m >= 0) {
    for (int k = 0; k < 3; ++k) v[k] = desc_.pin_motions[m].displacement[k].rate(t);
  }
  return v;
}

Eigen::Vector3d ParticleSystem::node_position(int i, const ConstVectorRef& q, double t) const {
  const int di = dof_of_node_[i];
  if (di >= 0) return q.segment<3>(di);
  return motion_of_node_[i] < 0 ? desc_.positions[i] : pinned_position(i, t);
}

Eigen::Vector3d ParticleSystem::node_velocity(int i, const ConstVectorRef& v, double t) const {
  const int di = dof_of_node_[i];
  if (di >= 0) return v.segment<3>(di);
  return motion_of_node_[i] < 0 ? Eigen::Vector3d::Zero() : pinned_velocity(i, t);
}

void ParticleSystem::point_kinematics(double t, int node, const Eigen::Vector3d& local,
                                      const ConstVectorRef& q, const ConstVectorRef& v,
                                      PointKinematics* out) const {
  (void)local;  // a node has no extent
  out->p = node_position(node, q, t);
  out->p_dot = node_velocity(node, v, t);
  const int di = dof_of_node_[node];
  const int n = di >= 0 ? 3 : 0;
  out->dofs.resize(n);
  out->J.resize(n);
  out->axis.resize(n);
  for (int k = 0; k < n; ++k) {
    out->dofs[k] = di + k;
    out->J[k] = Eigen::Vector3d::Unit(k);
    out->axis[k].setZero();
  }
}

void ParticleSystem::forces(double t, const ConstVectorRef& q, const ConstVectorRef& v,
                            const ConstVectorRef& z, VectorRef F) const {
  (void)z;
  const double alpha = desc_.drag;
  for (int i = 0; i < node_count(); ++i) {
    const int di = dof_of_node_[i];
    if (di < 0) continue;
    F.segment<3>(di) = desc_.masses[i] * (desc_.gravity - alpha * v.segment<3>(di));
  }
  for (const Spring& sp : desc_.springs) {
    const int da = dof_of_node_[sp.a], db = dof_of_node_[sp.b];
    if (da < 0 && db < 0) continue;  // both ends pinned: no force on any DOF
    const Eigen::Vector3d xa = node_position(sp.a, q, t), xb = node_position(sp.b, q, t);
    const Eigen::Vector3d vab = node_velocity(sp.b, v, t) - node_velocity(sp.a, v, t);
    const Eigen::Vector3d fa = spring_force_on_a(sp, xa, xb, vab);
    if (da >= 0) F.segment<3>(da) += fa;
    if (db >= 0) F.segment<3>(db) -= fa;
  }
}

const ForceJacobians& ParticleSystem::jacobian_pattern() const { return jacobian_pattern_; }

void ParticleSystem::check_jacobian_pattern(const ForceJacobians& J, const char* caller) const {
  const SparseMatrix& P = jacobian_pattern_.dF_dq;
  if (J.dF_dq.nonZeros() != P.nonZeros() || J.dF_dv.nonZeros() != P.nonZeros() ||
      J.dF_dq.rows() != P.rows() || J.dF_dv.rows() != P.rows()) {
    throw std::logic_error(name() + ": " + caller + "() needs matrices with jacobian_pattern()");
  }
}

void ParticleSystem::force_jacobians(double t, const ConstVectorRef& q, const ConstVectorRef& v,
                                     const ConstVectorRef& z, const JacobianRequest& request,
                                     ForceJacobians* J) const {
  (void)z;
  check_jacobian_pattern(*J, "force_jacobians");
  set_zero_keep_pattern(&J->dF_dq);
  set_zero_keep_pattern(&J->dF_dv);
  double* K = J->dF_dq.valuePtr();
  double* D = J->dF_dv.valuePtr();

  for (size_t i = 0; i < diagonal_slots_.size(); ++i)
    D[diagonal_slots_[i]] = -desc_.drag * free_mass_[i];

  long approximated = 0;
  for (size_t s = 0; s < desc_.springs.size(); ++s) {
    const Spring& sp = desc_.springs[s];
    const int da = dof_of_node_[sp.a], db = dof_of_node_[sp.b];
    if (da < 0 && db < 0) continue;
    const SpringFrame<double> f = spring_frame(node_position(sp.a, q, t), node_position(sp.b, q, t));

    // S = df_a/dx_b. The damping force c ((v_b - v_a).u) u also depends on x
    // through u; unless the request is complete that derivative is dropped
    // (MODELS.md allows it: it only slows Newton down, the residual stays
    // exact), which is also what keeps K symmetric.
    Eigen::Matrix3d S;
    if (f.collapsed) {
      // Direction undefined. k I is the exact Jacobian of a zero-rest-length
      // spring (force k d), the only kind that can rest collapsed; for L > 0
      // the exact transverse stiffness diverges as l -> 0, and k I is a
      // finite, positive semidefinite stand-in for it.
      S = sp.k * Eigen::Matrix3d::Identity();
      if (request.definite && sp.rest_length > 0.0 && sp.k > 0.0) ++approximated;
    } else {
      double transverse = 1.0 - sp.rest_length / f.l;
      if (request.definite && transverse < 0.0) {
        // Choi & Ko 2002: a compressed spring's negative transverse stiffness
        // can make -K indefinite; the iteration matrix drops it.
        transverse = 0.0;
        if (sp.k > 0.0) ++approximated;
      }
      const Eigen::Matrix3d uut = f.u * f.u.transpose();
      S = sp.k * (transverse * (Eigen::Matrix3d::Identity() - uut) + uut);
      if (request.complete && sp.c != 0.0) {
        // d/dd [c (w.u) u] with w = v_b - v_a and du/dd = P / l,
        // P = I - u u^T: c (u (P w)^T + (w.u) P) / l. Unsymmetric.
        const Eigen::Vector3d w = node_velocity(sp.b, v, t) - node_velocity(sp.a, v, t);
        const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - uut;
        S += (sp.c / f.l) * (f.u * (P * w).transpose() + w.dot(f.u) * P);
      }
    }
    const Eigen::Matrix3d C = sp.c * f.u * f.u.transpose();

    const std::array<int, 36>& slots = spring_slots_[s];
    for (int blk = 0; blk < 4; ++blk) {
      const int* bs = &slots[9 * blk];
      if (bs[0] < 0) continue;  // block touches a pinned node
      const double sign = kBlockSign[blk];
      for (int e = 0; e < 9; ++e) {
        // Slots are column-major within the block. Every block is +-df_a/dx_b
        // (f_b = -f_a, and f_a depends on x_b - x_a only), so the same
        // (row, col) of S serves all four even when S is unsymmetric.
        K[bs[e]] += sign * S(e % 3, e / 3);
        D[bs[e]] += sign * C(e % 3, e / 3);
      }
    }
  }
  J->approximated_terms = approximated;
}

void ParticleSystem::automatic_force_jacobians(double t, const ConstVectorRef& q,
                                               const ConstVectorRef& v, const ConstVectorRef& z,
                                               const JacobianRequest& request,
                                               ForceJacobians* J) const {
  (void)z, (void)request;  // exact and complete whatever the request
  check_jacobian_pattern(*J, "automatic_force_jacobians");
  set_zero_keep_pattern(&J->dF_dq);
  set_zero_keep_pattern(&J->dF_dv);
  double* K = J->dF_dq.valuePtr();
  double* D = J->dF_dv.valuePtr();

  // Gravity is constant and drag linear: their derivatives are known exactly
  // without dual numbers (as in force_jacobians()).
  for (size_t i = 0; i < diagonal_slots_.size(); ++i)
    D[diagonal_slots_[i]] = -desc_.drag * free_mass_[i];

  for (size_t s = 0; s < desc_.springs.size(); ++s) {
    const Spring& sp = desc_.springs[s];
    const int da = dof_of_node_[sp.a], db = dof_of_node_[sp.b];
    if (da < 0 && db < 0) continue;
    const Eigen::Vector3d xa = node_position(sp.a, q, t), xb = node_position(sp.b, q, t);
    // A pinned node's lanes are seeded anyway (uniform code) and simply
    // never scattered, as their slots are -1.
    const Eigen::Vector3d va = node_velocity(sp.a, v, t), vb = node_velocity(sp.b, v, t);
    const Vector3<SpringDual> vab = seeded(vb, kVb) - seeded(va, kVa);
    const Vector3<SpringDual> fa =
        spring_force_on_a<SpringDual>(sp, seeded(xa, kXa), seeded(xb, kXb), vab);

    const std::array<int, 36>& slots = spring_slots_[s];
    for (int blk = 0; blk < 4; ++blk) {
      const int* bs = &slots[9 * blk];
      if (bs[0] < 0) continue;
      // Rows of node a take +df_a, rows of node b take df_b = -df_a; columns
      // of node a read the a lanes, columns of node b the b lanes.
      const double sign = (blk == kAA || blk == kAB) ? 1.0 : -1.0;
      const bool column_b = blk == kAB || blk == kBB;
      const int x_lane = column_b ? kXb : kXa;
      const int v_lane = column_b ? kVb : kVa;
      for (int e = 0; e < 9; ++e) {
        const auto& derivatives = fa[e % 3].derivatives();
        K[bs[e]] += sign * derivatives[x_lane + e / 3];
        D[bs[e]] += sign * derivatives[v_lane + e / 3];
      }
    }
  }
  J->approximated_terms = 0;
}

std::vector<int> ParticleSystem::jacobian_colouring_hint() const {
  const auto& lattice = desc_.lattice;
  if (lattice.empty()) return {};
  for (const Spring& sp : desc_.springs) {
    const int span = std::abs(lattice[sp.a][0] - lattice[sp.b][0]) +
                     std::abs(lattice[sp.a][1] - lattice[sp.b][1]);
    if (span > 2) return {};
  }
  const Dimensions d = dimensions();
  std::vector<int> colour(d.nx(), -1);
  for (int node = 0; node < node_count(); ++node) {
    const int dof = dof_of_node_[node];
    if (dof < 0) continue;
    const int c = (((lattice[node][0] + 5 * lattice[node][1]) % 13) + 13) % 13;
    for (int k = 0; k < 3; ++k) {
      colour[dof + k] = 6 * c + k;
      colour[d.nq + dof + k] = 6 * c + 3 + k;
    }
  }
  return colour;
}

double ParticleSystem::energy(const State& s) const {
  const Dimensions dims = dimensions();
  const auto q = s.q(dims);
  const auto v = s.v(dims);
  auto position = [&](int i) -> Eigen::Vector3d { return node_position(i, q, s.t); };
  // Pinned nodes are included with their positions at s.t (for a fixed pin
  // a constant offset that makes this the total energy of every particle, as
  // a physicist would write it; differences in time are unaffected). A
  // moving pin's own kinetic energy is left out: no force acts on it.
  double e = 0.0;
  for (int i = 0; i < node_count(); ++i) {
    const int di = dof_of_node_[i];
    const double m = desc_.masses[i];
    if (di >= 0) e += 0.5 * m * v.segment<3>(di).squaredNorm();
    e -= m * desc_.gravity.dot(position(i));
  }
  for (const Spring& sp : desc_.springs) {
    const double stretch = (position(sp.b) - position(sp.a)).norm() - sp.rest_length;
    e += 0.5 * sp.k * stretch * stretch;
  }
  return e;
}

}  // namespace stiffsim
