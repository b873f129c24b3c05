#include "stiffsim/scene.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cassert>
#include <cmath>
#include <functional>
#include <stdexcept>

#include "stiffsim/error.h"
#include "stiffsim/linalg/sparse_pattern.h"
#include "stiffsim/structured_newton_matrix.h"

namespace stiffsim {
namespace {

// Adds `part` to the builder at the given offsets, or an identity block when
// the component has N = I and therefore no pattern of its own.
void add_velocity_map_block(const System& c, const Dimensions& off, PatternBuilder* b) {
  const Dimensions d = c.dimensions();
  if (c.capabilities().identity_velocity_map) {
    for (int i = 0; i < d.nv; ++i) b->add(off.nq + i, off.nv + i);
  } else {
    b->add_pattern(c.velocity_map_pattern(), off.nq, off.nv);
  }
}

SparseMatrix block_diagonal(const std::vector<std::unique_ptr<System>>& comps,
                            const std::vector<Dimensions>& offsets, int rows, int cols,
                            const std::function<const SparseMatrix&(const System&)>& get,
                            const std::function<std::pair<int, int>(const Dimensions&)>& at) {
  // One component fills the whole matrix: its own pattern is the result
  // (a merge of its 1.2 M entries took 0.1 s on the 100x100 sheet).
  if (comps.size() == 1) {
    const SparseMatrix& only = get(*comps[0]);
    if (only.rows() == rows && only.cols() == cols && only.isCompressed()) {
      SparseMatrix pattern = only;
      set_zero_keep_pattern(&pattern);
      return pattern;
    }
  }
  PatternBuilder b(rows, cols);
  for (size_t i = 0; i < comps.size(); ++i) {
    auto [r0, c0] = at(offsets[i]);
    b.add_pattern(get(*comps[i]), r0, c0);
  }
  return b.build();
}

}  // namespace

Scene::Scene(std::string name, std::vector<std::unique_ptr<System>> components,
             std::vector<Attachment> attachments)
    : name_(std::move(name)), components_(std::move(components)),
      attachments_(std::move(attachments)) {
  if (components_.empty()) throw InputError(name_ + ": a scene needs at least one component");
  caps_.identity_velocity_map = caps_.constant_mass_matrix = caps_.diagonal_mass_matrix = true;
  caps_.symmetric_jacobians = caps_.analytic_jacobians = caps_.has_energy = true;
  caps_.automatic_jacobians = caps_.passive = true;
  for (const auto& c : components_) {
    offsets_.push_back(dims_);
    const Dimensions d = c->dimensions();
    dims_.nq += d.nq;
    dims_.nv += d.nv;
    dims_.nz += d.nz;
    const Capabilities k = c->capabilities();
    caps_.identity_velocity_map &= k.identity_velocity_map;
    caps_.constant_mass_matrix &= k.constant_mass_matrix;
    caps_.diagonal_mass_matrix &= k.diagonal_mass_matrix;
    caps_.symmetric_jacobians &= k.symmetric_jacobians;
    caps_.analytic_jacobians &= k.analytic_jacobians;
    caps_.automatic_jacobians &= k.automatic_jacobians;
    caps_.has_energy &= k.has_energy;
    caps_.passive &= k.passive;
    caps_.has_quaternions |= k.has_quaternions;
  }

  caps_.momentum_residual = true;
  for (const auto& c : components_) caps_.momentum_residual &= c->capabilities().momentum_residual;

  if (!caps_.identity_velocity_map) {
    PatternBuilder b(dims_.nq, dims_.nv);
    for (size_t i = 0; i < components_.size(); ++i) {
      add_velocity_map_block(*components_[i], offsets_[i], &b);
    }
    velocity_map_pattern_ = b.build();
  }
  for (size_t i = 0; i < components_.size(); ++i) {
    const System& c = *components_[i];
    const bool own_N = !caps_.identity_velocity_map && !c.capabilities().identity_velocity_map;
    slots_N_.push_back(own_N ? slots_in(velocity_map_pattern_, c.velocity_map_pattern(),
                                        offsets_[i].nq, offsets_[i].nv)
                             : std::vector<int>());
  }

  for (const Attachment& at : attachments_) {
    const std::string who = name_ + ": attachment '" + at.name + "'";
    if (!(std::isfinite(at.k) && at.k >= 0.0 && std::isfinite(at.c) && at.c >= 0.0)) {
      throw InputError(who + ": k and c must be finite and >= 0");
    }
    if (at.a.component < 0 && at.b.component < 0) throw InputError(who + ": joins the world to itself");
    for (const AttachmentPoint* p : {&at.a, &at.b}) {
      if (p->component >= static_cast<int>(components_.size()) || !p->local.allFinite()) {
        throw InputError(who + ": no component " + std::to_string(p->component));
      }
      if (p->component < 0) continue;
      const System& s = *components_[p->component];
      if (s.point_elements() == 0) {
        throw InputError(who + ": component '" + s.name() + "' offers no points to attach to");
      }
      if (p->element < 0 || p->element >= s.point_elements()) {
        throw InputError(who + ": component '" + s.name() + "' has no point " +
                         std::to_string(p->element) + " (0.." +
                         std::to_string(s.point_elements() - 1) + ")");
      }
      most_point_dofs_ = std::max(most_point_dofs_, s.point_dofs(p->element));
    }
  }
}

// Everything a scene's evaluations write: the components' own data, the
// scratch of the attachments' points, and matrices with the components'
// own patterns to gather from.
struct Scene::Data : SystemData {
  const Scene* owner = nullptr;  // the scene that made it (checked in debug builds)
  std::vector<std::unique_ptr<SystemData>> components;
  PointKinematics point_a, point_b;
  // dp_dot/dq per column of both points (add_attachment_jacobians()).
  std::vector<Eigen::Vector3d> dp_dot_dq;
  // Per component, a state to hand energy().
  std::vector<State> component_states;
  // Per component with N != I, its N (velocity_map()).
  std::vector<SparseMatrix> N;
  // Per component, its M and Jacobians; made on first use (with the
  // patterns, which a run on a structured Newton matrix never needs).
  std::vector<SparseMatrix> M;
  std::vector<ForceJacobians> J;
};

Scene::Data& Scene::own(SystemData& data) const {
  Data& d = static_cast<Data&>(data);
  assert(d.owner == this && "a SystemData fits only the system that made it");
  return d;
}

std::unique_ptr<SystemData> Scene::make_data() const {
  auto data = std::make_unique<Data>();
  data->owner = this;
  for (size_t i = 0; i < components_.size(); ++i) {
    const System& c = *components_[i];
    data->components.push_back(c.make_data());
    data->component_states.emplace_back(0.0, Eigen::VectorXd(c.dimensions().nx()));
    data->N.push_back(slots_N_[i].empty() ? SparseMatrix() : c.velocity_map_pattern());
  }
  const int most = most_point_dofs_;
  for (PointKinematics* p : {&data->point_a, &data->point_b}) {
    p->dofs.reserve(most);
    p->q_index.reserve(most);
    p->J.reserve(most);
    p->axis.reserve(most);
    // Four quaternion coordinates per floating joint, which has six dofs.
    p->quaternion.reserve(most);
  }
  // Both points' dofs and quaternion coordinates at once.
  data->dp_dot_dq.reserve(4 * most);
  return data;
}

void Scene::attachment_points(int k, double t, const ConstVectorRef& q, const ConstVectorRef& v,
                              PointKinematics* a, PointKinematics* b) const {
  const Attachment& at = attachments_[k];
  for (auto [p, out] : {std::make_pair(&at.a, a), std::make_pair(&at.b, b)}) {
    if (p->component < 0) {
      out->p = p->local;
      out->p_dot.setZero();
      out->dofs.clear();
      out->q_index.clear();
      out->J.clear();
      out->axis.clear();
      out->quaternion.clear();
      continue;
    }
    const System& s = *components_[p->component];
    const Dimensions d = s.dimensions();
    const Dimensions& o = offsets_[p->component];
    s.point_kinematics(t, p->element, p->local, q.segment(o.nq, d.nq), v.segment(o.nv, d.nv), out);
  }
}

Eigen::Vector3d Scene::attachment_force(const Attachment& at, const PointKinematics& a,
                                        const PointKinematics& b) {
  return at.k * (b.p - a.p) + at.c * (b.p_dot - a.p_dot);
}

void Scene::add_attachment_forces(Data& data, double t, const ConstVectorRef& q,
                                  const ConstVectorRef& v, double scale, VectorRef F) const {
  const PointKinematics& point_a = data.point_a;
  const PointKinematics& point_b = data.point_b;
  for (int k = 0; k < static_cast<int>(attachments_.size()); ++k) {
    const Attachment& at = attachments_[k];
    attachment_points(k, t, q, v, &data.point_a, &data.point_b);
    // On point a; -f on point b. Generalized forces by virtual work: J^T f.
    const Eigen::Vector3d f = scale * attachment_force(at, point_a, point_b);
    const int oa = at.a.component < 0 ? 0 : offsets_[at.a.component].nv;
    const int ob = at.b.component < 0 ? 0 : offsets_[at.b.component].nv;
    for (size_t j = 0; j < point_a.dofs.size(); ++j) F[oa + point_a.dofs[j]] += point_a.J[j].dot(f);
    for (size_t j = 0; j < point_b.dofs.size(); ++j) F[ob + point_b.dofs[j]] -= point_b.J[j].dot(f);
  }
}

void Scene::add_attachment_jacobians(Data& data, double t, const ConstVectorRef& q,
                                     const ConstVectorRef& v, bool complete,
                                     ForceJacobians* J) const {
  const Patterns& L = patterns();
  double* K = J->dF_dq.valuePtr();
  double* D = J->dF_dv.valuePtr();
  const PointKinematics& point_a = data.point_a;
  const PointKinematics& point_b = data.point_b;
  std::vector<Eigen::Vector3d>& dp_dot_dq = data.dp_dot_dq;
  for (int k = 0; k < static_cast<int>(attachments_.size()); ++k) {
    const Attachment& at = attachments_[k];
    attachment_points(k, t, q, v, &data.point_a, &data.point_b);
    const Eigen::Vector3d f = attachment_force(at, point_a, point_b);
    const int na = static_cast<int>(point_a.dofs.size());
    const int n = na + static_cast<int>(point_b.dofs.size());
    // Rows are the velocity dofs of a then b, s = +1 on a's, -1 on b's:
    //   F_i = s_i J_i . f,  df/dq_m = -s_m (k dp/dq_m + c dp_dot/dq_m),
    //   df/dv_m = -s_m c J_m, and on one point's own columns the turn of
    //   its rows, s_i f . dJ_i/dq_m (point_kinematics.h). Columns of dF/dq
    //   are the coordinates of a then b: those of dofs with q_dot = v in
    //   dof order, then the quaternions'.
    auto point = [&](int i) -> const PointKinematics& { return i < na ? point_a : point_b; };
    auto local = [&](int i) { return i < na ? i : i - na; };
    auto sign = [&](int i) { return i < na ? 1.0 : -1.0; };
    // dp_dot/dq_m = axis_m x (sum_{j >= m} v_j J_j) + (sum_{j < m} v_j axis_j) x J_m
    // per dof m, then per quaternion coordinate
    // G (sum_{j >= first} v_j J_j) + (sum_{j < first} v_j axis_j) x dp.
    const int qa = static_cast<int>(point_a.quaternion.size());
    dp_dot_dq.resize(n + qa + point_b.quaternion.size());
    for (const PointKinematics* pk : {&point_a, &point_b}) {
      const bool is_a = pk == &point_a;
      const int first = is_a ? 0 : na;
      const int count = static_cast<int>(pk->dofs.size());
      const int component = is_a ? at.a.component : at.b.component;
      const int ov = component < 0 ? 0 : offsets_[component].nv;
      Eigen::Vector3d below = Eigen::Vector3d::Zero(), above = Eigen::Vector3d::Zero();
      for (int j = 0; j < count; ++j) below += v[ov + pk->dofs[j]] * pk->J[j];
      const Eigen::Vector3d all = below;
      for (int m = 0; m < count; ++m) {
        dp_dot_dq[first + m] = pk->axis[m].cross(below) + above.cross(pk->J[m]);
        below -= v[ov + pk->dofs[m]] * pk->J[m];
        above += v[ov + pk->dofs[m]] * pk->axis[m];
      }
      // Coordinates are listed root first, so `first` never decreases and
      // the sums run once down the dofs (a joint's four share them).
      Eigen::Vector3d turning = all, upstream = Eigen::Vector3d::Zero();
      int summed = 0;  // dofs before `first` taken out of turning so far
      for (size_t r = 0; r < pk->quaternion.size(); ++r) {
        const QuaternionCoordinate& qc = pk->quaternion[r];
        for (; summed < qc.first; ++summed) {
          turning -= v[ov + pk->dofs[summed]] * pk->J[summed];
          upstream += v[ov + pk->dofs[summed]] * pk->axis[summed];
        }
        dp_dot_dq[n + (is_a ? 0 : qa) + r] = qc.G * turning + upstream.cross(qc.dp);
      }
    }
    const std::vector<int>& sq = L.attachment_q[k];
    const std::vector<int>& sv = L.attachment_v[k];
    const int columns = static_cast<int>(sq.size()) / std::max(n, 1);
    for (int i = 0; i < n; ++i) {
      const PointKinematics& pi = point(i);
      const Eigen::Vector3d& Ji = pi.J[local(i)];
      const int li = local(i);
      int column = 0;
      // Columns of coordinates with q_dot = v.
      for (int m = 0; m < n; ++m) {
        const PointKinematics& pm = point(m);
        const Eigen::Vector3d& Jm = pm.J[local(m)];
        const double s = sign(i) * sign(m);
        D[sv[i * n + m]] += -at.c * s * Ji.dot(Jm);
        if (pm.q_index[local(m)] < 0) continue;
        double kq = -at.k * s * Ji.dot(Jm);
        if (complete) kq -= at.c * s * Ji.dot(dp_dot_dq[m]);
        if (&pi == &pm) {
          const int lm = local(m);
          const Eigen::Vector3d turn =
              lm <= li ? pm.axis[lm].cross(Ji) : pi.axis[li].cross(Jm);
          kq += sign(i) * f.dot(turn);
        }
        K[sq[i * columns + column++]] += kq;
      }
      // Quaternion coordinates.
      for (const PointKinematics* pm : {&point_a, &point_b}) {
        const double sm = pm == &point_a ? 1.0 : -1.0;
        const double s = sign(i) * sm;
        for (size_t r = 0; r < pm->quaternion.size(); ++r) {
          const QuaternionCoordinate& qc = pm->quaternion[r];
          double kq = -at.k * s * Ji.dot(qc.dp);
          if (complete) kq -= at.c * s * Ji.dot(dp_dot_dq[n + (pm == &point_a ? 0 : qa) + r]);
          if (&pi == pm) {
            const Eigen::Vector3d turn = li >= qc.first ? Eigen::Vector3d(qc.G * Ji)
                                                        : Eigen::Vector3d(pi.axis[li].cross(qc.dp));
            kq += sign(i) * f.dot(turn);
          }
          K[sq[i * columns + column++]] += kq;
        }
      }
    }
  }
}

const Scene::Patterns& Scene::patterns() const {
  std::call_once(patterns_built_, [this] {
    auto L = std::make_unique<Patterns>();
    using P = std::pair<int, int>;
    const auto& comps = components_;
    L->mass = block_diagonal(
        comps, offsets_, dims_.nv, dims_.nv,
        [](const System& s) -> const SparseMatrix& { return s.mass_matrix_pattern(); },
        [](const Dimensions& o) {
          return P{o.nv, o.nv};
        });
    auto jac = [&](SparseMatrix ForceJacobians::*m, int rows, int cols,
                   std::function<P(const Dimensions&)> at) {
      return block_diagonal(
          comps, offsets_, rows, cols,
          [m](const System& s) -> const SparseMatrix& { return s.jacobian_pattern().*m; }, at);
    };
    const Dimensions& D = dims_;
    ForceJacobians& J0 = L->jacobians;
    J0.dF_dq = jac(&ForceJacobians::dF_dq, D.nv, D.nq, [](auto& o) {
      return P{o.nv, o.nq};
    });
    J0.dF_dv = jac(&ForceJacobians::dF_dv, D.nv, D.nv, [](auto& o) {
      return P{o.nv, o.nv};
    });
    J0.dF_dz = jac(&ForceJacobians::dF_dz, D.nv, D.nz, [](auto& o) {
      return P{o.nv, o.nz};
    });
    J0.dfz_dq = jac(&ForceJacobians::dfz_dq, D.nz, D.nq, [](auto& o) {
      return P{o.nz, o.nq};
    });
    J0.dfz_dv = jac(&ForceJacobians::dfz_dv, D.nz, D.nv, [](auto& o) {
      return P{o.nz, o.nv};
    });
    J0.dfz_dz = jac(&ForceJacobians::dfz_dz, D.nz, D.nz, [](auto& o) {
      return P{o.nz, o.nz};
    });
    // The attachments' blocks: every pair of the dofs their two points move
    // with (fixed per attachment: taken at the initial state).
    std::vector<std::vector<int>> attachment_rows(attachments_.size()),
        attachment_cols(attachments_.size());
    if (!attachments_.empty()) {
      const State x0 = initial_state();
      const Dimensions& D0 = dims_;
      const Eigen::VectorXd q0 = x0.x.head(D0.nq), v0 = x0.x.segment(D0.nq, D0.nv);
      PatternBuilder bq(D0.nv, D0.nq), bv(D0.nv, D0.nv);
      bq.add_pattern(J0.dF_dq);
      bv.add_pattern(J0.dF_dv);
      PointKinematics point_a, point_b;
      for (int k = 0; k < static_cast<int>(attachments_.size()); ++k) {
        attachment_points(k, 0.0, q0, v0, &point_a, &point_b);
        // Rows (velocity indices) and the columns of dF/dq in the order
        // add_attachment_jacobians() walks them.
        std::vector<int>& rows = attachment_rows[k];
        std::vector<int>& cols = attachment_cols[k];
        auto comp_of = [&](const PointKinematics* pk) {
          return pk == &point_a ? attachments_[k].a.component : attachments_[k].b.component;
        };
        for (const PointKinematics* pk : {&point_a, &point_b}) {
          const Dimensions& o = offsets_[std::max(comp_of(pk), 0)];
          for (int d : pk->dofs) rows.push_back(o.nv + d);
        }
        for (const PointKinematics* pk : {&point_a, &point_b}) {
          const Dimensions& o = offsets_[std::max(comp_of(pk), 0)];
          for (int qi : pk->q_index) {
            if (qi >= 0) cols.push_back(o.nq + qi);
          }
        }
        for (const PointKinematics* pk : {&point_a, &point_b}) {
          const Dimensions& o = offsets_[std::max(comp_of(pk), 0)];
          for (const QuaternionCoordinate& qc : pk->quaternion) cols.push_back(o.nq + qc.q_index);
        }
        for (int r : rows) {
          for (int c : cols) bq.add(r, c);
          for (int m : rows) bv.add(r, m);
        }
      }
      J0.dF_dq = bq.build();
      J0.dF_dv = bv.build();
    }
    L->attachment_q.resize(attachments_.size());
    L->attachment_v.resize(attachments_.size());
    for (size_t k = 0; k < attachments_.size(); ++k) {
      for (int r : attachment_rows[k]) {
        for (int c : attachment_cols[k]) L->attachment_q[k].push_back(slot_of(J0.dF_dq, r, c));
        for (int m : attachment_rows[k]) L->attachment_v[k].push_back(slot_of(J0.dF_dv, r, m));
      }
    }
    for (size_t i = 0; i < comps.size(); ++i) {
      const System& c = *comps[i];
      const Dimensions& o = offsets_[i];
      Slots s;
      s.M = slots_in(L->mass, c.mass_matrix_pattern(), o.nv, o.nv);
      const ForceJacobians& J = c.jacobian_pattern();
      s.dF_dq = slots_in(J0.dF_dq, J.dF_dq, o.nv, o.nq);
      s.dF_dv = slots_in(J0.dF_dv, J.dF_dv, o.nv, o.nv);
      s.dF_dz = slots_in(J0.dF_dz, J.dF_dz, o.nv, o.nz);
      s.dfz_dq = slots_in(J0.dfz_dq, J.dfz_dq, o.nz, o.nq);
      s.dfz_dv = slots_in(J0.dfz_dv, J.dfz_dv, o.nz, o.nv);
      s.dfz_dz = slots_in(J0.dfz_dz, J.dfz_dz, o.nz, o.nz);
      L->slots.push_back(std::move(s));
    }
    patterns_ = std::move(L);
  });
  return *patterns_;
}

State Scene::initial_state() const {
  State s(0.0, Eigen::VectorXd::Zero(dims_.nx()));
  for (size_t i = 0; i < components_.size(); ++i) {
    const Dimensions d = components_[i]->dimensions();
    const Dimensions& o = offsets_[i];
    const State c = components_[i]->initial_state();
    s.x.segment(o.nq, d.nq) = c.q(d);
    s.x.segment(dims_.nq + o.nv, d.nv) = c.v(d);
    s.x.segment(dims_.nq + dims_.nv + o.nz, d.nz) = c.z(d);
  }
  return s;
}

namespace {
std::vector<std::string> concat(const std::vector<std::unique_ptr<System>>& comps,
                                std::vector<std::string> (System::*names)() const) {
  std::vector<std::string> all;
  for (const auto& c : comps) {
    auto n = ((*c).*names)();
    all.insert(all.end(), n.begin(), n.end());
  }
  return all;
}
}  // namespace

std::vector<std::string> Scene::position_names() const {
  return concat(components_, &System::position_names);
}
std::vector<std::string> Scene::velocity_names() const {
  return concat(components_, &System::velocity_names);
}
std::vector<std::string> Scene::misc_names() const {
  return concat(components_, &System::misc_names);
}

void Scene::map_velocity_to_qdot(const ConstVectorRef& q, const ConstVectorRef& v,
                                 VectorRef qdot) const {
  if (caps_.identity_velocity_map) {
    qdot = v;
    return;
  }
  for (size_t i = 0; i < components_.size(); ++i) {
    const Dimensions d = components_[i]->dimensions();
    const Dimensions& o = offsets_[i];
    components_[i]->map_velocity_to_qdot(q.segment(o.nq, d.nq), v.segment(o.nv, d.nv),
                                         qdot.segment(o.nq, d.nq));
  }
}

void Scene::velocity_map(SystemData& data, const ConstVectorRef& q, SparseMatrix* N) const {
  if (caps_.identity_velocity_map) return System::velocity_map(data, q, N);
  Data& d = own(data);
  set_zero_keep_pattern(N);
  for (size_t i = 0; i < components_.size(); ++i) {
    const System& c = *components_[i];
    const Dimensions n = c.dimensions();
    const Dimensions& o = offsets_[i];
    if (c.capabilities().identity_velocity_map) {
      for (int k = 0; k < n.nv; ++k) N->coeffRef(o.nq + k, o.nv + k) = 1.0;
    } else {
      c.velocity_map(*d.components[i], q.segment(o.nq, n.nq), &d.N[i]);
      scatter_add(d.N[i], slots_N_[i], 1.0, N);
    }
  }
}

bool Scene::project_positions(VectorRef q) const {
  if (!caps_.has_quaternions) return false;
  bool changed = false;
  for (size_t i = 0; i < components_.size(); ++i) {
    const Dimensions d = components_[i]->dimensions();
    changed |= components_[i]->project_positions(q.segment(offsets_[i].nq, d.nq));
  }
  return changed;
}

void Scene::mass_matrix(SystemData& data, const ConstVectorRef& q, SparseMatrix* M) const {
  Data& d = own(data);
  if (components_.size() == 1) return components_[0]->mass_matrix(*d.components[0], q, M);
  const Patterns& L = patterns();
  if (d.M.empty()) {
    for (const auto& c : components_) d.M.push_back(c->mass_matrix_pattern());
  }
  set_zero_keep_pattern(M);
  for (size_t i = 0; i < components_.size(); ++i) {
    const Dimensions n = components_[i]->dimensions();
    components_[i]->mass_matrix(*d.components[i], q.segment(offsets_[i].nq, n.nq), &d.M[i]);
    scatter_add(d.M[i], L.slots[i].M, 1.0, M);
  }
}

void Scene::forces(SystemData& data, double t, const ConstVectorRef& q, const ConstVectorRef& v,
                   const ConstVectorRef& z, VectorRef F) const {
  Data& d = own(data);
  for (size_t i = 0; i < components_.size(); ++i) {
    const Dimensions n = components_[i]->dimensions();
    const Dimensions& o = offsets_[i];
    components_[i]->forces(*d.components[i], t, q.segment(o.nq, n.nq), v.segment(o.nv, n.nv),
                           z.segment(o.nz, n.nz), F.segment(o.nv, n.nv));
  }
  if (!attachments_.empty()) add_attachment_forces(d, t, q, v, 1.0, F);
}

void Scene::momentum_residual(SystemData& data, double t, const ConstVectorRef& q,
                              const ConstVectorRef& v, const ConstVectorRef& z,
                              const ConstVectorRef& dv, double h, VectorRef r) const {
  Data& d = own(data);
  for (size_t i = 0; i < components_.size(); ++i) {
    const Dimensions n = components_[i]->dimensions();
    const Dimensions& o = offsets_[i];
    components_[i]->momentum_residual(*d.components[i], t, q.segment(o.nq, n.nq),
                                      v.segment(o.nv, n.nv), z.segment(o.nz, n.nz),
                                      dv.segment(o.nv, n.nv), h, r.segment(o.nv, n.nv));
  }
  if (attachments_.empty()) return;
  // r = M dv - h F: the attachments' forces enter with -h.
  add_attachment_forces(d, t, q, v, -h, r);
}

std::unique_ptr<StructuredNewtonMatrix> Scene::make_structured_newton_matrix() const {
  if (components_.size() != 1 || !attachments_.empty()) return nullptr;
  return components_[0]->make_structured_newton_matrix();
}

void Scene::misc_derivatives(SystemData& data, double t, const ConstVectorRef& q,
                             const ConstVectorRef& v, const ConstVectorRef& z,
                             VectorRef zdot) const {
  if (dims_.nz == 0) return;
  Data& d = own(data);
  for (size_t i = 0; i < components_.size(); ++i) {
    const Dimensions n = components_[i]->dimensions();
    const Dimensions& o = offsets_[i];
    components_[i]->misc_derivatives(*d.components[i], t, q.segment(o.nq, n.nq),
                                     v.segment(o.nv, n.nv), z.segment(o.nz, n.nz),
                                     zdot.segment(o.nz, n.nz));
  }
}

void Scene::force_jacobians(SystemData& data, double t, const ConstVectorRef& q,
                            const ConstVectorRef& v, const ConstVectorRef& z,
                            const JacobianRequest& request, ForceJacobians* J) const {
  Data& d = own(data);
  gather_jacobians(d, t, q, v, z, request, J, &System::force_jacobians);
  if (!attachments_.empty()) add_attachment_jacobians(d, t, q, v, request.complete, J);
}

void Scene::automatic_force_jacobians(SystemData& data, double t, const ConstVectorRef& q,
                                      const ConstVectorRef& v, const ConstVectorRef& z,
                                      const JacobianRequest& request, ForceJacobians* J) const {
  Data& d = own(data);
  gather_jacobians(d, t, q, v, z, request, J, &System::automatic_force_jacobians);
  if (!attachments_.empty()) add_attachment_jacobians(d, t, q, v, true, J);
}

void Scene::gather_jacobians(Data& data, double t, const ConstVectorRef& q, const ConstVectorRef& v,
                             const ConstVectorRef& z, const JacobianRequest& request,
                             ForceJacobians* J, JacobianMethod method) const {
  if (components_.size() == 1 && attachments_.empty()) {
    return ((*components_[0]).*method)(*data.components[0], t, q, v, z, request, J);
  }
  for (SparseMatrix* m : {&J->dF_dq, &J->dF_dv, &J->dF_dz, &J->dfz_dq, &J->dfz_dv, &J->dfz_dz}) {
    set_zero_keep_pattern(m);
  }
  J->approximated_terms = 0;
  const Patterns& L = patterns();
  if (data.J.empty()) {
    for (const auto& c : components_) data.J.push_back(c->jacobian_pattern());
  }
  for (size_t i = 0; i < components_.size(); ++i) {
    const Dimensions d = components_[i]->dimensions();
    const Dimensions& o = offsets_[i];
    ForceJacobians& c = data.J[i];
    JacobianRequest own = request;
    if (request.acceleration) own.acceleration = request.acceleration + o.nv;
    ((*components_[i]).*method)(*data.components[i], t, q.segment(o.nq, d.nq),
                                v.segment(o.nv, d.nv), z.segment(o.nz, d.nz), own, &c);
    const Slots& s = L.slots[i];
    scatter_add(c.dF_dq, s.dF_dq, 1.0, &J->dF_dq);
    scatter_add(c.dF_dv, s.dF_dv, 1.0, &J->dF_dv);
    scatter_add(c.dF_dz, s.dF_dz, 1.0, &J->dF_dz);
    scatter_add(c.dfz_dq, s.dfz_dq, 1.0, &J->dfz_dq);
    scatter_add(c.dfz_dv, s.dfz_dv, 1.0, &J->dfz_dv);
    scatter_add(c.dfz_dz, s.dfz_dz, 1.0, &J->dfz_dz);
    J->approximated_terms += c.approximated_terms;
  }
}

std::vector<int> Scene::jacobian_colouring_hint() const {
  // Attachments couple rows the components' colourings may share.
  if (!attachments_.empty()) return {};
  if (components_.size() == 1) return components_[0]->jacobian_colouring_hint();
  std::vector<int> colour(dims_.nx(), -1);
  for (size_t i = 0; i < components_.size(); ++i) {
    const std::vector<int> part = components_[i]->jacobian_colouring_hint();
    const Dimensions d = components_[i]->dimensions();
    if (static_cast<int>(part.size()) != d.nx()) return {};
    const Dimensions& o = offsets_[i];
    for (int k = 0; k < d.nq; ++k) colour[o.nq + k] = part[k];
    for (int k = 0; k < d.nv; ++k) colour[dims_.nq + o.nv + k] = part[d.nq + k];
    for (int k = 0; k < d.nz; ++k) colour[dims_.nq + dims_.nv + o.nz + k] = part[d.nq + d.nv + k];
  }
  return colour;
}

std::vector<std::array<int, 2>> Scene::covered_couplings() const {
  std::vector<std::array<int, 2>> pairs;
  if (!attachments_.empty()) return pairs;
  for (size_t i = 0; i < components_.size(); ++i) {
    const int offset = offsets_[i].nv;
    for (const auto& [a, b] : components_[i]->covered_couplings()) {
      pairs.push_back({a + offset, b + offset});
    }
  }
  return pairs;
}

double Scene::energy(SystemData& data, const State& s) const {
  if (!caps_.has_energy) return std::nan("");
  Data& d = own(data);
  double e = 0.0;
  if (components_.size() == 1) {
    // One component's state is the scene's: no copy.
    e = components_[0]->energy(*d.components[0], s);
  } else {
    // Energy is evaluated once or twice per step (the energy guard, the
    // incremental potential): the components' states are the data's.
    for (size_t i = 0; i < components_.size(); ++i) {
      const Dimensions n = components_[i]->dimensions();
      const Dimensions& o = offsets_[i];
      State& c = d.component_states[i];
      c.t = s.t;
      c.x.segment(0, n.nq) = s.x.segment(o.nq, n.nq);
      c.x.segment(n.nq, n.nv) = s.x.segment(dims_.nq + o.nv, n.nv);
      c.x.segment(n.nq + n.nv, n.nz) = s.x.segment(dims_.nq + dims_.nv + o.nz, n.nz);
      e += components_[i]->energy(*d.components[i], c);
    }
  }
  if (!attachments_.empty()) {
    const ConstVectorRef q = s.x.head(dims_.nq), v = s.x.segment(dims_.nq, dims_.nv);
    for (int k = 0; k < static_cast<int>(attachments_.size()); ++k) {
      attachment_points(k, s.t, q, v, &d.point_a, &d.point_b);
      e += 0.5 * attachments_[k].k * (d.point_b.p - d.point_a.p).squaredNorm();
    }
  }
  return e;
}

}  // namespace stiffsim
