#include "stiffsim/model/robertson.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

#include "stiffsim/error.h"

namespace stiffsim {

RobertsonSystem::RobertsonSystem(double k1, double k2, double k3) : k1_(k1), k2_(k2), k3_(k3) {
  const double rates[3] = {k1, k2, k3};
  for (int i = 0; i < 3; ++i) {
    if (!std::isfinite(rates[i]) || rates[i] < 0.0) {
      std::ostringstream msg;
      msg << "robertson: rate k" << i + 1 << " must be finite and >= 0, got " << rates[i];
      throw InputError(msg.str());
    }
  }
  mass_pattern_.resize(0, 0);
  mass_pattern_.makeCompressed();
  jacobian_pattern_ = empty_jacobians(dimensions());
  PatternBuilder dense(3, 3);
  dense.add_block(0, 0, 3, 3);
  jacobian_pattern_.dfz_dz = dense.build();
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) slots_[i][j] = slot_of(jacobian_pattern_.dfz_dz, i, j);
  }
}

Capabilities RobertsonSystem::capabilities() const {
  Capabilities c;
  // No mechanics at all: the trivial facts let integrators skip N and M.
  c.identity_velocity_map = true;
  c.constant_mass_matrix = true;
  c.diagonal_mass_matrix = true;
  c.analytic_jacobians = true;
  // The kinetics Jacobian is not symmetric, and there is no energy (so no
  // passivity to guard either).
  c.symmetric_jacobians = false;
  c.passive = false;
  c.has_energy = false;
  return c;
}

State RobertsonSystem::initial_state() const { return State(0.0, Eigen::Vector3d(1.0, 0.0, 0.0)); }

void RobertsonSystem::mass_matrix(SystemData&, const ConstVectorRef& q, SparseMatrix* M) const {
  (void)q, (void)M;
}

void RobertsonSystem::forces(SystemData&, double t, const ConstVectorRef& q,
                             const ConstVectorRef& v, const ConstVectorRef& z, VectorRef F) const {
  (void)t, (void)q, (void)v, (void)z, (void)F;
}

void RobertsonSystem::misc_derivatives(SystemData&, double t, const ConstVectorRef& q,
                                       const ConstVectorRef& v, const ConstVectorRef& z,
                                       VectorRef zdot) const {
  (void)t, (void)q, (void)v;
  const double y1 = z[0], y2 = z[1], y3 = z[2];
  // Each reaction's rate is added to one species and taken from another, so
  // the three derivatives sum to zero exactly in exact arithmetic.
  const double r1 = k1_ * y1, r2 = k2_ * y2 * y2, r3 = k3_ * y2 * y3;
  zdot[0] = -r1 + r3;
  zdot[1] = r1 - r3 - r2;
  zdot[2] = r2;
}

void RobertsonSystem::force_jacobians(SystemData&, double t, const ConstVectorRef& q,
                                      const ConstVectorRef& v, const ConstVectorRef& z,
                                      const JacobianRequest& request, ForceJacobians* J) const {
  (void)t, (void)q, (void)v, (void)request;
  if (J->dfz_dz.rows() != 3 || J->dfz_dz.cols() != 3 || J->dfz_dz.nonZeros() != 9) {
    throw std::logic_error(name() + ": force_jacobians() needs matrices with jacobian_pattern()");
  }
  const double y2 = z[1], y3 = z[2];
  double* A = J->dfz_dz.valuePtr();
  A[slots_[0][0]] = -k1_;
  A[slots_[0][1]] = k3_ * y3;
  A[slots_[0][2]] = k3_ * y2;
  A[slots_[1][0]] = k1_;
  A[slots_[1][1]] = -k3_ * y3 - 2.0 * k2_ * y2;
  A[slots_[1][2]] = -k3_ * y2;
  A[slots_[2][0]] = 0.0;
  A[slots_[2][1]] = 2.0 * k2_ * y2;
  A[slots_[2][2]] = 0.0;
  J->approximated_terms = 0;
}

}  // namespace stiffsim
