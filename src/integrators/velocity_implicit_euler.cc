#include "stiffsim/integrators/velocity_implicit_euler.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "stiffsim/error.h"
#include "stiffsim/integrators/wall_clock.h"
#include "stiffsim/linalg/sparse_pattern.h"
#include "stiffsim/linalg/sparse_products.h"

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
  choose_structured_newton_matrix(
      implicit_.newton_form == NewtonForm::kMassMatrix && dims_.nz == 0,
      "the recursion solves VIE's mass-matrix form of systems without misc states");
}

void VelocityImplicitEuler::do_initialize() {
  const Dimensions& d = dims_;
  step_error_ = step_error_h_ = step_change_ = 0.0;
  residual_state_.resize(d.nx());
  predicted_.resize(d.nx());
  start_iterate_.resize(d.nx());
  shared_iterate_.resize(d.nx());
  guess_iterate_.resize(d.nx());
  energy_state_.x = Eigen::VectorXd::Zero(d.nx());
  dv_.resize(d.nv);
  qdot_.resize(d.nq);
  F_.resize(d.nv);
  zdot_.resize(d.nz);
  if (structured()) {
    // No assembled matrix, Jacobian or pattern: the system's recursion is
    // the Newton matrix.
    use_potential_merit_ = false;
    initialize_newton(d.ny());
    return;
  }
  load_jacobian_patterns();
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
  // Where D and K share one pattern that holds M and the diagonal (a
  // particle system's: each spring's 3x3 blocks in both), that pattern is
  // the union already, with its rows sorted as build() sorts them; building
  // it again took 0.2 s of the 100x100 sheet's set-up (3.5 M entries
  // collected and sorted).
  if (d.nz == 0 && same_pattern(J.dF_dv, K_or_KN) &&
      holds_pattern(K_or_KN, system_.mass_matrix_pattern(), true)) {
    iteration_matrix_ = K_or_KN;
    set_zero_keep_pattern(&iteration_matrix_);
  } else {
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
  }

  slots_M_ = slots_in(iteration_matrix_, system_.mass_matrix_pattern());
  slots_D_ = slots_in(iteration_matrix_, J.dF_dv);
  slots_K_ = slots_in(iteration_matrix_, K_or_KN);
  slots_Fz_ = slots_in(iteration_matrix_, J.dF_dz, 0, d.nv);
  slots_Zv_ = slots_in(iteration_matrix_, J.dfz_dv, d.nv, 0);
  slots_Zq_ = slots_in(iteration_matrix_, Zq_or_ZqN, d.nv, 0);
  slots_Zz_ = slots_in(iteration_matrix_, J.dfz_dz, d.nv, d.nv);
  identity_slots_.resize(d.ny());
  for (int i = 0; i < d.ny(); ++i) identity_slots_[i] = slot_of(iteration_matrix_, i, i);
  auto in_order = [&](const std::vector<int>& slots) {
    if (static_cast<Eigen::Index>(slots.size()) != iteration_matrix_.nonZeros()) return false;
    for (size_t k = 0; k < slots.size(); ++k) {
      if (slots[k] != static_cast<int>(k)) return false;
    }
    return true;
  };
  shared_pattern_ = d.nz == 0 && in_order(slots_D_) && in_order(slots_K_);

  initialize_newton(d.ny());
  // G is a valid merit where the residual is its gradient: the mass-matrix
  // form of a passive scene with energy, analytic Jacobians, N = I, a
  // constant diagonal M and no z states.
  use_potential_merit_ = implicit_.newton_form == NewtonForm::kMassMatrix && caps_.has_energy &&
                         caps_.passive && caps_.analytic_jacobians && caps_.identity_velocity_map &&
                         caps_.diagonal_mass_matrix && caps_.constant_mass_matrix && d.nz == 0;
  if (use_potential_merit_) {
    merit_jacobians_ = system_.jacobian_pattern();
    damping_matrix_ = &merit_jacobians_.dF_dv;
    g_scale_ = 0.0;
  }
}

