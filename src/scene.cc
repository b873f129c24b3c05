#include "stiffsim/scene.h"

#include <cmath>
#include <functional>
#include <stdexcept>

#include "stiffsim/error.h"
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
  PatternBuilder b(rows, cols);
  for (size_t i = 0; i < comps.size(); ++i) {
    auto [r0, c0] = at(offsets[i]);
    b.add_pattern(get(*comps[i]), r0, c0);
  }
  return b.build();
}

}  // namespace

Scene::Scene(std::string name, std::vector<std::unique_ptr<System>> components)
    : name_(std::move(name)), components_(std::move(components)) {
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
    scratch_N_.push_back(own_N ? c.velocity_map_pattern() : SparseMatrix());
  }
}

Scene::Patterns& Scene::patterns() const {
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
      L->scratch_M.push_back(c.mass_matrix_pattern());
      L->scratch_J.push_back(J);
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

void Scene::velocity_map(const ConstVectorRef& q, SparseMatrix* N) const {
  if (caps_.identity_velocity_map) return System::velocity_map(q, N);
  set_zero_keep_pattern(N);
  for (size_t i = 0; i < components_.size(); ++i) {
    const System& c = *components_[i];
    const Dimensions d = c.dimensions();
    const Dimensions& o = offsets_[i];
    if (c.capabilities().identity_velocity_map) {
      for (int k = 0; k < d.nv; ++k) N->coeffRef(o.nq + k, o.nv + k) = 1.0;
    } else {
      c.velocity_map(q.segment(o.nq, d.nq), &scratch_N_[i]);
      scatter_add(scratch_N_[i], slots_N_[i], 1.0, N);
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

void Scene::mass_matrix(const ConstVectorRef& q, SparseMatrix* M) const {
  if (components_.size() == 1) return components_[0]->mass_matrix(q, M);
  Patterns& L = patterns();
  set_zero_keep_pattern(M);
  for (size_t i = 0; i < components_.size(); ++i) {
    const Dimensions d = components_[i]->dimensions();
    components_[i]->mass_matrix(q.segment(offsets_[i].nq, d.nq), &L.scratch_M[i]);
    scatter_add(L.scratch_M[i], L.slots[i].M, 1.0, M);
  }
}

void Scene::forces(double t, const ConstVectorRef& q, const ConstVectorRef& v,
                   const ConstVectorRef& z, VectorRef F) const {
  for (size_t i = 0; i < components_.size(); ++i) {
    const Dimensions d = components_[i]->dimensions();
    const Dimensions& o = offsets_[i];
    components_[i]->forces(t, q.segment(o.nq, d.nq), v.segment(o.nv, d.nv), z.segment(o.nz, d.nz),
                           F.segment(o.nv, d.nv));
  }
}

void Scene::momentum_residual(double t, const ConstVectorRef& q, const ConstVectorRef& v,
                              const ConstVectorRef& z, const ConstVectorRef& dv, double h,
                              VectorRef r) const {
  for (size_t i = 0; i < components_.size(); ++i) {
    const Dimensions d = components_[i]->dimensions();
    const Dimensions& o = offsets_[i];
    components_[i]->momentum_residual(t, q.segment(o.nq, d.nq), v.segment(o.nv, d.nv),
                                      z.segment(o.nz, d.nz), dv.segment(o.nv, d.nv), h,
                                      r.segment(o.nv, d.nv));
  }
}

std::unique_ptr<StructuredNewtonMatrix> Scene::make_structured_newton_matrix() const {
  if (components_.size() != 1) return nullptr;
  return components_[0]->make_structured_newton_matrix();
}

void Scene::misc_derivatives(double t, const ConstVectorRef& q, const ConstVectorRef& v,
                             const ConstVectorRef& z, VectorRef zdot) const {
  if (dims_.nz == 0) return;
  for (size_t i = 0; i < components_.size(); ++i) {
    const Dimensions d = components_[i]->dimensions();
    const Dimensions& o = offsets_[i];
    components_[i]->misc_derivatives(t, q.segment(o.nq, d.nq), v.segment(o.nv, d.nv),
                                     z.segment(o.nz, d.nz), zdot.segment(o.nz, d.nz));
  }
}

void Scene::force_jacobians(double t, const ConstVectorRef& q, const ConstVectorRef& v,
                            const ConstVectorRef& z, const JacobianRequest& request,
                            ForceJacobians* J) const {
  gather_jacobians(t, q, v, z, request, J, &System::force_jacobians);
}

void Scene::automatic_force_jacobians(double t, const ConstVectorRef& q, const ConstVectorRef& v,
                                      const ConstVectorRef& z, const JacobianRequest& request,
                                      ForceJacobians* J) const {
  gather_jacobians(t, q, v, z, request, J, &System::automatic_force_jacobians);
}

void Scene::gather_jacobians(double t, const ConstVectorRef& q, const ConstVectorRef& v,
                             const ConstVectorRef& z, const JacobianRequest& request,
                             ForceJacobians* J, JacobianMethod method) const {
  if (components_.size() == 1) {
    return ((*components_[0]).*method)(t, q, v, z, request, J);
  }
  for (SparseMatrix* m : {&J->dF_dq, &J->dF_dv, &J->dF_dz, &J->dfz_dq, &J->dfz_dv, &J->dfz_dz}) {
    set_zero_keep_pattern(m);
  }
  J->approximated_terms = 0;
  Patterns& L = patterns();
  for (size_t i = 0; i < components_.size(); ++i) {
    const Dimensions d = components_[i]->dimensions();
    const Dimensions& o = offsets_[i];
    ForceJacobians& c = L.scratch_J[i];
    JacobianRequest own = request;
    if (request.acceleration) own.acceleration = request.acceleration + o.nv;
    ((*components_[i]).*method)(t, q.segment(o.nq, d.nq), v.segment(o.nv, d.nv),
                                z.segment(o.nz, d.nz), own, &c);
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

double Scene::energy(const State& s) const {
  if (!caps_.has_energy) return std::nan("");
  double e = 0.0;
  for (size_t i = 0; i < components_.size(); ++i) {
    const Dimensions d = components_[i]->dimensions();
    const Dimensions& o = offsets_[i];
    State c(s.t, Eigen::VectorXd(d.nx()));
    c.x.segment(0, d.nq) = s.x.segment(o.nq, d.nq);
    c.x.segment(d.nq, d.nv) = s.x.segment(dims_.nq + o.nv, d.nv);
    c.x.segment(d.nq + d.nv, d.nz) = s.x.segment(dims_.nq + dims_.nv + o.nz, d.nz);
    e += components_[i]->energy(c);
  }
  return e;
}

}  // namespace stiffsim
