#include "stiffsim/model/particles.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <type_traits>
#include <unordered_map>
#include <unsupported/Eigen/AutoDiff>
#include <utility>

#include "stiffsim/error.h"

namespace stiffsim {

namespace {

// Same bound as the builders: a typo in a node count must fail with a message,
// not try to allocate terabytes (and 3 * nodes must fit in an int index).
constexpr long kMaxNodes = 10'000'000;

std::string node_range(int n) {
  std::ostringstream s;
  s << "[0, " << n << ")";
  return s.str();
}

[[noreturn]] void fail(const std::string& component, const std::string& what) {
  throw InputError((component.empty() ? std::string("particles") : component) + ": " + what);
}

// Derivative lanes of one element: positions then velocities of its
// stencil's nodes. Fixed size, so the dual numbers live on the stack and the
// automatic Jacobian costs O(elements), never O(elements * dofs).
template <int Nodes>
using ElementDual = Eigen::AutoDiffScalar<Eigen::Matrix<double, 6 * Nodes, 1>>;

template <int Nodes>
Vector3<ElementDual<Nodes>> seeded(const Eigen::Vector3d& value, int first_lane) {
  Vector3<ElementDual<Nodes>> x;
  for (int i = 0; i < 3; ++i) x[i] = ElementDual<Nodes>(value[i], 6 * Nodes, first_lane + i);
  return x;
}

}  // namespace

template <typename E>
inline bool ParticleSystem::gather(const E& e, double t, const ConstVectorRef& q,
                                   const ConstVectorRef& v, Eigen::Vector3d* x,
                                   Eigen::Vector3d* vel, int* dofs) const {
  const auto stencil = e.nodes();
  bool moves = false;
  for (int i = 0; i < E::kNodes; ++i) {
    // Free nodes read the state in place; the hot loops must not pay a call
    // per node for them.
    const int d = dof_of_node_[stencil[i]];
    if (dofs) dofs[i] = d;
    if (d >= 0) {
      x[i] = q.segment<3>(d);
      vel[i] = v.segment<3>(d);
      moves = true;
    } else {
      x[i] = node_position(stencil[i], q, t);
      vel[i] = node_velocity(stencil[i], v, t);
    }
  }
  return moves;
}

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
      fail(who, "mass of node " + std::to_string(i) + " must be finite and > 0 (got " +
                    format_number(m) + ")");
    }
  }
  springs_.elements.reserve(desc_.springs.size());
  for (size_t s = 0; s < desc_.springs.size(); ++s) {
    springs_.elements.emplace_back(desc_.springs[s], s, nodes, who);
  }
  // The loops over the springs run in node order (by the lower node, then
  // the higher), not in the description's: a mesh lists its springs by
  // kind (stretch, shear, bend), and each kind's pass swept the whole of
  // the Jacobians' values, 9.2 MB each on the 100x100 sheet, where in node
  // order a spring's four blocks lie near the last one's.
  std::stable_sort(springs_.elements.begin(), springs_.elements.end(),
                   [](const SpringElement& x, const SpringElement& y) {
                     const auto [xa, xb] = x.nodes();
                     const auto [ya, yb] = y.nodes();
                     return std::make_pair(std::min(xa, xb), std::max(xa, xb)) <
                            std::make_pair(std::min(ya, yb), std::max(ya, yb));
                   });
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
    fail(who, "drag must be finite and >= 0 (got " + format_number(desc_.drag) + ")");
  }

  // DOFs: free nodes in node order (duplicate pins are harmless).
  std::vector<char> is_pinned(nodes, 0);
  for (int p : desc_.pinned) is_pinned[p] = 1;
  dof_of_node_.assign(nodes, -1);
  for (int i = 0; i < nodes; ++i) {
    if (!is_pinned[i]) dof_of_node_[i] = 3 * free_nodes_++;
  }
  const int nv = 3 * free_nodes_;
  free_springs_ = SpringBatch(springs_.elements, dof_of_node_);
  for (size_t k = 0; k < springs_.elements.size(); ++k) {
    const auto [a, b] = springs_.elements[k].nodes();
    if (dof_of_node_[a] < 0 || dof_of_node_[b] < 0) pinned_springs_.push_back(static_cast<int>(k));
  }

  PatternBuilder mass(nv, nv);
  mass.add_diagonal(0, nv);
  mass_pattern_ = mass.build();

  // K and D share one pattern: the 3x3 diagonal block of every free node
  // (drag and springs to pinned nodes land there) and both off-diagonal
  // blocks of every spring between two free nodes. Collected per node
  // pair and expanded to 3x3 blocks: per entry (1.2 M of them, 9 MB in a
  // vector grown by doubling) it took 0.26 s of the 100x100 sheet's
  // set-up, most of it in page faults and copies.
  PatternBuilder jac(free_nodes_, free_nodes_);
  for (int i = 0; i < nodes; ++i) {
    if (dof_of_node_[i] >= 0) jac.add(dof_of_node_[i] / 3, dof_of_node_[i] / 3);
  }
  for_each_element_set([&](const auto& set) {
    for (const auto& e : set.elements) {
      const auto stencil = e.nodes();
      for (int i : stencil) {
        for (int j : stencil) {
          if (i != j && dof_of_node_[i] >= 0 && dof_of_node_[j] >= 0) {
            jac.add(dof_of_node_[i] / 3, dof_of_node_[j] / 3);
          }
        }
      }
    }
  });
  jacobian_pattern_ = empty_jacobians(dimensions());
  jacobian_pattern_.dF_dq = expand_blocks(jac.build(), 3);
  jacobian_pattern_.dF_dv = jacobian_pattern_.dF_dq;

  const SparseMatrix& K = jacobian_pattern_.dF_dq;
  auto block_slots = [&K](int row0, int col0, int* out) {
    for (int c = 0; c < 3; ++c) {
      for (int r = 0; r < 3; ++r) out[r + 3 * c] = slot_of(K, row0 + r, col0 + c);
    }
  };
  for_each_element_set([&](auto& set) {
    constexpr int n = std::decay_t<decltype(set)>::kNodes;
    set.slots.resize(set.elements.size());
    for (size_t k = 0; k < set.elements.size(); ++k) {
      const auto stencil = set.elements[k].nodes();
      auto& slots = set.slots[k];
      slots.fill(-1);
      for (int i = 0; i < n; ++i) {
        for (int j = 0; j < n; ++j) {
          const int di = dof_of_node_[stencil[i]], dj = dof_of_node_[stencil[j]];
          if (di >= 0 && dj >= 0) block_slots(di, dj, &slots[9 * (i * n + j)]);
        }
      }
    }
  });
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

