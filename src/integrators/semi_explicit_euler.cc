#include "stiffsim/integrators/semi_explicit_euler.h"

#include "stiffsim/error.h"

namespace stiffsim {
namespace {

IntegratorSettings checked(IntegratorSettings settings) {
  if (!settings.fixed_step || settings.error_estimate) {
    throw InputError(
        "semi-explicit-euler has no error estimate: use fixed_step without error_estimate, or "
        "rk3/rk45");
  }
  return settings;
}

}  // namespace

SemiExplicitEuler::SemiExplicitEuler(const System& system, IntegratorSettings settings)
    : IntegratorBase(system, checked(settings)) {}

void SemiExplicitEuler::do_initialize() {
  F_.resize(dims_.nv);
  zdot_.resize(dims_.nz);
  vdot_.resize(dims_.nv);
  qdot_.resize(dims_.nq);
}

bool SemiExplicitEuler::do_step(double h) {
  const int nq = dims_.nq, nv = dims_.nv, nz = dims_.nz;
  const Eigen::VectorXd& x = state_.x;
  const auto q = x.segment(0, nq);
  evaluate_forces(state_.t, x, &F_, &zdot_);
  solve_mass_matrix(state_.t, q, F_, &vdot_);
  auto v_new = candidate_.segment(nq, nv);
  v_new = x.segment(nq, nv) + h * vdot_;
  candidate_.segment(nq + nv, nz) = x.segment(nq + nv, nz) + h * zdot_;
  if (caps_.identity_velocity_map) {
    candidate_.segment(0, nq) = q + h * v_new;
  } else {
    // N at the step start: the update stays explicit.
    system_.map_velocity_to_qdot(q, v_new, qdot_);
    ++stats_.velocity_map_evaluations;
    candidate_.segment(0, nq) = q + h * qdot_;
  }
  if (caps_.has_quaternions) system_.project_positions(candidate_.segment(0, nq));
  return true;
}

}  // namespace stiffsim
