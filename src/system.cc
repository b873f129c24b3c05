#include "stiffsim/system.h"

#include <stdexcept>

#include "stiffsim/structured_newton_matrix.h"

namespace stiffsim {

std::unique_ptr<SystemData> System::make_data() const { return std::make_unique<SystemData>(); }

void System::map_velocity_to_qdot(const ConstVectorRef& q, const ConstVectorRef& v,
                                  VectorRef qdot) const {
  (void)q;
  qdot = v;
}

const SparseMatrix& System::velocity_map_pattern() const {
  throw std::logic_error(name() +
                         ": velocity_map_pattern() is only defined for systems with N(q) != I; "
                         "check capabilities().identity_velocity_map first");
}

void System::velocity_map(SystemData&, const ConstVectorRef& q, SparseMatrix* N) const {
  (void)q, (void)N;
  throw std::logic_error(name() +
                         ": velocity_map() is only defined for systems with N(q) != I; "
                         "check capabilities().identity_velocity_map first");
}

void System::force_jacobians(SystemData&, double t, const ConstVectorRef& q,
                             const ConstVectorRef& v, const ConstVectorRef& z,
                             const JacobianRequest& request, ForceJacobians* J) const {
  (void)t, (void)q, (void)v, (void)z, (void)request, (void)J;
  throw std::logic_error(name() +
                         ": no analytic Jacobians; use a finite-difference scheme (forward or "
                         "central) or automatic");
}

void System::momentum_residual(SystemData&, double t, const ConstVectorRef& q,
                               const ConstVectorRef& v, const ConstVectorRef& z,
                               const ConstVectorRef& dv, double h, VectorRef r) const {
  (void)t, (void)q, (void)v, (void)z, (void)dv, (void)h, (void)r;
  throw std::logic_error(name() + ": momentum_residual() is not implemented; check "
                                  "capabilities().momentum_residual first");
}

std::unique_ptr<StructuredNewtonMatrix> System::make_structured_newton_matrix() const {
  return nullptr;
}

void System::point_kinematics(double, int, const Eigen::Vector3d&, const ConstVectorRef&,
                              const ConstVectorRef&, PointKinematics*) const {
  throw std::logic_error(name() + ": has no points that attachments can act on");
}

void System::automatic_force_jacobians(SystemData&, double t, const ConstVectorRef& q,
                                       const ConstVectorRef& v, const ConstVectorRef& z,
                                       const JacobianRequest& request, ForceJacobians* J) const {
  (void)t, (void)q, (void)v, (void)z, (void)request, (void)J;
  throw std::logic_error(name() +
                         ": no automatic-differentiation Jacobians; use analytic (if available), "
                         "forward or central");
}

ForceJacobians empty_jacobians(const Dimensions& d) {
  ForceJacobians J;
  J.dF_dq.resize(d.nv, d.nq);
  J.dF_dv.resize(d.nv, d.nv);
  J.dF_dz.resize(d.nv, d.nz);
  J.dfz_dq.resize(d.nz, d.nq);
  J.dfz_dv.resize(d.nz, d.nv);
  J.dfz_dz.resize(d.nz, d.nz);
  for (SparseMatrix* m : {&J.dF_dq, &J.dF_dv, &J.dF_dz, &J.dfz_dq, &J.dfz_dv, &J.dfz_dz}) {
    m->makeCompressed();
  }
  return J;
}

}  // namespace stiffsim
