#include "stiffsim/integrators/implicit_integrator.h"

#include <cmath>
#include <stdexcept>

#include "stiffsim/error.h"
#include "stiffsim/integrators/wall_clock.h"

namespace stiffsim {

JacobianScheme parse_jacobian_scheme(const std::string& name) {
  if (name == "analytic") return JacobianScheme::kAnalytic;
  if (name == "forward") return JacobianScheme::kForward;
  if (name == "central") return JacobianScheme::kCentral;
  if (name == "automatic") return JacobianScheme::kAutomatic;
  throw InputError("unknown Jacobian scheme '" + name +
                   "' (expected analytic, forward, central or automatic)");
}

std::string to_string(JacobianScheme scheme) {
  switch (scheme) {
    case JacobianScheme::kAnalytic:
      return "analytic";
    case JacobianScheme::kForward:
      return "forward";
    case JacobianScheme::kCentral:
      return "central";
    case JacobianScheme::kAutomatic:
      return "automatic";
  }
  return "?";
}

NewtonForm parse_newton_form(const std::string& name) {
  if (name == "mass-matrix") return NewtonForm::kMassMatrix;
  if (name == "generic") return NewtonForm::kGeneric;
  throw InputError("unknown Newton form '" + name + "' (expected mass-matrix or generic)");
}

std::string to_string(NewtonForm form) {
  return form == NewtonForm::kMassMatrix ? "mass-matrix" : "generic";
}

ImplicitIntegrator::ImplicitIntegrator(const System& system, IntegratorSettings settings,
                                       ImplicitSettings implicit)
    : IntegratorBase(system, settings), implicit_(implicit) {
  if (implicit_.max_newton_iterations < 1) {
    throw InputError("max_newton_iterations must be at least 1");
  }
  if (!(implicit_.newton_kappa > 0.0 && implicit_.newton_kappa < 1.0)) {
    throw InputError("newton_kappa must be in (0, 1)");
  }
  if (implicit_.jacobian == JacobianScheme::kAnalytic && !caps_.analytic_jacobians) {
    throw InputError(system.name() + " has no analytic Jacobians: choose forward or central");
  }
  if (implicit_.jacobian != JacobianScheme::kAnalytic) {
    throw InputError("Jacobian scheme '" + to_string(implicit_.jacobian) +
                     "' is not available yet; use analytic");
  }
  jacobians_ = system.jacobian_pattern();
}

ImplicitIntegrator::Convergence ImplicitIntegrator::check_newton_convergence(
    int iteration, const Eigen::VectorXd& x, const Eigen::VectorXd& dx, double dx_norm,
    double last_dx_norm) {
  if (!std::isfinite(dx_norm)) return Convergence::kDiverged;
  // An update at the level of round-off has converged whatever the rate says.
  constexpr double kZeroTol = 10 * std::numeric_limits<double>::epsilon();
  bool zero = true;
  for (Eigen::Index i = 0; i < dx.size() && zero; ++i) {
    zero = std::abs(dx[i]) <= std::max(std::abs(x[i]), 1.0) * kZeroTol;
  }
  if (zero) return Convergence::kConverged;
  // Hairer & Wanner IV.8: theta = |dx_k| / |dx_{k-1}|, eta = theta / (1 - theta).
  // The first iteration has no rate. Hairer's stand-in (the previous solve's
  // eta) assumes a good predictor; ours starts from x_n, so the first update
  // is the whole step and a stale small eta would accept it unchecked.
  if (iteration == 0) return Convergence::kNotYet;
  const double theta = dx_norm / last_dx_norm;
  if (theta >= 1.0) return Convergence::kDiverged;
  const double eta = theta / (1.0 - theta);
  if (eta * dx_norm <= newton_tolerance()) return Convergence::kConverged;
  return Convergence::kNotYet;
}

void ImplicitIntegrator::compute_force_jacobians(double t, const Eigen::VectorXd& x) {
  const auto start = WallClock::now();
  JacobianRequest request;
  request.definite = implicit_.definite_iteration_matrix;
  system_.force_jacobians(t, x.segment(0, dims_.nq), x.segment(dims_.nq, dims_.nv),
                          x.segment(dims_.nq + dims_.nv, dims_.nz), request, &jacobians_);
  ++stats_.jacobian_evaluations;
  stats_.jacobian_approximated_terms += jacobians_.approximated_terms;
  stats_.jacobian_seconds += seconds_since(start);
  jacobians_valid_ = true;
}

bool ImplicitIntegrator::factor_iteration_matrix(const SparseMatrix& matrix, bool symmetric) {
  if (!solver_.solver) {
    solver_ = make_linear_solver(implicit_.linear_solver, matrix, symmetric);
    const auto start = WallClock::now();
    solver_.solver->analyze(matrix);
    stats_.factorization_seconds += seconds_since(start);
    ++stats_.symbolic_analyses;
    stats_.iteration_matrix_nonzeros = matrix.nonZeros();
  }
  const auto start = WallClock::now();
  factored_ = solver_.solver->factorize(matrix);
  stats_.factorization_seconds += seconds_since(start);
  ++stats_.iteration_matrix_factorizations;
  if (factored_) stats_.factor_nonzeros = solver_.solver->factor_nonzeros();
  return factored_;
}

void ImplicitIntegrator::solve_iteration_matrix(const Eigen::VectorXd& rhs, Eigen::VectorXd* dx) {
  const auto start = WallClock::now();
  solver_.solver->solve(rhs, dx);
  stats_.solve_seconds += seconds_since(start);
  ++stats_.linear_solves;
}

IntegratorReport ImplicitIntegrator::report() const {
  IntegratorReport r = IntegratorBase::report();
  r.jacobian_scheme = to_string(implicit_.jacobian);
  r.newton_form = to_string(implicit_.newton_form);
  if (solver_.solver) {
    r.linear_solver = solver_.solver->method();
    r.linear_solver_reason = solver_.reason;
    r.linear_solver_fallback = solver_.solver->fallback_note();
  }
  return r;
}

}  // namespace stiffsim
