#include "stiffsim/integrators/velocity_implicit_euler.h"

#include <chrono>

#include "stiffsim/error.h"

namespace stiffsim {
namespace {
using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// Structural product A * B (pattern only), so the pattern of K N(q) is known
// before any value is.
SparseMatrix product_pattern(const SparseMatrix& A, const SparseMatrix& B) {
  SparseMatrix a = A, b = B;
  for (SparseMatrix* m : {&a, &b}) std::fill(m->valuePtr(), m->valuePtr() + m->nonZeros(), 1.0);
  SparseMatrix p = a * b;
  p.makeCompressed();
  return p;
}

// whole[slots[k]] += scale * part[k] / d[row(k)]: the generic form's rows of
// M^-1 times a Jacobian block, for a diagonal M.
void scatter_add_row_scaled(const SparseMatrix& part, const std::vector<int>& slots, double scale,
                            const double* diagonal, SparseMatrix* whole) {
  const int* rows = part.innerIndexPtr();
  const double* values = part.valuePtr();
  double* out = whole->valuePtr();
  for (Eigen::Index k = 0; k < part.nonZeros(); ++k) {
    out[slots[k]] += scale * values[k] / diagonal[rows[k]];
  }
}
}  // namespace

VelocityImplicitEuler::VelocityImplicitEuler(const System& system, IntegratorSettings settings,
                                             ImplicitSettings implicit)
    : ImplicitIntegrator(system, settings, implicit) {
  if (implicit_.newton_form == NewtonForm::kGeneric && !caps_.diagonal_mass_matrix) {
    throw InputError(
        "the generic Newton form (I - h J_l) is only available for diagonal mass matrices, "
        "where M^-1 keeps the sparsity; use the mass-matrix form");
  }
}

void VelocityImplicitEuler::do_initialize() {
  const Dimensions& d = dims_;
  const ForceJacobians& J = jacobians_;
  const bool identity_N = caps_.identity_velocity_map;
  if (!identity_N) {
    N_ = system_.velocity_map_pattern();
    KN_ = product_pattern(J.dF_dq, N_);
    ZqN_ = product_pattern(J.dfz_dq, N_);
  }
  const SparseMatrix& K_or_KN = identity_N ? J.dF_dq : KN_;
  const SparseMatrix& Zq_or_ZqN = identity_N ? J.dfz_dq : ZqN_;

  // One pattern for the whole Newton matrix, built once per run: the union
  // of M, D, K N and the z blocks, plus the diagonal (identity of the z rows,
  // or of everything in the generic form).
  PatternBuilder b(d.ny(), d.ny());
  b.add_pattern(system_.mass_matrix_pattern());
  b.add_pattern(J.dF_dv);
  b.add_pattern(K_or_KN);
  b.add_pattern(J.dF_dz, 0, d.nv);
  b.add_pattern(J.dfz_dv, d.nv, 0);
  b.add_pattern(Zq_or_ZqN, d.nv, 0);
  b.add_pattern(J.dfz_dz, d.nv, d.nv);
  b.add_diagonal(0, d.ny());
  iteration_matrix_ = b.build();

  slots_M_ = slots_in(iteration_matrix_, system_.mass_matrix_pattern());
  slots_D_ = slots_in(iteration_matrix_, J.dF_dv);
  slots_K_ = slots_in(iteration_matrix_, K_or_KN);
  slots_Fz_ = slots_in(iteration_matrix_, J.dF_dz, 0, d.nv);
  slots_Zv_ = slots_in(iteration_matrix_, J.dfz_dv, d.nv, 0);
  slots_Zq_ = slots_in(iteration_matrix_, Zq_or_ZqN, d.nv, 0);
  slots_Zz_ = slots_in(iteration_matrix_, J.dfz_dz, d.nv, d.nv);
  identity_slots_.resize(d.ny());
  for (int i = 0; i < d.ny(); ++i) identity_slots_[i] = slot_of(iteration_matrix_, i, i);

  jacobians_valid_ = false;
  invalidate_factorization();
  factored_h_ = 0.0;
  for (Eigen::VectorXd* v : {&x_big_, &x_half_, &x_small_, &guess_, &dx_}) v->resize(d.nx());
  for (Eigen::VectorXd* v : {&r_, &dy_}) v->resize(d.ny());
  qdot_.resize(d.nq);
  q_prev_.resize(d.nq);
  F_.resize(d.nv);
  zdot_.resize(d.nz);
}

bool VelocityImplicitEuler::form_and_factor(double h) {
  const auto start = Clock::now();
  const Dimensions& d = dims_;
  const ForceJacobians& J = jacobians_;
  SparseMatrix& W = iteration_matrix_;
  set_zero_keep_pattern(&W);
  const SparseMatrix& K = caps_.identity_velocity_map ? J.dF_dq : KN_;
  const SparseMatrix& Zq = caps_.identity_velocity_map ? J.dfz_dq : ZqN_;
  if (implicit_.newton_form == NewtonForm::kMassMatrix) {
    // W = [M - h D - h^2 K N, -h dF/dz; -h dfz/dv - h^2 dfz/dq N, I - h dfz/dz]
    scatter_add(mass_matrix_at(state_.q(d)), slots_M_, 1.0, &W);
    scatter_add(J.dF_dv, slots_D_, -h, &W);
    scatter_add(K, slots_K_, -h * h, &W);
    for (int i = d.nv; i < d.ny(); ++i) W.valuePtr()[identity_slots_[i]] += 1.0;
  } else {
    // A = I - h J_l with J_l = [M^-1 (D + h K N), M^-1 dF/dz; dfz/dv + h dfz/dq N, dfz/dz].
    const double* m = mass_matrix_at(state_.q(d)).valuePtr();
    for (int i = 0; i < d.ny(); ++i) W.valuePtr()[identity_slots_[i]] += 1.0;
    scatter_add_row_scaled(J.dF_dv, slots_D_, -h, m, &W);
    scatter_add_row_scaled(K, slots_K_, -h * h, m, &W);
    scatter_add_row_scaled(J.dF_dz, slots_Fz_, -h, m, &W);
  }
  if (implicit_.newton_form == NewtonForm::kMassMatrix) scatter_add(J.dF_dz, slots_Fz_, -h, &W);
  scatter_add(J.dfz_dv, slots_Zv_, -h, &W);
  scatter_add(Zq, slots_Zq_, -h * h, &W);
  scatter_add(J.dfz_dz, slots_Zz_, -h, &W);
  stats_.assembly_seconds += seconds_since(start);
  factored_h_ = h;
  // Symmetric (so CHOLMOD applies) for conservative particle-like systems:
  // N = I, no z coupling, symmetric K and D, and the mass-matrix form.
  const bool symmetric = implicit_.newton_form == NewtonForm::kMassMatrix &&
                         caps_.symmetric_jacobians && caps_.identity_velocity_map && d.nz == 0;
  return factor_iteration_matrix(W, symmetric);
}

void VelocityImplicitEuler::compute_jacobian_and_factor(double t, const Eigen::VectorXd& x,
                                                        double h) {
  compute_jacobian(t, x, h);
  form_and_factor(h);
}

void VelocityImplicitEuler::compute_jacobian(double t, const Eigen::VectorXd& x, double h) {
  const Dimensions& d = dims_;
  // Linearize where the step is heading: q_n + h N(q_n) v_n, as Drake does.
  guess_ = x;
  if (caps_.identity_velocity_map) {
    guess_.segment(0, d.nq) += h * x.segment(d.nq, d.nv);
  } else {
    system_.map_velocity_to_qdot(x.segment(0, d.nq), x.segment(d.nq, d.nv), qdot_);
    ++stats_.velocity_map_evaluations;
    guess_.segment(0, d.nq) += h * qdot_;
    system_.velocity_map(x.segment(0, d.nq), &N_);
    ++stats_.velocity_map_evaluations;
  }
  compute_force_jacobians(t, guess_);
  if (!caps_.identity_velocity_map) {
    // The products K N and dfz/dq N keep their (structural) pattern; their
    // slots are looked up again because Eigen may order a product freshly.
    KN_ = jacobians_.dF_dq * N_;
    ZqN_ = jacobians_.dfz_dq * N_;
    KN_.makeCompressed();
    ZqN_.makeCompressed();
    slots_K_ = slots_in(iteration_matrix_, KN_);
    slots_Zq_ = slots_in(iteration_matrix_, ZqN_, d.nv, 0);
  }
}

bool VelocityImplicitEuler::refresh_matrices(double t, const Eigen::VectorXd& x, double h,
                                             int trial) {
  // The reuse ladder (DESIGN.md section 2, Drake's MaybeFreshenVelocityMatrices).
  if (!reuse_enabled() || !jacobians_valid_) {
    compute_jacobian_and_factor(t, x, h);
    return true;
  }
  if (!iteration_matrix_factored() && trial == 1) {
    form_and_factor(h);
    return true;
  }
  switch (trial) {
    case 1:  // reuse the last factorization as is, even from another h
      return true;
    case 2:  // refactor with the current h from the last Jacobian
      form_and_factor(h);
      return true;
    case 3:  // fresh Jacobian, refactor
      compute_jacobian_and_factor(t, x, h);
      return true;
    default:  // give up: the caller shrinks h
      return false;
  }
}

void VelocityImplicitEuler::residual(double t, double h, const Eigen::VectorXd& x0,
                                     const Eigen::VectorXd& x, Eigen::VectorXd* r) {
  // The residual is exact: q = q_n + h N(q_k) v is rebuilt from the current
  // v before F is evaluated, as in Drake's l(y).
  const Dimensions& d = dims_;
  guess_ = x;
  if (caps_.identity_velocity_map) {
    guess_.segment(0, d.nq) = x0.segment(0, d.nq) + h * x.segment(d.nq, d.nv);
  } else {
    system_.map_velocity_to_qdot(x.segment(0, d.nq), x.segment(d.nq, d.nv), qdot_);
    ++stats_.velocity_map_evaluations;
    guess_.segment(0, d.nq) = x0.segment(0, d.nq) + h * qdot_;
  }
  evaluate_forces(t, guess_, &F_, &zdot_);
  const auto v = x.segment(d.nq, d.nv);
  const auto v0 = x0.segment(d.nq, d.nv);
  const SparseMatrix& M = mass_matrix_at(guess_.segment(0, d.nq));
  if (implicit_.newton_form == NewtonForm::kMassMatrix) {
    r->segment(0, d.nv).noalias() = M * (v - v0);
    r->segment(0, d.nv) -= h * F_;
  } else {
    const double* m = M.valuePtr();
    for (int i = 0; i < d.nv; ++i) (*r)[i] = v[i] - v0[i] - h * F_[i] / m[i];
  }
  r->segment(d.nv, d.nz) =
      x.segment(d.nq + d.nv, d.nz) - x0.segment(d.nq + d.nv, d.nz) - h * zdot_;
}

bool VelocityImplicitEuler::newton(double t0, double h, const Eigen::VectorXd& x0,
                                   const Eigen::VectorXd& guess, int trial, Eigen::VectorXd* x) {
  const Dimensions& d = dims_;
  const double tf = t0 + h;
  *x = guess;
  if (!implicit_.full_newton) {
    if (!refresh_matrices(t0, x0, h, trial)) return false;
    if (!iteration_matrix_factored()) return false;
  }
  q_prev_ = x->segment(0, d.nq);
  double last_norm = std::numeric_limits<double>::infinity();
  for (int i = 0; i < implicit_.max_newton_iterations; ++i) {
    if (implicit_.full_newton) {
      // Linearize at the current iterate itself (no position prediction).
      compute_jacobian(tf, *x, 0.0);
      if (!form_and_factor(h)) return false;
    }
    ++stats_.newton_raphson_iterations;
    residual(tf, h, x0, *x, &r_);
    r_ = -r_;
    solve_iteration_matrix(r_, &dy_);
    x->segment(d.nq, d.ny()) += dy_;
    // Positions with N lagged one iterate: q_{k+1} = q_n + h N(q_k) v_{k+1}.
    if (caps_.identity_velocity_map) {
      x->segment(0, d.nq) = x0.segment(0, d.nq) + h * x->segment(d.nq, d.nv);
    } else {
      system_.map_velocity_to_qdot(x->segment(0, d.nq), x->segment(d.nq, d.nv), qdot_);
      ++stats_.velocity_map_evaluations;
      x->segment(0, d.nq) = x0.segment(0, d.nq) + h * qdot_;
    }
    dx_.segment(0, d.nq) = x->segment(0, d.nq) - q_prev_;
    dx_.segment(d.nq, d.ny()) = dy_;
    q_prev_ = x->segment(0, d.nq);
    const double norm = state_change_norm(dx_);
    const Convergence c = check_newton_convergence(i, *x, dx_, norm, last_norm);
    if (c == Convergence::kConverged) return true;
    if (c == Convergence::kDiverged) return false;
    last_norm = norm;
  }
  return false;
}

bool VelocityImplicitEuler::solve_step(double t0, double h, const Eigen::VectorXd& x0,
                                       const Eigen::VectorXd& guess, Eigen::VectorXd* x) {
  ++stats_.newton_solves;
  for (int trial = 1; trial <= 4; ++trial) {
    if (newton(t0, h, x0, guess, trial, x)) {
      if (caps_.has_quaternions) system_.project_positions(x->segment(0, dims_.nq));
      return true;
    }
    if (!reuse_enabled()) return false;
  }
  return false;
}

bool VelocityImplicitEuler::do_step(double h) {
  const double t0 = state_.t;
  const Eigen::VectorXd& x0 = state_.x;
  if (!estimating_error()) return solve_step(t0, h, x0, x0, &candidate_);

  // The large step is the error estimator's share of the work (as in Drake).
  const IntegratorStatistics before = stats_;
  const bool big_ok = solve_step(t0, h, x0, x0, &x_big_);
  stats_.error_estimator_derivative_evaluations +=
      stats_.derivative_evaluations - before.derivative_evaluations;
  stats_.error_estimator_derivative_evaluations_for_jacobian +=
      stats_.derivative_evaluations_for_jacobian - before.derivative_evaluations_for_jacobian;
  stats_.error_estimator_jacobian_evaluations +=
      stats_.jacobian_evaluations - before.jacobian_evaluations;
  stats_.error_estimator_iteration_matrix_factorizations +=
      stats_.iteration_matrix_factorizations - before.iteration_matrix_factorizations;
  stats_.error_estimator_newton_raphson_iterations +=
      stats_.newton_raphson_iterations - before.newton_raphson_iterations;
  if (!big_ok) return false;

  x_half_ = 0.5 * (x0 + x_big_);
  if (!solve_step(t0, 0.5 * h, x0, x_half_, &x_small_)) return false;
  x_half_.swap(x_small_);
  if (!solve_step(t0 + 0.5 * h, 0.5 * h, x_half_, x_big_, &candidate_)) return false;
  // x_big - x_small = (h^2/4) x'' + O(h^3): the local error of the propagated
  // half-step result, to leading order.
  error_ = x_big_ - candidate_;
  return true;
}

}  // namespace stiffsim