const SparseMatrix& VelocityImplicitEuler::form_iteration_matrix(double h, bool* symmetric) {
  const auto start = WallClock::now();
  const Dimensions& d = dims_;
  const ForceJacobians& J = jacobians_;
  SparseMatrix& W = iteration_matrix_;
  const SparseMatrix& K = caps_.identity_velocity_map ? J.dF_dq : KN_;
  const SparseMatrix& Zq = caps_.identity_velocity_map ? J.dfz_dq : ZqN_;
  if (implicit_.newton_form == NewtonForm::kMassMatrix) {
    // W = [M - h D - h^2 K N, -h dF/dz; -h dfz/dv - h^2 dfz/dq N, I - h dfz/dz]
    if (shared_pattern_) {
      // D, K and W store the same entries in the same order (particles:
      // the force Jacobians' pattern holds every diagonal block, and so
      // M's pattern): one pass over the three, where zeroing W and
      // scattering D and K through their slots took three
      // (cloth_stiff.yaml: 3.7% of the run's samples).
      const double* dv = J.dF_dv.valuePtr();
      const double* kv = K.valuePtr();
      double* w = W.valuePtr();
      const Eigen::Index count = W.nonZeros();
      for (Eigen::Index k = 0; k < count; ++k) w[k] = -h * dv[k] - h * h * kv[k];
      scatter_add(mass_matrix_at(state_.q(d)), slots_M_, 1.0, &W);
    } else {
      set_zero_keep_pattern(&W);
      scatter_add(mass_matrix_at(state_.q(d)), slots_M_, 1.0, &W);
      scatter_add(J.dF_dv, slots_D_, -h, &W);
      scatter_add(K, slots_K_, -h * h, &W);
    }
    for (int i = d.nv; i < d.ny(); ++i) W.valuePtr()[identity_slots_[i]] += 1.0;
  } else {
    // A = I - h J_l with J_l = [M^-1 (D + h K N), M^-1 dF/dz; dfz/dv + h dfz/dq N, dfz/dz].
    set_zero_keep_pattern(&W);
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
  // Symmetric (so CHOLMOD applies) for conservative particle-like systems:
  // N = I, no z coupling, symmetric K and D, and the mass-matrix form.
  // Finite-difference and automatic Jacobians carry the unsymmetric terms
  // the analytic ones drop.
  *symmetric = implicit_.newton_form == NewtonForm::kMassMatrix &&
               implicit_.jacobian == JacobianScheme::kAnalytic && caps_.symmetric_jacobians &&
               caps_.identity_velocity_map && d.nz == 0;
  return W;
}

void VelocityImplicitEuler::compute_jacobian(double t, const Eigen::VectorXd& x, double h) {
  const Dimensions& d = dims_;
  compute_force_jacobians_ahead(t, x, h);
  if (!caps_.identity_velocity_map) {
    system_.velocity_map(*data_, x.segment(0, d.nq), &N_);  // N(q_n): lagged, as the seed says
    ++stats_.velocity_map_evaluations;
    // The products K N and dfz/dq N into their structural patterns, so
    // their slots in the iteration matrix stay valid and nothing is
    // allocated.
    multiply_into_pattern(jacobians_.dF_dq, N_, &KN_, &product_marker_);
    multiply_into_pattern(jacobians_.dfz_dq, N_, &ZqN_, &product_marker_);
  }
}

void VelocityImplicitEuler::residual(double t, double h, const Eigen::VectorXd& x0,
                                     const Eigen::VectorXd& x, Eigen::VectorXd* r) {
  // The residual is exact: q = q_n + h N(q_k) v is rebuilt from the current
  // v before F is evaluated, as in Drake's l(y).
  const Dimensions& d = dims_;
  residual_state_ = x;
  if (caps_.identity_velocity_map) {
    residual_state_.segment(0, d.nq) = x0.segment(0, d.nq) + h * x.segment(d.nq, d.nv);
  } else {
    system_.map_velocity_to_qdot(x.segment(0, d.nq), x.segment(d.nq, d.nv), qdot_);
    ++stats_.velocity_map_evaluations;
    residual_state_.segment(0, d.nq) = x0.segment(0, d.nq) + h * qdot_;
  }
  const auto v = x.segment(d.nq, d.nv);
  const auto v0 = x0.segment(d.nq, d.nv);
  if (implicit_.newton_form == NewtonForm::kMassMatrix && caps_.momentum_residual &&
      !caps_.constant_mass_matrix) {
    // One inverse-dynamics pass at the acceleration (v - v_n) / h: M(q) is
    // never formed for a residual.
    const auto start = WallClock::now();
    const auto q = residual_state_.segment(0, d.nq);
    const auto z = residual_state_.segment(d.nq + d.nv, d.nz);
    dv_ = v - v0;
    system_.momentum_residual(*data_, t, q, v, z, dv_, h, r->segment(0, d.nv));
    if (d.nz > 0) system_.misc_derivatives(*data_, t, q, v, z, zdot_);
    ++stats_.derivative_evaluations;
    stats_.derivative_seconds += seconds_since(start);
    r->segment(d.nv, d.nz) = x.segment(d.nq + d.nv, d.nz) - x0.segment(d.nq + d.nv, d.nz) - h * zdot_;
    return;
  }
  evaluate_forces(t, residual_state_, &F_, &zdot_);
  const SparseMatrix& M = mass_matrix_at(residual_state_.segment(0, d.nq));
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

void VelocityImplicitEuler::complete_iterate(double h, const Eigen::VectorXd& x0,
                                             Eigen::VectorXd* x) {
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

double VelocityImplicitEuler::residual_norm(const Eigen::VectorXd& r) const {
  // Velocity units: W = M - h D - h^2 K >= M (D and the definite K are
  // negative semidefinite), so |W^-1 r|_M <= |r|_{M^-1}: the velocity error
  // left by a residual is at most the residual divided by the masses.
  if (implicit_.newton_form != NewtonForm::kMassMatrix) return r.lpNorm<Eigen::Infinity>();
  if (!caps_.diagonal_mass_matrix || mass_diagonal_ == nullptr) {
    return std::numeric_limits<double>::infinity();
  }
  double largest = 0.0;
  for (int i = 0; i < dims_.nv; ++i)
    largest = std::max(largest, std::abs(r[i] / mass_diagonal_[i]));
  for (int i = dims_.nv; i < r.size(); ++i) largest = std::max(largest, std::abs(r[i]));
  return largest;
}

const Eigen::VectorXd& VelocityImplicitEuler::residual_scaling() {
  // merit() divides the momentum rows by the masses.
  if (implicit_.newton_form != NewtonForm::kMassMatrix || !caps_.diagonal_mass_matrix ||
      mass_diagonal_ == nullptr) {
    residual_scale_.resize(0);
    return residual_scale_;
  }
  // A constant M gives the same scaling every solve: formed once.
  if (caps_.constant_mass_matrix && residual_scale_.size() == dims_.ny()) return residual_scale_;
  residual_scale_.resize(dims_.ny());
  for (int i = 0; i < dims_.nv; ++i) residual_scale_[i] = 1.0 / mass_diagonal_[i];
  residual_scale_.tail(dims_.nz).setOnes();
  return residual_scale_;
}

const Eigen::VectorXd& VelocityImplicitEuler::predictor(double h, const Eigen::VectorXd& x0) {
  // The step's velocities extrapolated from the last accepted step (the
  // acceleration held): exact for a free fall, and the first iterate
  // starts where the Newton direction has least to do.
  const Dimensions& d = dims_;
  const double h_prev = state_.t - previous_.t;
  if (!(h_prev > 0.0) || &x0 != &state_.x || d.nv == 0) return x0;
  predicted_ = x0;
  predicted_.segment(d.nq, d.nv) +=
      (h / h_prev) * (x0.segment(d.nq, d.nv) - previous_.x.segment(d.nq, d.nv));
  complete_iterate(h, x0, &predicted_);
  return predicted_;
}

double VelocityImplicitEuler::incremental_potential(double t, const Eigen::VectorXd& x0,
                                                    const Eigen::VectorXd& x, double h,
                                                    bool damping) {
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
  const double potential = system_.energy(*data_, energy_state_);
  const auto v = x.segment(d.nq, d.nv);
  dv_ = v - x0.segment(d.nq, d.nv);
  const double* m = mass_diagonal_;
  double inertia = 0.0;
  for (int i = 0; i < d.nv; ++i) inertia += 0.5 * m[i] * dv_[i] * dv_[i];
  if (!damping) return inertia + potential;
  // Particles' damping matrices are symmetric: half of D is read.
  const double vDv = caps_.symmetric_jacobians ? symmetric_quadratic_form(*damping_matrix_, v)
                                               : quadratic_form(*damping_matrix_, v);
  return inertia + potential - 0.5 * h * vDv;
}

void VelocityImplicitEuler::begin_newton(double t0, double h, const Eigen::VectorXd& x0) {
  (void)t0, (void)h;
  if (use_potential_merit_) g_scale_ = std::abs(system_.energy(*data_, state_));
  load_mass_diagonal(x0);
}

void VelocityImplicitEuler::load_mass_diagonal(const Eigen::VectorXd& x0) {
  mass_diagonal_ =
      caps_.diagonal_mass_matrix ? mass_matrix_at(x0.segment(0, dims_.nq)).valuePtr() : nullptr;
}

bool VelocityImplicitEuler::potential_search(int trial) const {
  // The potential costs a damping-matrix evaluation per iteration, so the
  // reuse rungs (1, 2), whose solves are the common and easy ones, use the
  // residual with the energy guard behind it; the rungs that follow a
  // failure (3, 4), where spurious roots are met, use G.
  return has_potential() && trial >= 3;
}

double VelocityImplicitEuler::potential(double t, const Eigen::VectorXd& x0,
                                        const Eigen::VectorXd& x, double h, bool new_iterate,
                                        bool jacobian_at_x) {
  // Full Newton's Jacobian at the iterate holds its damping matrix: an
  // evaluation of the damping alone costs as much as the Jacobian (every
  // spring's frame), and full Newton searches every iterate
  // (cloth_stiff.yaml: about one in two of the run's force-Jacobian
  // evaluations).
  if (new_iterate) {
    if (jacobian_at_x) {
      damping_matrix_ = &jacobians_.dF_dv;
    } else {
      evaluate_damping(t, x);
      damping_matrix_ = &merit_jacobians_.dF_dv;
    }
  }
  return incremental_potential(t, x0, x, h);
}

double VelocityImplicitEuler::potential_roundoff(double g) const {
  return 1e-11 * (std::abs(g) + g_scale_);
}

void VelocityImplicitEuler::evaluate_damping(double t, const Eigen::VectorXd& x) {
  const auto start = WallClock::now();
  const Dimensions& d = dims_;
  system_.force_jacobians(*data_, t, x.segment(0, d.nq), x.segment(d.nq, d.nv),
                          x.segment(d.nq + d.nv, d.nz), JacobianRequest{}, &merit_jacobians_);
  ++stats_.merit_damping_evaluations;
  stats_.jacobian_seconds += seconds_since(start);
}

const Eigen::VectorXd& VelocityImplicitEuler::first_iterate(double h,
                                                            const Eigen::VectorXd& predicted) {
  // The predictor holds the last step's acceleration, exact for a free
  // fall. On a very stiff sheet the velocities jitter from step to step,
  // and the extrapolated jitter can start Newton far up the incremental
  // potential G, even in another basin: on models/cloth.yaml at 16x16 with
  // stretch k = 1e8 at a fixed 1/60 for 2 s, 188 of 206 attempts were
  // halved from there (20 s); started at v = v_n whenever that was the
  // lower point of G, 12 of 126 (3.3 s). G is compared without its
  // damping term: the damping matrix at each point costs a Jacobian
  // evaluation, and the stiff springs' potential and the inertia decide
  // the choice. models/cloth.yaml at a fixed 1/60 for 2 s took 1.06x the
  // time of the predictor alone with it, 0.84x without (medians of 5).
  //
  // Newton starts ImplicitSettings::predictor_share (0.5) of the way to the
  // predictor, not at it. Where the sheet folds and buckles, the
  // acceleration a step extrapolates has often turned by the next, and
  // the midpoint hedges between the two starts' errors (h^2 a' at the
  // predictor where a is smooth, h a at v_n where it swings). Against the
  // predictor (share 1), paired runs at a fixed 1/60 with the same Newton
  // tolerances: cloth.yaml for 2 s 0.85x the time (10 starts; 166 against
  // 190 factorizations), cloth_stiff.yaml 0.95x (10; 415 against 428), the
  // 60x60 sheet for 0.5 s 0.47x (8; halvings in none against 6 of 8 runs),
  // the 100x100 sheet 0.96x (5), the 16x16 sheet of k = 1e8 1.04x (6).
  // Shares of 0.25 and 0.75 (without the comparison below) did less on
  // the first two; v_n always gave 0.80-1.08x on cloth.yaml in three
  // ensembles. G is no guide to the share: at G's lowest of 9 points along
  // the line (0.75-1 of the way on most steps) the sheets took 0.94-1.03x
  // the time of the predictor. Without the comparison with v_n below,
  // cloth.yaml took 1.35x the time of the midpoint with it.
  if (&predicted == &state_.x || !has_potential()) return predicted;
  const double tf = state_.t + h;
  load_mass_diagonal(state_.x);  // all G needs here of begin_newton()
  // Where the predictor missed the last step's result by less than
  // kTrustedPredictorMiss of that step's velocity change (2 step_error_
  // against step_change_), it is the start: at small h the motion is
  // smooth, the miss (h^2 a') a few hundredths of the change (h a), and
  // the midpoint cost Newton iterations. The 20x20 sheet of k = 1e6 to
  // 0.25 s at h = 1e-4 took 49 factorizations and 5,381 Newton
  // iterations from the midpoint, 24 and 2,894 from the predictor, 25 and
  // 2,832 with the rule (1e-3: 94, 82 and 80 factorizations). At 1/60 the
  // predictor misses by 0.2-0.8 of the change, and the rule keeps the
  // midpoint (cloth.yaml, 8 starts: 0.95x the time of the midpoint
  // throughout; cloth_stiff.yaml 1.00x).
  const double share =
      2.0 * step_error_ < kTrustedPredictorMiss * step_change_ ? 1.0 : implicit_.predictor_share;
  const Eigen::VectorXd* toward = &predicted;
  if (share != 1.0) {
    shared_iterate_ = state_.x + share * (predicted - state_.x);
    complete_iterate(h, state_.x, &shared_iterate_);
    toward = &shared_iterate_;
  }
  start_iterate_ = state_.x;
  complete_iterate(h, state_.x, &start_iterate_);
  const double g_start = incremental_potential(tf, state_.x, start_iterate_, h, false);
  const double g_toward = incremental_potential(tf, state_.x, *toward, h, false);
  if (!(g_start < g_toward)) return *toward;
  ++stats_.predictor_declined;
  return start_iterate_;
}

double VelocityImplicitEuler::guess_potential(double t0, double h, const Eigen::VectorXd& x0,
                                              const Eigen::VectorXd& x) {
  if (!has_potential()) return std::numeric_limits<double>::quiet_NaN();
  load_mass_diagonal(x0);  // all G needs here of begin_newton()
  guess_iterate_ = x;
  complete_iterate(h, x0, &guess_iterate_);
  return incremental_potential(t0 + h, x0, guess_iterate_, h, false);
}

bool VelocityImplicitEuler::do_step(double h) {
  if (!estimating_error() && !extrapolating()) {
    // Fixed steps without an estimate. The predictor extrapolates v with
    // the last step's velocity change, which implicit Euler made
    // h a(t_n), to v_n + h a(t_n); the step itself takes v_n + h a(t_n+1),
    // so to leading order the result differs from the prediction by
    // h^2 a', twice the step's local error h^2 a' / 2 (the exact
    // v(t_n+1) = v_n + h a(t_n) + h^2 a' / 2 + ...). The last step's
    // difference (scaled by h^2 to this step) sets this solve's Newton
    // tolerance (use_step_error_tolerance).
    const Eigen::VectorXd& predicted = predictor(h, state_.x);
    const bool has_prediction = &predicted != &state_.x;
    const double scale = step_error_h_ > 0.0 ? (h / step_error_h_) * (h / step_error_h_) : 0.0;
    use_step_error_tolerance(has_prediction ? scale * step_error_ : 0.0);
    const Eigen::VectorXd& guess =
        krylov_path() || structured() ? first_iterate(h, predicted) : state_.x;
    const bool solved = solve_step(state_.t, h, state_.x, guess, &candidate_) &&
                        keep_lowest_root(state_.t, h, state_.x, &candidate_);
    if (solved && has_prediction) {
      const int nq = dims_.nq, nv = dims_.nv;
      step_error_ =
          (candidate_.segment(nq, nv) - predicted.segment(nq, nv)).lpNorm<Eigen::Infinity>() / 2.0;
      step_change_ =
          (candidate_.segment(nq, nv) - state_.x.segment(nq, nv)).lpNorm<Eigen::Infinity>();
      step_error_h_ = h;
    }
    return solved;
  }
  return step_doubling(h);
}

}  // namespace stiffsim
