#include "stiffsim/integrators/velocity_implicit_euler.h"

#include <cmath>

#include "stiffsim/error.h"
#include "stiffsim/integrators/wall_clock.h"

namespace stiffsim {
namespace {

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
  jacobian_step_t_ = jacobian_step_h_ = std::numeric_limits<double>::quiet_NaN();
  for (Eigen::VectorXd* v : {&x_big_, &x_half_, &x_small_, &guess_, &dx_}) v->resize(d.nx());
  for (Eigen::VectorXd* v : {&r_, &dy_, &r_trial_}) v->resize(d.ny());
  x_trial_.resize(d.nx());
  energy_state_.x = Eigen::VectorXd::Zero(d.nx());
  guard_energy_ = implicit_.energy_guard && caps_.has_energy && caps_.passive;
  // G is a valid merit where the residual is its gradient: the mass-matrix
  // form of a passive scene with energy, analytic Jacobians, N = I, a
  // constant diagonal M and no z states.
  use_potential_merit_ = implicit_.newton_form == NewtonForm::kMassMatrix && caps_.has_energy &&
                         caps_.passive && caps_.analytic_jacobians && caps_.identity_velocity_map &&
                         caps_.diagonal_mass_matrix && caps_.constant_mass_matrix && d.nz == 0;
  dv_.resize(d.nv);
  if (use_potential_merit_) {
    merit_jacobians_ = system_.jacobian_pattern();
    Dv_.resize(d.nv);
    g_scale_ = 0.0;
  }
  qdot_.resize(d.nq);
  q_prev_.resize(d.nq);
  F_.resize(d.nv);
  zdot_.resize(d.nz);
}

bool VelocityImplicitEuler::form_and_factor(double h) {
  const auto start = WallClock::now();
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
  jacobian_step_t_ = t;
  jacobian_step_h_ = h;
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

VelocityImplicitEuler::Refresh VelocityImplicitEuler::refresh_matrices(double t,
                                                                       const Eigen::VectorXd& x,
                                                                       double h, int trial) {
  // The reuse ladder (DESIGN.md section 2, Drake's MaybeFreshenVelocityMatrices),
  // without its two no-ops: refactoring the last Jacobian at the h it was
  // factored with, and recomputing a Jacobian already evaluated for this very
  // step start and h, reproduce the matrix that just failed.
  const bool fresh = jacobian_step_t_ == t && jacobian_step_h_ == h;
  if (!reuse_enabled() || !jacobians_valid_) {
    compute_jacobian_and_factor(t, x, h);
    return Refresh::kProceed;
  }
  if (!iteration_matrix_factored() && trial == 1) {
    form_and_factor(h);
    return Refresh::kProceed;
  }
  switch (trial) {
    case 1:  // reuse the last factorization as is, even from another h
      return Refresh::kProceed;
    case 2:  // refactor with the current h from the last Jacobian
      if (factored_h_ != h) {
        form_and_factor(h);
        return Refresh::kProceed;
      }
      [[fallthrough]];
    case 3:  // fresh Jacobian, refactor
      if (fresh) return Refresh::kSkip;
      compute_jacobian_and_factor(t, x, h);
      return Refresh::kProceed;
    default:  // give up: the caller shrinks h
      return Refresh::kGiveUp;
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
  if (implicit_.newton_form == NewtonForm::kMassMatrix && caps_.diagonal_mass_matrix) {
    const double* m = M.valuePtr();
    for (int i = 0; i < d.nv; ++i) (*r)[i] = m[i] * (v[i] - v0[i]) - h * F_[i];
  } else if (implicit_.newton_form == NewtonForm::kMassMatrix) {
    dv_ = v - v0;  // a named workspace: the sparse product would allocate a temporary
    r->segment(0, d.nv).noalias() = M * dv_;
    r->segment(0, d.nv) -= h * F_;
  } else {
    const double* m = M.valuePtr();
    for (int i = 0; i < d.nv; ++i) (*r)[i] = v[i] - v0[i] - h * F_[i] / m[i];
  }
  r->segment(d.nv, d.nz) = x.segment(d.nq + d.nv, d.nz) - x0.segment(d.nq + d.nv, d.nz) - h * zdot_;
}

void VelocityImplicitEuler::advance_positions(double h, const Eigen::VectorXd& x0,
                                              Eigen::VectorXd* x) {
  // q_{k+1} = q_n + h N(q_k) v_{k+1}: N lagged one iterate.
  const Dimensions& d = dims_;
  if (caps_.identity_velocity_map) {
    x->segment(0, d.nq) = x0.segment(0, d.nq) + h * x->segment(d.nq, d.nv);
  } else {
    system_.map_velocity_to_qdot(x->segment(0, d.nq), x->segment(d.nq, d.nv), qdot_);
    ++stats_.velocity_map_evaluations;
    x->segment(0, d.nq) = x0.segment(0, d.nq) + h * qdot_;
  }
}

double VelocityImplicitEuler::merit(const Eigen::VectorXd& r) const {
  // The residual measured in velocity units (the mass-matrix form's v rows
  // are momenta), so that light and heavy nodes weigh alike.
  if (implicit_.newton_form == NewtonForm::kMassMatrix && caps_.diagonal_mass_matrix) {
    const double* m = mass_diagonal_;
    double sum = 0.0;
    for (int i = 0; i < dims_.nv; ++i) sum += (r[i] / m[i]) * (r[i] / m[i]);
    return sum + r.tail(dims_.nz).squaredNorm();
  }
  return r.squaredNorm();
}

double VelocityImplicitEuler::incremental_potential(double t, const Eigen::VectorXd& x0,
                                                    const Eigen::VectorXd& x, double h) {
  // G_k(v) = 1/2 (v - v_n)^T M (v - v_n) + Phi(q_n + h v) - h/2 v^T D_k v.
  // Damping forces are D(q) v, linear in v; with D frozen at the current
  // iterate (freezing it for a whole step lets the slope error
  // h (D(q) - D_k) v . dy stall the search near the solution) they derive
  // from the last term, so the residual at the iterate is exactly the
  // gradient of G_k and the Armijo slope r . dy is exact.
  const Dimensions& d = dims_;
  energy_state_.t = t;
  energy_state_.x.segment(0, d.nq) = x.segment(0, d.nq);
  energy_state_.x.segment(d.nq, d.nv).setZero();
  const double potential = system_.energy(energy_state_);
  const auto v = x.segment(d.nq, d.nv);
  dv_ = v - x0.segment(d.nq, d.nv);
  const double* m = mass_diagonal_;
  double inertia = 0.0;
  for (int i = 0; i < d.nv; ++i) inertia += 0.5 * m[i] * dv_[i] * dv_[i];
  Dv_.noalias() = merit_jacobians_.dF_dv * v;
  return inertia + potential - 0.5 * h * v.dot(Dv_);
}

bool VelocityImplicitEuler::newton(double t0, double h, const Eigen::VectorXd& x0,
                                   const Eigen::VectorXd& guess, int trial, Eigen::VectorXd* x) {
  const Dimensions& d = dims_;
  const double tf = t0 + h;
  *x = guess;
  advance_positions(h, x0, x);
  // The last rung before shrinking h is a full Newton iteration: a step that
  // starts where the linearization is degenerate (a flat membrane at rest has
  // no transverse stiffness) converges once the Jacobian follows the iterate.
  const bool full_newton = implicit_.full_newton || trial == kFullNewtonTrial;
  if (!full_newton) {
    if (refresh_matrices(t0, x0, h, trial) != Refresh::kProceed) return false;
    if (!iteration_matrix_factored()) return false;
  }
  ++stats_.newton_trials;
  residual(tf, h, x0, *x, &r_);
  if (use_potential_merit_) g_scale_ = std::abs(system_.energy(state_));
  mass_diagonal_ =
      caps_.diagonal_mass_matrix ? mass_matrix_at(x0.segment(0, d.nq)).valuePtr() : nullptr;
  double r_merit = merit(r_);
  q_prev_ = x->segment(0, d.nq);
  double last_norm = std::numeric_limits<double>::infinity();
  // The last rung converges (at least linearly with the definite clamp) but
  // may need more iterations than a fresh modified Newton; giving it three
  // times the budget is cheaper than halving the step.
  const int max_iterations = trial == kFullNewtonTrial ? 3 * implicit_.max_newton_iterations
                                                       : implicit_.max_newton_iterations;
  for (int i = 0; i < max_iterations; ++i) {
    if (full_newton) {
      // Linearize at the current iterate itself (positions already advanced).
      compute_jacobian(tf, *x, 0.0);
      jacobian_step_t_ = std::numeric_limits<double>::quiet_NaN();
      if (!form_and_factor(h)) return false;
    }
    ++stats_.newton_raphson_iterations;
    r_ = -r_;
    solve_iteration_matrix(r_, &dy_);
    // Line search. Where the scene has an incremental potential G (see
    // incremental_potential()), W's Newton direction descends G whatever
    // approximations W holds, so the search heads for a minimizer of G: it
    // never climbs to a saddle of G, a spurious root of the step equations
    // where buckled stiff springs gain energy. Otherwise the residual norm
    // is the merit. The full step is taken whenever it qualifies; the trial
    // residual is then the next iteration's, at no extra cost.
    // The potential costs a damping-matrix evaluation per iteration, so the
    // reuse rungs (1, 2), whose solves are the common and easy ones, use
    // the residual with the energy guard behind it; the rungs that follow a
    // failure (3, 4), where spurious roots are met, use G.
    const bool use_potential = use_potential_merit_ && trial >= 3;
    double g_current = 0.0, slope = 0.0;
    if (use_potential) {
      evaluate_damping(tf, *x);
      g_current = incremental_potential(tf, x0, *x, h);
      slope = -r_.dot(dy_);  // r_ holds minus the residual = minus grad G_k
    }
    const bool potential_search = use_potential && slope < 0.0;
    double alpha = 1.0;
    for (int backtrack = 0;; ++backtrack) {
      x_trial_ = *x;
      x_trial_.segment(d.nq, d.ny()) += alpha * dy_;
      advance_positions(h, x0, &x_trial_);
      residual(tf, h, x0, x_trial_, &r_trial_);
      const double trial_merit = merit(r_trial_);
      bool accept = std::isfinite(trial_merit);
      if (accept && potential_search) {
        const double g_trial = incremental_potential(tf, x0, x_trial_, h);
        // Near the solution G changes by less than its own round-off; there
        // a G that did not measurably rise and a smaller residual decide.
        const double roundoff = 1e-11 * (std::abs(g_current) + g_scale_);
        accept = g_trial <= g_current + 1e-4 * alpha * slope ||
                 (g_trial <= g_current + roundoff && trial_merit < r_merit);
      } else if (accept) {
        accept = trial_merit <= (1.0 - 1e-4 * alpha) * r_merit;
      }
      if (accept) {
        r_merit = trial_merit;
        break;
      }
      if (backtrack == kMaxBacktracks) return false;
      alpha *= 0.5;
      ++stats_.line_search_backtracks;
    }
    x->swap(x_trial_);
    r_.swap(r_trial_);
    dx_.segment(0, d.nq) = x->segment(0, d.nq) - q_prev_;
    dx_.segment(d.nq, d.ny()) = alpha * dy_;
    q_prev_ = x->segment(0, d.nq);
    const double norm = state_change_norm(dx_);
    if (alpha < 1.0) {
      // A damped step says nothing about the rate of the undamped iteration.
      last_norm = std::numeric_limits<double>::infinity();
      continue;
    }
    const Convergence c = check_newton_convergence(i, *x, dx_, norm, last_norm);
    if (c == Convergence::kConverged) return passes_energy_guard(x0, *x);
    if (c == Convergence::kDiverged) return false;
    last_norm = norm;
  }
  return false;
}

void VelocityImplicitEuler::evaluate_damping(double t, const Eigen::VectorXd& x) {
  const auto start = WallClock::now();
  const Dimensions& d = dims_;
  system_.force_jacobians(t, x.segment(0, d.nq), x.segment(d.nq, d.nv),
                          x.segment(d.nq + d.nv, d.nz), JacobianRequest{}, &merit_jacobians_);
  ++stats_.merit_damping_evaluations;
  stats_.jacobian_seconds += seconds_since(start);
}

bool VelocityImplicitEuler::passes_energy_guard(const Eigen::VectorXd& x0,
                                                const Eigen::VectorXd& x) {
  // For a scene whose forces are conservative or dissipative, an implicit
  // Euler step that gains energy has found a spurious root of the step
  // equations (a buckled or inverted configuration of stiff springs reached
  // at a large h): the attempt counts as a failure and the step shrinks.
  if (!guard_energy_) return true;
  energy_state_.x = x0;
  const double before = system_.energy(energy_state_);
  energy_state_.x = x;
  const double after = system_.energy(energy_state_);
  // Round-off of the energy sums and the Newton tolerance's share.
  const double allowance = 1e-8 * (std::abs(before) + std::abs(after)) + 1e-12;
  if (after <= before + allowance) return true;
  ++stats_.energy_guard_rejections;
  return false;
}

bool VelocityImplicitEuler::solve_step(double t0, double h, const Eigen::VectorXd& x0,
                                       const Eigen::VectorXd& guess, Eigen::VectorXd* x) {
  ++stats_.newton_solves;
  for (int trial = 1; trial <= kFullNewtonTrial; ++trial) {
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
