#include "stiffsim/model/articulated_body_solver.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace stiffsim {

ArticulatedBodySolver::ArticulatedBodySolver(const ArticulatedModel& model,
                                             std::vector<double> stiffness,
                                             std::vector<double> damping)
    : model_(model),
      stiffness_(std::move(stiffness)),
      damping_(std::move(damping)),
      X_(model.bodies()),
      IA_(model.bodies()),
      S_(model.bodies()),
      U_(model.bodies()),
      UD_(model.bodies()),
      Dinv_(model.bodies()),
      p_(model.bodies()),
      a_(model.bodies()),
      u_(model.bodies()) {
  // Every block has a fixed capacity (6): nothing is allocated per call.
  for (int i = 0; i < model.bodies(); ++i) {
    const int n = joint_nv(model.tree.bodies[i].type);
    Dinv_[i].setZero(n, n);
    u_[i].setZero(n);
  }
  llt_.compute(Block::Identity(6, 6));
}

bool ArticulatedBodySolver::factor(const ConstVectorRef& q, double h) {
  const int nb = model_.bodies();
  for (int i = 0; i < nb; ++i) {
    const TreeBody& b = model_.tree.bodies[i];
    const JointMotion<double> jm =
        body_joint_motion<double>(model_, i, q.segment(model_.q_offset[i], joint_nq(b.type)));
    S_[i] = jm.S;
    X_[i] = motion_transform_matrix(jm.pose);
    IA_[i] = model_.inertia_matrix[i];
  }
  double smallest = std::numeric_limits<double>::infinity(), largest = 0.0;
  bool ok = true;
  for (int i = nb - 1; i >= 0; --i) {
    const int n = static_cast<int>(S_[i].cols());
    U_[i].noalias() = IA_[i] * S_[i];
    if (n == 1) {
      // Revolute and prismatic joints, the common case: a scalar pivot.
      const double d = S_[i].col(0).dot(U_[i].col(0)) + h * damping_[i] + h * h * stiffness_[i];
      if (!(d > 0.0)) {
        ok = false;
        continue;
      }
      smallest = std::min(smallest, d);
      largest = std::max(largest, d);
      Dinv_[i](0, 0) = 1.0 / d;
    } else {
      llt_.compute(S_[i].transpose() * U_[i]);
      if (llt_.info() != Eigen::Success) {
        ok = false;
        continue;
      }
      const auto L = llt_.matrixLLT().diagonal();
      smallest = std::min(smallest, L.minCoeff() * L.minCoeff());
      largest = std::max(largest, L.maxCoeff() * L.maxCoeff());
      Dinv_[i].setIdentity(n, n);
      llt_.solveInPlace(Dinv_[i]);
    }
    UD_[i].noalias() = U_[i] * Dinv_[i];
    const int parent = model_.tree.bodies[i].parent;
    if (parent >= 0) {
      // I^a = I^A - U D^-1 U^T, carried into the parent's frame.
      IA_[i].noalias() -= UD_[i] * U_[i].transpose();
      IA_[parent].noalias() += X_[i].transpose() * IA_[i] * X_[i];
    }
  }
  pivot_ratio_ = ok && largest > 0.0 ? smallest / largest : 0.0;
  // The pivots of an LDL^T factorization: one at the level of round-off
  // relative to the largest is a zero pivot.
  return ok && pivot_ratio_ > 1e-12;
}

void ArticulatedBodySolver::solve(const ConstVectorRef& rhs, VectorRef x) {
  const int nb = model_.bodies();
  for (int i = 0; i < nb; ++i) p_[i].setZero();
  for (int i = nb - 1; i >= 0; --i) {
    const int n = static_cast<int>(S_[i].cols());
    u_[i] = rhs.segment(model_.v_offset[i], n);
    u_[i].noalias() -= S_[i].transpose() * p_[i];
    const int parent = model_.tree.bodies[i].parent;
    if (parent >= 0) {
      p_[i].noalias() += UD_[i] * u_[i];
      p_[parent].noalias() += X_[i].transpose() * p_[i];
    }
  }
  for (int i = 0; i < nb; ++i) {
    const int n = static_cast<int>(S_[i].cols());
    const int parent = model_.tree.bodies[i].parent;
    if (parent >= 0) {
      a_[i].noalias() = X_[i] * a_[parent];
    } else {
      a_[i].setZero();
    }
    u_[i].noalias() -= U_[i].transpose() * a_[i];
    auto xi = x.segment(model_.v_offset[i], n);
    xi.noalias() = Dinv_[i] * u_[i];
    a_[i].noalias() += S_[i] * xi;
  }
}

}  // namespace stiffsim