void ParticleSystem::mass_matrix(SystemData&, const ConstVectorRef& q, SparseMatrix* M) const {
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

void ParticleSystem::point_kinematics(double t, int node, const Eigen::Vector3d& local,
                                      const ConstVectorRef& q, const ConstVectorRef& v,
                                      PointKinematics* out) const {
  (void)local;  // a node has no extent
  out->p = node_position(node, q, t);
  out->p_dot = node_velocity(node, v, t);
  const int di = dof_of_node_[node];
  const int n = di >= 0 ? 3 : 0;
  out->dofs.resize(n);
  out->q_index.resize(n);
  out->J.resize(n);
  out->axis.resize(n);
  out->quaternion.clear();
  for (int k = 0; k < n; ++k) {
    out->dofs[k] = di + k;
    out->q_index[k] = di + k;
    out->J[k] = Eigen::Vector3d::Unit(k);
    out->axis[k].setZero();
  }
}

void ParticleSystem::forces(SystemData&, double t, const ConstVectorRef& q, const ConstVectorRef& v,
                            const ConstVectorRef& z, VectorRef F) const {
  (void)z;
  const double alpha = desc_.drag;
  for (int i = 0; i < node_count(); ++i) {
    const int di = dof_of_node_[i];
    if (di < 0) continue;
    F.segment<3>(di) = desc_.masses[i] * (desc_.gravity - alpha * v.segment<3>(di));
  }
  // The springs between free nodes, four at a time (spring_batch.h): each
  // GMRES product evaluates the forces once, and on the 100x100 sheet an
  // evaluation took 390 us with every spring through its element (as the
  // springs to a pinned node still go, below) against 220 us (BM_Forces).
  free_springs_.add_forces(q.data(), v.data(), F.data());
  Eigen::Vector3d x[2], vel[2], f[2];
  int dofs[2];
  for (int k : pinned_springs_) {
    const SpringElement& e = springs_.elements[k];
    if (!gather(e, t, q, v, x, vel, dofs)) continue;  // every node pinned: no force on a DOF
    e.force(x, vel, f);
    for (int i = 0; i < 2; ++i) {
      if (dofs[i] >= 0) F.segment<3>(dofs[i]) += f[i];
    }
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

void ParticleSystem::force_jacobians(SystemData&, double t, const ConstVectorRef& q,
                                     const ConstVectorRef& v, const ConstVectorRef& z,
                                     const JacobianRequest& request, ForceJacobians* J) const {
  (void)z;
  check_jacobian_pattern(*J, "force_jacobians");
  set_zero_keep_pattern(&J->dF_dq);
  set_zero_keep_pattern(&J->dF_dv);
  double* K = J->dF_dq.valuePtr();
  double* D = J->dF_dv.valuePtr();

  for (size_t i = 0; i < diagonal_slots_.size(); ++i)
    D[diagonal_slots_[i]] = -desc_.drag * free_mass_[i];

  long approximated = 0;
  const Eigen::Map<const Eigen::VectorXd> tension_q(
      request.tension_positions ? request.tension_positions : q.data(), q.size());
  for_each_element_set([&](const auto& set) {
    using Element = typename std::decay_t<decltype(set)>::Element;
    constexpr int n = Element::kNodes;
    Eigen::Vector3d x[n], vel[n], x_tension[n], v_unused[n];
    const Eigen::Vector3d* tension = request.tension_positions ? x_tension : nullptr;
    for (size_t k = 0; k < set.elements.size(); ++k) {
      if (!gather(set.elements[k], t, q, v, x, vel)) continue;
      if (request.tension_positions) gather(set.elements[k], t, tension_q, v, x_tension, v_unused);
      const auto& slots = set.slots[k];  // column-major within each block
      if constexpr (is_difference_element<Element>::value) {
        Eigen::Matrix3d S, C;
        set.elements[k].jacobian_difference(x, vel, tension, request, &S, &C, &approximated);
        constexpr double kSign[4] = {-1.0, +1.0, +1.0, -1.0};
        const double* s = S.data();  // column-major too
        const double* c = C.data();
        for (int blk = 0; blk < 4; ++blk) {
          const int* bs = &slots[9 * blk];
          if (bs[0] < 0) continue;  // the block touches a pinned node
          for (int e = 0; e < 9; ++e) {
            K[bs[e]] += kSign[blk] * s[e];
            D[bs[e]] += kSign[blk] * c[e];
          }
        }
      } else {
        Eigen::Matrix3d Kb[n * n], Db[n * n];
        set.elements[k].jacobian_blocks(x, vel, tension, request, Kb, Db, &approximated);
        for (int blk = 0; blk < n * n; ++blk) {
          const int* bs = &slots[9 * blk];
          if (bs[0] < 0) continue;  // the block touches a pinned node
          for (int e = 0; e < 9; ++e) {
            K[bs[e]] += Kb[blk](e % 3, e / 3);
            D[bs[e]] += Db[blk](e % 3, e / 3);
          }
        }
      }
    }
  });
  J->approximated_terms = approximated;
}

void ParticleSystem::automatic_force_jacobians(SystemData&, double t, const ConstVectorRef& q,
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

  for_each_element_set([&](const auto& set) {
    constexpr int n = std::decay_t<decltype(set)>::kNodes;
    using Dual = ElementDual<n>;
    Eigen::Vector3d x[n], vel[n];
    Vector3<Dual> xd[n], vd[n], fd[n];
    for (size_t k = 0; k < set.elements.size(); ++k) {
      if (!gather(set.elements[k], t, q, v, x, vel)) continue;
      // A pinned node's lanes are seeded anyway (uniform code) and simply
      // never scattered, as their slots are -1.
      for (int i = 0; i < n; ++i) {
        xd[i] = seeded<n>(x[i], 3 * i);
        vd[i] = seeded<n>(vel[i], 3 * n + 3 * i);
      }
      set.elements[k].force(xd, vd, fd);
      const auto& slots = set.slots[k];
      for (int i = 0; i < n; ++i) {
        for (int j = 0; j < n; ++j) {
          const int* bs = &slots[9 * (i * n + j)];
          if (bs[0] < 0) continue;
          // Rows of node i take df_i; columns of node j read node j's lanes.
          for (int e = 0; e < 9; ++e) {
            const auto& derivatives = fd[i][e % 3].derivatives();
            K[bs[e]] += derivatives[3 * j + e / 3];
            D[bs[e]] += derivatives[3 * n + 3 * j + e / 3];
          }
        }
      }
    }
  });
  J->approximated_terms = 0;
}

std::vector<std::array<int, 2>> ParticleSystem::covered_couplings() const {
  const std::vector<Spring>& springs = desc_.springs;
  const long nodes = node_count();
  auto key = [nodes](int a, int b) {
    return static_cast<long long>(std::min(a, b)) * nodes + std::max(a, b);
  };
  // The spring on each pair of nodes, or -1 where several share it.
  std::unordered_map<long long, int> on_pair;
  std::vector<std::vector<int>> at_node(node_count());
  for (int s = 0; s < static_cast<int>(springs.size()); ++s) {
    const auto [it, fresh] = on_pair.emplace(key(springs[s].a, springs[s].b), s);
    if (!fresh) it->second = -1;
    at_node[springs[s].a].push_back(s);
    at_node[springs[s].b].push_back(s);
  }
  auto covers = [&](int t, const Spring& s) {
    const Spring& u = springs[t];
    return u.k >= System::kCoverageRatio * s.k && u.c >= System::kCoverageRatio * s.c;
  };
  std::vector<std::array<int, 2>> pairs;
  for (int s = 0; s < static_cast<int>(springs.size()); ++s) {
    const Spring& sp = springs[s];
    const int da = dof_of_node_[sp.a], db = dof_of_node_[sp.b];
    if (da < 0 || db < 0 || on_pair.at(key(sp.a, sp.b)) != s) continue;
    const Eigen::Vector3d& xa = desc_.positions[sp.a];
    const Eigen::Vector3d& xb = desc_.positions[sp.b];
    for (int t : at_node[sp.a]) {
      const int m = springs[t].a == sp.a ? springs[t].b : springs[t].a;
      if (m == sp.b || !covers(t, sp)) continue;
      const auto other = on_pair.find(key(m, sp.b));
      if (other == on_pair.end() || other->second < 0 || !covers(other->second, sp)) continue;
      const Eigen::Vector3d& xm = desc_.positions[m];
      if ((xa + xb - 2.0 * xm).norm() <= kCollinearity * (xa - xb).norm()) {
        pairs.push_back({da, db});
        break;
      }
    }
  }
  return pairs;
}

std::vector<int> ParticleSystem::jacobian_colouring_hint() const {
  const auto& lattice = desc_.lattice;
  if (lattice.empty()) return {};
  bool short_stencils = true;
  for_each_element_set([&](const auto& set) {
    for (const auto& e : set.elements) {
      for (int a : e.nodes()) {
        for (int b : e.nodes()) {
          const int span =
              std::abs(lattice[a][0] - lattice[b][0]) + std::abs(lattice[a][1] - lattice[b][1]);
          if (span > 2) short_stencils = false;
        }
      }
    }
  });
  if (!short_stencils) return {};
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

double ParticleSystem::energy(SystemData&, const State& s) const {
  const Dimensions dims = dimensions();
  const ConstVectorRef q = s.q(dims);
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
  for_each_element_set([&](const auto& set) {
    constexpr int n = std::decay_t<decltype(set)>::kNodes;
    Eigen::Vector3d x[n];
    for (const auto& element : set.elements) {
      const auto stencil = element.nodes();
      for (int i = 0; i < n; ++i) x[i] = position(stencil[i]);
      e += element.energy(x);
    }
  });
  return e;
}

}  // namespace stiffsim
