#include "stiffsim/integrators/implicit_euler.h"

#include <cmath>

#include "stiffsim/error.h"
#include "stiffsim/integrators/wall_clock.h"

namespace stiffsim {
namespace {
// The trapezoid estimate's iteration matrix I - h/2 J lives beside IE's.
constexpr int kImplicitEulerMatrix = 0;
constexpr int kTrapezoidMatrix = 1;
}  // namespace

ImplicitEuler::ImplicitEuler(const System& system, IntegratorSettings settings,
                             ImplicitSettings implicit)
    : ImplicitIntegrator(system, settings, implicit) {
  if (implicit_.newton_form == NewtonForm::kGeneric && !caps_.diagonal_mass_matrix) {
    throw InputError(
        "the generic Newton form (I - h J) is only available for diagonal mass matrices, "
        "where M^-1 keeps the sparsity; use the mass-matrix form");
  }
  if (implicit_.extrapolate && implicit_.error_estimator != ImplicitErrorEstimate::kStepDoubling) {
    // Extrapolation needs the step-doubling pair; ie2 is IE with doubling.
    implicit_.error_estimator = ImplicitErrorEstimate::kStepDoubling;
  }
  choose_structured_newton_matrix(
      false, "the recursion solves VIE's velocity Newton systems; ie iterates on q and v together");
}

bool ImplicitEuler::uses_doubling() const {
  return implicit_.extrapolate || implicit_.error_estimator == ImplicitErrorEstimate::kStepDoubling;
}

void ImplicitEuler::do_initialize() {
  load_jacobian_patterns();
  const Dimensions& d = dims_;
  const ForceJacobians& J = jacobians_;
  const int q0 = 0, v0 = d.nq, z0 = d.nq + d.nv;
  PatternBuilder b(d.nx(), d.nx());
  b.add_diagonal(0, d.nx());
  if (caps_.identity_velocity_map) {
    for (int i = 0; i < d.nq; ++i) b.add(q0 + i, v0 + i);
  } else {
    N_ = system_.velocity_map_pattern();
    b.add_pattern(N_, q0, v0);
  }
  b.add_pattern(system_.mass_matrix_pattern(), v0, v0);
  b.add_pattern(J.dF_dq, v0, q0);
  b.add_pattern(J.dF_dv, v0, v0);
  b.add_pattern(J.dF_dz, v0, z0);
  b.add_pattern(J.dfz_dq, z0, q0);
  b.add_pattern(J.dfz_dv, z0, v0);
  b.add_pattern(J.dfz_dz, z0, z0);
  iteration_matrix_ = b.build();

  diagonal_slots_.resize(d.nx());
  for (int i = 0; i < d.nx(); ++i) diagonal_slots_[i] = slot_of(iteration_matrix_, i, i);
  if (caps_.identity_velocity_map) {
    slots_N_.resize(d.nq);
    for (int i = 0; i < d.nq; ++i) slots_N_[i] = slot_of(iteration_matrix_, q0 + i, v0 + i);
  } else {
    slots_N_ = slots_in(iteration_matrix_, N_, q0, v0);
  }
  slots_M_ = slots_in(iteration_matrix_, system_.mass_matrix_pattern(), v0, v0);
  slots_K_ = slots_in(iteration_matrix_, J.dF_dq, v0, q0);
  slots_D_ = slots_in(iteration_matrix_, J.dF_dv, v0, v0);
  slots_Fz_ = slots_in(iteration_matrix_, J.dF_dz, v0, z0);
  slots_Zq_ = slots_in(iteration_matrix_, J.dfz_dq, z0, q0);
  slots_Zv_ = slots_in(iteration_matrix_, J.dfz_dv, z0, v0);
  slots_Zz_ = slots_in(iteration_matrix_, J.dfz_dz, z0, z0);

  initialize_newton(d.nx());
  theta_ = 1.0;
  for (Eigen::VectorXd* v : {&x_ie_, &x_trap_, &xdot0_}) v->resize(d.nx());
  qdot_.resize(d.nq);
  F_.resize(d.nv);
  zdot_.resize(d.nz);
  dv_.resize(d.nv);
}

void ImplicitEuler::compute_jacobian(double t, const Eigen::VectorXd& x, double h) {
  // Linearized where the step is heading, q + h N(q) v, as VIE does (Drake's
  // IE takes (t0, x0) and notes that the end of the step would be better):
  // a cloth at rest and flat has no transverse stiffness at x0, and the two
  // methods should differ in their Newton systems, not in where they
  // linearize.
  compute_force_jacobians_ahead(t, x, h);
  if (!caps_.identity_velocity_map) {
    system_.velocity_map(*data_, linearization_.segment(0, dims_.nq), &N_);
    ++stats_.velocity_map_evaluations;
  }
}

const SparseMatrix& ImplicitEuler::form_iteration_matrix(double h, bool* symmetric) {
  const auto start = WallClock::now();
  const Dimensions& d = dims_;
  const ForceJacobians& J = jacobians_;
  const double a = theta_ * h;  // the step the implicit part sees
  SparseMatrix& A = iteration_matrix_;
  set_zero_keep_pattern(&A);
  double* values = A.valuePtr();
  // q rows: [I, -a N, 0].
  for (int i = 0; i < d.nq; ++i) values[diagonal_slots_[i]] += 1.0;
  if (caps_.identity_velocity_map) {
    for (int i = 0; i < d.nq; ++i) values[slots_N_[i]] -= a;
  } else {
    scatter_add(N_, slots_N_, -a, &A);
  }
  const SparseMatrix& M = mass_matrix_at(state_.q(d));
  if (implicit_.newton_form == NewtonForm::kMassMatrix) {
    // v rows: [-a K, M - a D, -a dF/dz].
    scatter_add(M, slots_M_, 1.0, &A);
    scatter_add(J.dF_dq, slots_K_, -a, &A);
    scatter_add(J.dF_dv, slots_D_, -a, &A);
    scatter_add(J.dF_dz, slots_Fz_, -a, &A);
  } else {
    // v rows of I - a J: [-a M^-1 K, I - a M^-1 D, -a M^-1 dF/dz] (diagonal M).
    const double* m = M.valuePtr();
    for (int i = 0; i < d.nv; ++i) values[diagonal_slots_[d.nq + i]] += 1.0;
    auto add_scaled = [&](const SparseMatrix& part, const std::vector<int>& slots) {
      const int* rows = part.innerIndexPtr();
      const double* p = part.valuePtr();
      for (Eigen::Index k = 0; k < part.nonZeros(); ++k) values[slots[k]] -= a * p[k] / m[rows[k]];
    };
    add_scaled(J.dF_dq, slots_K_);
    add_scaled(J.dF_dv, slots_D_);
    add_scaled(J.dF_dz, slots_Fz_);
  }
  // z rows: [-a Zq, -a Zv, I - a Zz].
  for (int i = d.nq + d.nv; i < d.nx(); ++i) values[diagonal_slots_[i]] += 1.0;
  scatter_add(J.dfz_dq, slots_Zq_, -a, &A);
  scatter_add(J.dfz_dv, slots_Zv_, -a, &A);
  scatter_add(J.dfz_dz, slots_Zz_, -a, &A);
  stats_.assembly_seconds += seconds_since(start);
  // The q rows (I, -a N) against the v rows (-a K, M - a D) make A
  // unsymmetric whatever K and D are.
  *symmetric = false;
  return A;
}

void ImplicitEuler::begin_newton(double t0, double h, const Eigen::VectorXd& x0) {
  (void)t0;
  merit_step_ = theta_ * h;
  mass_diagonal_ =
      caps_.diagonal_mass_matrix ? mass_matrix_at(x0.segment(0, dims_.nq)).valuePtr() : nullptr;
}

void ImplicitEuler::residual(double t, double h, const Eigen::VectorXd& x0,
                             const Eigen::VectorXd& x, Eigen::VectorXd* r) {
  // theta = 1: x - x_n - h f(x); theta = 1/2: x - x_n - h/2 (f(x_n) + f(x)),
  // v rows scaled by M(q) in the mass-matrix form.
  const Dimensions& d = dims_;
  const double a = theta_ * h, b = (1.0 - theta_) * h;
  const auto q = x.segment(0, d.nq), v = x.segment(d.nq, d.nv), z = x.segment(d.nq + d.nv, d.nz);
  if (caps_.identity_velocity_map) {
    r->segment(0, d.nq) = q - x0.segment(0, d.nq) - a * v;
  } else {
    system_.map_velocity_to_qdot(q, v, qdot_);
    ++stats_.velocity_map_evaluations;
    r->segment(0, d.nq) = q - x0.segment(0, d.nq) - a * qdot_;
  }
  if (b != 0.0) r->segment(0, d.nq) -= b * xdot0_.segment(0, d.nq);
  evaluate_forces(t, x, &F_, &zdot_);
  dv_ = v - x0.segment(d.nq, d.nv);
  if (b != 0.0) dv_ -= b * xdot0_.segment(d.nq, d.nv);
  const SparseMatrix& M = mass_matrix_at(q);
  if (implicit_.newton_form == NewtonForm::kMassMatrix && caps_.diagonal_mass_matrix) {
    const double* m = M.valuePtr();
    for (int i = 0; i < d.nv; ++i) (*r)[d.nq + i] = m[i] * dv_[i] - a * F_[i];
  } else if (implicit_.newton_form == NewtonForm::kMassMatrix) {
    r->segment(d.nq, d.nv).noalias() = M * dv_;
    r->segment(d.nq, d.nv) -= a * F_;
  } else {
    const double* m = M.valuePtr();
    for (int i = 0; i < d.nv; ++i) (*r)[d.nq + i] = dv_[i] - a * F_[i] / m[i];
  }
  auto rz = r->segment(d.nq + d.nv, d.nz);
  rz = z - x0.segment(d.nq + d.nv, d.nz) - a * zdot_;
  if (b != 0.0) rz -= b * xdot0_.segment(d.nq + d.nv, d.nz);
}

double ImplicitEuler::merit(const Eigen::VectorXd& r) const {
  // Every row in velocity units: the v rows as VIE measures them, the q
  // rows divided by the step (q - q_n)/h - N v. Unscaled, a stiff scene's
  // position residuals weigh next to nothing against its momenta, and the
  // approximate Newton direction stops being a descent direction.
  const Dimensions& d = dims_;
  if (implicit_.newton_form == NewtonForm::kMassMatrix && caps_.diagonal_mass_matrix) {
    double sum =
        r.segment(0, d.nq).squaredNorm() / (merit_step_ * merit_step_) + r.tail(d.nz).squaredNorm();
    for (int i = 0; i < d.nv; ++i) {
      const double w = r[d.nq + i] / mass_diagonal_[i];
      sum += w * w;
    }
    return sum;
  }
  return r.segment(0, d.nq).squaredNorm() / (merit_step_ * merit_step_) +
         r.tail(d.nv + d.nz).squaredNorm();
}

const Eigen::VectorXd& ImplicitEuler::residual_scaling() {
  // The row weights of merit(), so Krylov solves minimize its norm.
  const Dimensions& d = dims_;
  residual_scale_.resize(d.nx());
  residual_scale_.head(d.nq).setConstant(1.0 / merit_step_);
  const bool by_mass =
      implicit_.newton_form == NewtonForm::kMassMatrix && caps_.diagonal_mass_matrix;
  for (int i = 0; i < d.nv; ++i)
    residual_scale_[d.nq + i] = by_mass ? 1.0 / mass_diagonal_[i] : 1.0;
  residual_scale_.tail(d.nz).setOnes();
  return residual_scale_;
}

bool ImplicitEuler::step_with_trapezoid_estimate(double h) {
  const double t0 = state_.t;
  const Eigen::VectorXd& x0 = state_.x;
  theta_ = 1.0;
  use_iteration_matrix(kImplicitEulerMatrix);
  if (!solve_step(t0, h, x0, x0, &x_ie_)) return false;

  // The trapezoid rule from the IE result, sharing its Jacobian: its work is
  // the error estimator's.
  const IntegratorStatistics before = stats_;
  evaluate_state_derivative(t0, x0, &xdot0_);
  theta_ = 0.5;
  use_iteration_matrix(kTrapezoidMatrix);
  // The trapezoid rule conserves energy where IE dissipates it; its result
  // is only compared, never propagated, so the energy guard stays out.
  suspend_energy_guard(true);
  const bool ok = solve_step(t0, h, x0, x_ie_, &x_trap_);
  suspend_energy_guard(false);
  theta_ = 1.0;
  use_iteration_matrix(kImplicitEulerMatrix);
  add_estimator_share(before, &stats_);
  if (!ok) return false;
  error_ = x_ie_ - x_trap_;
  candidate_.swap(x_ie_);
  return true;
}

bool ImplicitEuler::do_step(double h) {
  if (!estimating_error() && !extrapolating()) {
    return solve_step(state_.t, h, state_.x, state_.x, &candidate_);
  }
  if (uses_doubling()) return step_doubling(h);
  return step_with_trapezoid_estimate(h);
}

IntegratorReport ImplicitEuler::report() const {
  IntegratorReport r = ImplicitIntegrator::report();
  if (estimating_error())
    r.error_estimator = uses_doubling() ? "step doubling" : "implicit trapezoid";
  return r;
}

}  // namespace stiffsim
