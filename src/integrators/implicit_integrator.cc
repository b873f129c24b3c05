#include "stiffsim/integrators/implicit_integrator.h"

#include <Eigen/SparseCholesky>
#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>

#include "stiffsim/error.h"
#include "stiffsim/integrators/wall_clock.h"
#include "stiffsim/linalg/sparse_products.h"

namespace stiffsim {

NewtonForm parse_newton_form(const std::string& name) {
  if (name == "mass-matrix") return NewtonForm::kMassMatrix;
  if (name == "generic") return NewtonForm::kGeneric;
  throw InputError("unknown Newton form '" + name + "' (expected mass-matrix or generic)");
}

std::string to_string(NewtonForm form) {
  return form == NewtonForm::kMassMatrix ? "mass-matrix" : "generic";
}

NewtonSolve parse_newton_solve(const std::string& name) {
  if (name == "auto") return NewtonSolve::kAuto;
  if (name == "chord") return NewtonSolve::kChord;
  if (name == "krylov") return NewtonSolve::kKrylov;
  if (name == "fresh") return NewtonSolve::kFresh;
  if (name == "recursive") return NewtonSolve::kRecursive;
  throw InputError("unknown Newton solve '" + name +
                   "' (expected auto, chord, krylov, fresh or recursive)");
}

std::string to_string(NewtonSolve solve) {
  switch (solve) {
    case NewtonSolve::kAuto:
      return "auto";
    case NewtonSolve::kChord:
      return "chord";
    case NewtonSolve::kKrylov:
      return "krylov";
    case NewtonSolve::kFresh:
      return "fresh";
    case NewtonSolve::kRecursive:
      return "recursive";
  }
  return "?";
}

bool parse_newton_tolerance(const std::string& name) {
  if (name == "step-error") return true;
  if (name == "accuracy") return false;
  throw InputError("unknown Newton tolerance '" + name + "' (expected step-error or accuracy)");
}

std::string newton_tolerance_name(bool step_error_tolerance) {
  return step_error_tolerance ? "step-error" : "accuracy";
}

bool parse_preconditioner_precision(const std::string& name) {
  if (name == "single") return true;
  if (name == "double") return false;
  throw InputError("unknown preconditioner precision '" + name + "' (expected single or double)");
}

std::string preconditioner_precision_name(bool single) { return single ? "single" : "double"; }

ImplicitErrorEstimate parse_error_estimator(const std::string& name) {
  if (name == "trapezoid") return ImplicitErrorEstimate::kTrapezoid;
  if (name == "doubling") return ImplicitErrorEstimate::kStepDoubling;
  throw InputError("unknown error estimator '" + name + "' (expected trapezoid or doubling)");
}

std::string to_string(ImplicitErrorEstimate estimator) {
  return estimator == ImplicitErrorEstimate::kTrapezoid ? "trapezoid" : "doubling";
}

ImplicitIntegrator::ImplicitIntegrator(const System& system, IntegratorSettings settings,
                                       ImplicitSettings implicit)
    : IntegratorBase(system, settings),
      implicit_(implicit),
      jacobian_evaluator_(system, implicit.jacobian) {
  if (implicit_.max_newton_iterations < 1) {
    throw InputError("max_newton_iterations must be at least 1");
  }
  if (!(implicit_.newton_kappa > 0.0 && implicit_.newton_kappa < 1.0)) {
    throw InputError("newton_kappa must be in (0, 1)");
  }
  if (!(implicit_.step_error_kappa > 0.0 && implicit_.step_error_kappa < 1.0)) {
    throw InputError("step_error_kappa must be in (0, 1)");
  }
  if (implicit_.direct_stall_updates < 0) {
    throw InputError("direct_stall_updates must be at least 0 (0: never)");
  }
  if (implicit_.max_krylov_iterations < 1) {
    throw InputError("max_krylov_iterations must be at least 1");
  }
  if (implicit_.refined_solve_products < 1) {
    throw InputError("refined_solve_products must be at least 1");
  }
  if (!(implicit_.max_forcing > 0.0 && implicit_.max_forcing < 1.0)) {
    throw InputError("max_forcing must be in (0, 1)");
  }
  if (!(implicit_.krylov_forcing > 0.0 && implicit_.krylov_forcing < 1.0)) {
    throw InputError("krylov_forcing must be in (0, 1)");
  }
  if (implicit_.newton_solve == NewtonSolve::kFresh) implicit_.full_newton = true;
}

void ImplicitIntegrator::choose_structured_newton_matrix(bool method_allows,
                                                         const std::string& why_not) {
  const NewtonSolve asked = implicit_.newton_solve;
  if (asked != NewtonSolve::kAuto && asked != NewtonSolve::kRecursive) return;
  std::unique_ptr<StructuredNewtonMatrix> matrix =
      method_allows ? system_.make_structured_newton_matrix() : nullptr;
  if (asked == NewtonSolve::kRecursive && !matrix) {
    throw InputError("--newton-solve recursive: " +
                     (method_allows ? system_.name() +
                                          " has no structured Newton matrix (exact articulated "
                                          "trees without bushings have one)"
                                    : why_not));
  }
  if (!matrix) return;
  // Under auto, small trees keep the assembled matrix, and so does a run
  // that asked for another Jacobian scheme (it wants that Jacobian used).
  if (asked == NewtonSolve::kAuto &&
      (dims_.nv < kRecursiveMinDofs || implicit_.jacobian != JacobianScheme::kAnalytic)) {
    return;
  }
  structured_ = std::move(matrix);
  newton_solve_chosen_ = true;
  newton_solve_reason_ =
      std::string(asked == NewtonSolve::kRecursive ? "asked for: " : "auto: ") +
      structured_->method() + " (O(n): M(q) + h D + h^2 K of the joints) factored at every " +
      "iterate, preconditioning GMRES on the exact Jacobian applied by residual differences" +
      (asked == NewtonSolve::kRecursive ? ""
                                        : "; trees of at least " +
                                              std::to_string(kRecursiveMinDofs) + " velocities");
}

bool ImplicitIntegrator::factor_structured(const Eigen::VectorXd& x, double h) {
  const auto start = WallClock::now();
  const bool ok = structured_->factor(x.segment(0, dims_.nq), h);
  stats_.factorization_seconds += seconds_since(start);
  ++stats_.recursive_factorizations;
  return ok;
}

ImplicitIntegrator::Convergence ImplicitIntegrator::check_newton_convergence(
    int iteration, const Eigen::VectorXd& x, const Eigen::VectorXd& dx, double dx_norm,
    double last_dx_norm) {
  if (!std::isfinite(dx_norm)) return Convergence::kDiverged;
  // An update at the level of round-off has converged whatever the rate says.
  bool zero = true;
  for (Eigen::Index i = 0; i < dx.size() && zero; ++i) {
    zero = std::abs(dx[i]) <= std::max(std::abs(x[i]), 1.0) * kZeroUpdate;
  }
  if (zero) return Convergence::kConverged;
  // Hairer & Wanner IV.8: theta = |dx_k| / |dx_{k-1}|, eta = theta / (1 - theta).
  // As in Drake, the test starts at the third iteration: the first rate is
  // no guide with a reused matrix. Formed for another h (or state), the
  // matrix leaves soft components converged after one update while stiff
  // ones barely move, so |dx_1| / |dx_0| reads small and eta |dx_1| passes
  // the tolerance with the stiff error untouched. Measured on an 8x8 cloth
  // (IE at accuracy 1e-3, matrix from h = 1e-3 reused at h = 1.4e-5): steps
  // accepted with a velocity residual of 0.13 m/s, whose error estimate then
  // never fell with h (27,156 steps in 0.5 s).
  if (iteration == 0) return Convergence::kNotYet;
  // An update a thousandth of the tolerance needs no rate: a matrix formed
  // within kReuseStepRatio of h moves every direction by at least 1/16 of
  // its error per iteration, so the error left is below 1/60 of the
  // tolerance. Without this, an iteration that reached round-off in two
  // updates reads its third, noise, as a rate near 1 and fails.
  if (dx_norm <= 1e-3 * solve_tolerance_) return Convergence::kConverged;
  if (iteration < 2) return Convergence::kNotYet;
  // After a damped step (last_dx_norm infinite) there is no rate either:
  // theta would read 0 and accept any update. Eta = 1 stands in, so only an
  // update already below the tolerance converges.
  if (!std::isfinite(last_dx_norm)) {
    return dx_norm <= solve_tolerance_ ? Convergence::kConverged : Convergence::kNotYet;
  }
  const double theta = dx_norm / last_dx_norm;
  if (theta >= 1.0) return Convergence::kDiverged;
  const double eta = theta / (1.0 - theta);
  if (eta * dx_norm <= solve_tolerance_) return Convergence::kConverged;
  return Convergence::kNotYet;
}

void ImplicitIntegrator::compute_force_jacobians(double t, const Eigen::VectorXd& x) {
  const auto start = WallClock::now();
  JacobianRequest request;
  request.definite = implicit_.definite_iteration_matrix && !exact_jacobian_;
  if (estimate_tensions_ && !exact_jacobian_) {
    request.tension_positions = tension_positions_.data();
    request.tension_carried = tension_carried_;
  }
  if (!caps_.constant_mass_matrix && dims_.nv > 0 && iterate_acceleration_) {
    request.acceleration = inertial_acceleration_.data();
  } else if (!caps_.constant_mass_matrix && dims_.nv > 0) {
    // The Newton matrices need d(M(q) dv)/dq beside K (system.h,
    // JacobianRequest::acceleration); dv ~ h a, predicted by the
    // acceleration at the linearization point.
    inertial_F_.resize(dims_.nv);
    inertial_zdot_.resize(dims_.nz);
    evaluate_forces(t, x, &inertial_F_, &inertial_zdot_);
    solve_mass_matrix(t, x.segment(0, dims_.nq), inertial_F_, &inertial_acceleration_);
    request.acceleration = inertial_acceleration_.data();
  }
  // Differences count their evaluations of (F, f_z) as derivative
  // evaluations too, as Drake does.
  const int evaluations = jacobian_evaluator_.evaluate(t, x, request, &jacobians_);
  stats_.derivative_evaluations += evaluations;
  stats_.derivative_evaluations_for_jacobian += evaluations;
  ++stats_.jacobian_evaluations;
  stats_.jacobian_approximated_terms += jacobians_.approximated_terms;
  last_jacobian_seconds_ = seconds_since(start);
  stats_.jacobian_seconds += last_jacobian_seconds_;
  jacobians_valid_ = true;
}

void ImplicitIntegrator::compute_force_jacobians_ahead(double t, const Eigen::VectorXd& x,
                                                       double h) {
  const Dimensions& d = dims_;
  linearization_ = x;
  if (caps_.identity_velocity_map) {
    linearization_.segment(0, d.nq) += h * x.segment(d.nq, d.nv);
  } else {
    system_.map_velocity_to_qdot(x.segment(0, d.nq), x.segment(d.nq, d.nv), predictor_qdot_);
    ++stats_.velocity_map_evaluations;
    linearization_.segment(0, d.nq) += h * predictor_qdot_;
  }
  compute_force_jacobians(t, linearization_);
}

const SparseMatrix& ImplicitIntegrator::factored_matrix(const SparseMatrix& W) {
  CoveredCouplings& c = covered_;
  if (!c.examined) {
    c.examined = true;
    const long n = W.rows();
    if (!implicit_.drop_covered_couplings || n < kCoveredMinUnknowns) return W;
    const std::vector<std::array<int, 2>> pairs = system_.covered_couplings();
    if (pairs.empty()) return W;
    // The point (its first index) of every index a pair names, and each
    // point's partners.
    std::vector<int> point(n, -1);
    std::vector<std::vector<int>> partners(n);
    for (const auto& [a, b] : pairs) {
      if (a < 0 || b < 0 || a + 3 > n || b + 3 > n) return W;
      for (int d = 0; d < 3; ++d) point[a + d] = a, point[b + d] = b;
      partners[a].push_back(b);
      partners[b].push_back(a);
    }
    const int* outer = W.outerIndexPtr();
    const int* inner = W.innerIndexPtr();
    auto left_out = [&](int r, int col) {
      const int pr = point[r], pc = point[col];
      if (pr < 0 || pc < 0 || pr == pc) return false;
      return std::find(partners[pr].begin(), partners[pr].end(), pc) != partners[pr].end();
    };
    c.source.clear();
    c.source.reserve(W.nonZeros());
    c.matrix.resize(n, n);
    c.matrix.reserve(W.nonZeros());
    long below = 0, above = 0;
    std::vector<std::pair<int, int>> left;  // (entry of W, its column)
    for (long col = 0; col < n; ++col) {
      c.matrix.startVec(col);
      for (int k = outer[col]; k < outer[col + 1]; ++k) {
        if (left_out(inner[k], static_cast<int>(col))) {
          left.push_back({k, static_cast<int>(col)});
          (inner[k] > col ? below : above) += 1;
        } else {
          c.matrix.insertBack(inner[k], col) = 0.0;
          c.source.push_back(k);
        }
      }
    }
    c.matrix.finalize();
    if (left.empty() || below != above) return W;  // W must hold both triangles
    // Each left-out entry (r, col) of block (a, b) adds to (r, a + col - b).
    const int* m_outer = c.matrix.outerIndexPtr();
    const int* m_inner = c.matrix.innerIndexPtr();
    c.left_out.clear();
    c.twin.clear();
    for (const auto& [k, col] : left) {
      const int r = inner[k];
      const long twin_col = point[r] + (col - point[col]);
      const int* first = m_inner + m_outer[twin_col];
      const int* last = m_inner + m_outer[twin_col + 1];
      const int* at = std::lower_bound(first, last, r);
      if (at == last || *at != r) return W;  // no diagonal block to move it to
      c.left_out.push_back(k);
      c.twin.push_back(static_cast<int>(at - m_inner));
    }
  }
  if (c.left_out.empty()) return W;
  // The kept entries are gathered (no test per entry of W), then the
  // left-out ones added to their twins.
  const double* value = W.valuePtr();
  double* out = c.matrix.valuePtr();
  const int* source = c.source.data();
  const long kept = static_cast<long>(c.source.size());
  for (long j = 0; j < kept; ++j) out[j] = value[source[j]];
  for (size_t i = 0; i < c.left_out.size(); ++i) out[c.twin[i]] += value[c.left_out[i]];
  return c.matrix;
}

bool ImplicitIntegrator::factor_iteration_matrix(const SparseMatrix& W, bool symmetric, double h,
                                                 bool preconditioner, bool refined) {
  IterationMatrix& m = matrices_[active_];
  m.h = h;
  m.refined = false;  // form_and_factor() says otherwise
  // A preconditioner (after the slot's first factorization, which chooses
  // the solver) leaves out the covered couplings where there are any.
  const SparseMatrix& without =
      preconditioner && m.solver.solver && symmetric ? factored_matrix(W) : W;
  m.covered_active = &without != &W;
  if (m.covered_active) {
    if (!m.covered.solver) {
      m.covered =
          make_linear_solver(implicit_.linear_solver, without, symmetric, SmallSystems::kByDensity);
      const auto start = WallClock::now();
      m.covered.solver->analyze(without);
      stats_.factorization_seconds += seconds_since(start);
      ++stats_.symbolic_analyses;
    }
    ++stats_.covered_coupling_factorizations;
  }
  const SparseMatrix& matrix = without;
  if (!m.solver.solver) {
    // Small symmetric systems with a constant mass matrix (particles) are
    // banded or grid-like: sparse unless their pattern is dense. Exact
    // trees, whose M(q) fills in along each branch, keep the dense chord
    // below 200 unknowns (see choose_newton_solve()).
    m.solver = make_linear_solver(
        implicit_.linear_solver, matrix, symmetric,
        caps_.constant_mass_matrix ? SmallSystems::kByDensity : SmallSystems::kDense);
    const auto start = WallClock::now();
    m.solver.solver->analyze(matrix);
    stats_.factorization_seconds += seconds_since(start);
    ++stats_.symbolic_analyses;
    stats_.iteration_matrix_nonzeros = W.nonZeros();
  }
  const auto start = WallClock::now();
  LinearSolver& solver = m.covered_active ? *m.covered.solver : *m.solver.solver;
  // Full Newton's factor without the covered couplings only preconditions
  // (GMRES on W, or on the exact Jacobian when finishing): where its
  // solves are in single precision, it is factored in single precision
  // too, in about two thirds of the time (BM_FactorizePreconditioner/32
  // against BM_Factorize/32). The solver goes back to double for good
  // where a float factor's first solve misses W by more than 1e-3.
  // Not the Krylov path's preconditioners: the 100x100 sheet at 1/60 to
  // 0.5 s took a halving in 4 of 6 runs with them in float, in none of 6
  // with only full Newton's (1.69x the time, paired), though cloth.yaml at
  // 1/60 for 2 s took 0.87x the time with them (12 starts).
  if (refined && m.covered_active && implicit_.single_precision_preconditioner) {
    const long before = solver.counters().single_precision_factorizations;
    m.factored = solver.factorize_preconditioner(matrix, factor_if_definite_);
    stats_.single_precision_factorizations +=
        solver.counters().single_precision_factorizations - before;
  } else {
    m.factored =
        factor_if_definite_ ? solver.factorize_if_definite(matrix) : solver.factorize(matrix);
  }
  last_factorization_seconds_ = seconds_since(start);
  stats_.factorization_seconds += last_factorization_seconds_;
  ++stats_.iteration_matrix_factorizations;
  switch (factor_reason_) {
    case FactorReason::kFirst:
      ++stats_.factorizations_first;
      break;
    case FactorReason::kCostModel:
      ++stats_.factorizations_cost_model;
      break;
    case FactorReason::kKrylovFailed:
      ++stats_.factorizations_krylov_failed;
      break;
    case FactorReason::kLadder:
      ++stats_.factorizations_ladder;
      break;
  }
  factor_reason_ = FactorReason::kLadder;
  krylov_excess_seconds_ = 0.0;
  refactor_due_ = refactor_failed_ = false;
  if (m.factored) stats_.factor_nonzeros = solver.factor_nonzeros();
  if (!newton_solve_chosen_) choose_newton_solve(matrix.rows());
  return m.factored;
}

bool ImplicitIntegrator::form_and_factor(double h, bool refined) {
  bool symmetric = false;
  const SparseMatrix& matrix = form_iteration_matrix(h, &symmetric);
  refined = refined && implicit_.refine_without_covered;
  const bool factored = factor_iteration_matrix(matrix, symmetric, h, refined, refined);
  IterationMatrix& m = matrices_[active_];
  m.refined = refined && m.covered_active;
  m.if_definite = factor_if_definite_;
  if (m.refined) {
    // W's pattern is fixed for the run: only the first copy allocates.
    if (m.whole.nonZeros() == matrix.nonZeros() && m.whole.rows() == matrix.rows()) {
      std::copy_n(matrix.valuePtr(), matrix.nonZeros(), m.whole.valuePtr());
    } else {
      m.whole = matrix;
    }
  }
  return factored;
}

void ImplicitIntegrator::choose_newton_solve(long unknowns) {
  const long velocities = dims_.nv;
  // GMRES needs only a factorization to precondition with, of any kind
  // (LL^T, LDL^T, LU). Small systems, solved dense, keep the direct path:
  // there a factorization costs about what a few Krylov products do.
  const std::string method = matrices_[active_].solver.solver->method();
  const bool sparse = method.rfind("dense", 0) != 0;
  const NewtonSolve asked = implicit_.newton_solve;
  newton_solve_chosen_ = true;
  krylov_ = false;
  if (implicit_.full_newton || asked == NewtonSolve::kFresh) {
    newton_solve_reason_ = "asked for: a fresh Jacobian and factorization every iteration";
  } else if (asked == NewtonSolve::kChord) {
    newton_solve_reason_ = "asked for";
  } else if (!reuse_enabled()) {
    newton_solve_reason_ = "no reuse asked for: fresh matrices every step attempt";
  } else if (!sparse) {
    newton_solve_reason_ = "the iteration matrix is solved by " + method +
                           " (small or dense: a direct solve is cheapest)";
  } else if (asked == NewtonSolve::kAuto && velocities <= kSmallSystemMaxSize) {
    // Small sparse systems (SmallSystems::kByDensity) keep the chord: its
    // reused sparse factor already makes the solves cheap, and the chord is
    // deterministic, where the Krylov path's cost model follows wall-clock
    // timings (two runs of one scene then differ within the tolerance).
    // The rope of models/rope.yaml (147 unknowns) under vie2 at accuracy
    // 1e-5 ends on the chord's rate test at the dense path's error
    // (2.9e-4 m against RK45 at 1e-10); on the Krylov path it ended 3-5x
    // further from it, where the extrapolation amplified its looser solves.
    // Counted in velocities: IE's matrix over (q, v) reduces to VIE's over v
    // once its identity block is eliminated (UMFPACK's symmetric strategy
    // does that), so the same rope is as small for both. Counted in IE's
    // unknowns (294), the rope went to the Krylov path, whose
    // refactorizations at the iterates carry transverse stiffness the rest
    // state's factor lacks (an L U of 2,900 entries against 1,200): the
    // precision report's IE runs took 1.1-2x their time at aa7add7.
    newton_solve_reason_ = "auto: small system (" + std::to_string(velocities) +
                           " velocities <= " + std::to_string(kSmallSystemMaxSize) + ", " +
                           std::to_string(unknowns) + " unknowns) on " + method +
                           ": the chord (deterministic; the factor is reused over many steps)";
  } else {
    krylov_ = true;
    newton_solve_reason_ =
        std::string(asked == NewtonSolve::kKrylov ? "asked for: " : "auto: ") +
        "sparse iteration matrix (" + method + "); GMRES on the exact Jacobian at each iterate " +
        "(matrix-free), the last factorization preconditions, refactored by measured cost" +
        (asked == NewtonSolve::kKrylov
             ? ""
             : "; each step starts with the chord or Krylov, whichever cost less lately");
  }
}

void ImplicitIntegrator::solve_iteration_matrix(const Eigen::VectorXd& rhs, Eigen::VectorXd* dx,
                                                bool preconditioner, bool refine) {
  const auto start = WallClock::now();
  if (structured_) {
    structured_->solve(rhs, *dx);
  } else {
    const IterationMatrix& m = matrices_[active_];
    LinearSolver& solver = current_solver();
    if (!preconditioner && m.refined && refine) {
      // Its preconditioner's solves count themselves; the products and
      // GMRES's own work are added here.
      const double inner = stats_.solve_seconds;
      solve_refined(rhs, dx);
      stats_.solve_seconds = inner + seconds_since(start);
      return;
    }
    if (preconditioner && implicit_.single_precision_preconditioner) {
      const LinearSolverCounters before = solver.counters();
      solver.solve_preconditioner(rhs, dx);
      const LinearSolverCounters& after = solver.counters();
      stats_.single_precision_solves +=
          after.single_precision_solves - before.single_precision_solves;
      stats_.single_precision_declined +=
          after.single_precision_declined - before.single_precision_declined;
      preconditioner_setup_seconds_ +=
          after.single_precision_setup_seconds - before.single_precision_setup_seconds;
    } else {
      solver.solve(rhs, dx);
    }
  }
  stats_.solve_seconds += seconds_since(start);
  ++stats_.linear_solves;
}

LinearSolver& ImplicitIntegrator::current_solver() {
  const IterationMatrix& m = matrices_[active_];
  return *(m.covered_active ? m.covered.solver : m.solver.solver);
}

bool ImplicitIntegrator::chord_starts_gmres(const Eigen::VectorXd& rhs) {
  if (structured_ || chord_solver_ == nullptr || !iteration_matrix_factored()) return false;
  const LinearSolver& solver = current_solver();
  if (&solver != chord_solver_ || solver.counters().factorizations != chord_factorizations_ ||
      rhs.size() != chord_residual_.size() || !(rhs + chord_residual_).isZero(0.0)) {
    return false;
  }
  const Eigen::VectorXd& scale = residual_scaling();
  return scale.size() == 0 || scale.maxCoeff() == scale.minCoeff();
}

void ImplicitIntegrator::solve_refined(const Eigen::VectorXd& rhs, Eigen::VectorXd* dx) {
  IterationMatrix& m = matrices_[active_];
  // W is symmetric (the covered couplings are left out of symmetric
  // matrices only): the product with its transpose reads each stored
  // column as a row, a dot product per entry instead of scattered writes.
  auto apply = [&m](const Eigen::VectorXd& p, Eigen::VectorXd* Wp) {
    transpose_product(m.whole, p, Wp);
  };
  auto precondition = [this](const Eigen::VectorXd& r, Eigen::VectorXd* z) {
    solve_iteration_matrix(r, z, true);
  };
  const GmresResult g = gmres(apply, precondition, rhs, Eigen::VectorXd(), kRefinedSolveTolerance,
                              implicit_.refined_solve_products, &refine_gmres_, dx,
                              [](int, double) { return false; });
  ++stats_.refined_solves;
  stats_.refined_solve_products += g.iterations;
  if (g.converged) return;
  // Where the sheet folds, the bend springs leave their stretch springs'
  // directions and the factor without them stops approximating W: W is
  // factored whole, as full Newton did before, and solves with it from now
  // on. Where that fails (W is not definite, though its factor without the
  // covered couplings was), that factor stays and GMRES's direction stands
  // for the search to judge.
  ++stats_.refined_solve_fallbacks;
  const bool if_definite = factor_if_definite_;
  factor_if_definite_ = m.if_definite;
  const bool whole = factor_iteration_matrix(m.whole, true, m.h);
  factor_if_definite_ = if_definite;
  if (whole) {
    solve_iteration_matrix(rhs, dx);
    return;
  }
  // The factor without the covered couplings is still the covered
  // solver's: it stays in use.
  m.covered_active = m.refined = m.factored = true;
}

void ImplicitIntegrator::initialize_newton(int unknowns) {
  const int nx = dims_.nx();
  newton_solve_chosen_ = structured_ != nullptr;
  krylov_ = refactor_due_ = refactor_first_ = refactor_failed_ = false;
  for (StartCost& c : start_costs_) c = StartCost{};
  last_explored_ = kKrylovStart;  // the first exploration tries the fresh start
  tension_positions_.resize(dims_.nq);
  estimate_tensions_ = tension_carried_ = false;
  solves_since_exploration_ = 0;
  exploration_interval_ = kStartExploration;
  last_best_ = kChordStart;
  explored_ = false;
  if (!structured_) newton_solve_reason_.clear();
  last_factorization_seconds_ = krylov_excess_seconds_ = last_jacobian_seconds_ = 0.0;
  solve_excess_seconds_ = last_refactor_seconds_ = product_seconds_ = 0.0;
  preconditioner_setup_seconds_ = 0.0;
  eisenstat_walker_solves_left_ = 0;
  finishing_products_ = finishing_weight_ = 0.0;
  residual_scale_.resize(0);
  second_derivative_t0_ = std::numeric_limits<double>::quiet_NaN();  // no estimate yet
  second_derivative_smooth_ = second_derivative_trusted_ = false;
  for (Eigen::VectorXd* v : {&x_big_, &x_half_, &x_small_, &dx_, &x_trial_, &second_derivative_,
                             &second_derivative_previous_, &x_guess_}) {
    v->resize(nx);
  }
  for (Eigen::VectorXd* v :
       {&r_, &dy_, &r_trial_, &chord_update_, &chord_residual_, &root_r_, &root_dy_}) {
    v->resize(unknowns);
  }
  root_x_.resize(nx);
  x_prev_.resize(nx);
  x_product_.resize(nx);
  r_product_.resize(unknowns);
  linearization_.resize(nx);
  predictor_qdot_.resize(dims_.nq);
  energy_state_.x = Eigen::VectorXd::Zero(nx);
  // NaN matches no state: nothing remembered yet, and no allocation later.
  for (RememberedEnergy& r : remembered_energy_) {
    r.x = Eigen::VectorXd::Constant(nx, std::numeric_limits<double>::quiet_NaN());
  }
  newton_tolerance_ = implicit_.newton_kappa * settings_.accuracy;
  extrapolated_h_ = extrapolated_correction_ = extrapolated_motion_ = 0.0;
  // Only where the step's energy change obeys the identity of
  // passes_energy_guard(): a passive scene with a constant mass matrix (the
  // step minimizes an incremental potential). With a configuration-dependent
  // M(q) (articulated bodies) the step's velocity-product terms trade O(h^2)
  // energy either way as well.
  // Free rigid bodies (quaternions) have a constant M but velocity
  // products too.
  guard_energy_ = implicit_.energy_guard && caps_.has_energy && caps_.passive &&
                  caps_.constant_mass_matrix && caps_.identity_velocity_map;
  if (guard_energy_) {
    guard_jacobians_ = system_.jacobian_pattern();
    guard_q_.resize(dims_.nq);
    guard_v_.resize(dims_.nv);
    guard_z_ = Eigen::VectorXd::Zero(dims_.nz);
  }
  jacobians_valid_ = false;
  invalidate_factorization();
  for (auto& m : matrices_) m.h = 0.0;
  active_ = 0;
  jacobian_step_t_ = jacobian_step_h_ = std::numeric_limits<double>::quiet_NaN();
}

void ImplicitIntegrator::compute_jacobian_and_factor(double t, const Eigen::VectorXd& x, double h) {
  compute_jacobian(t, x, h);
  jacobian_step_t_ = t;
  jacobian_step_h_ = h;
  form_and_factor(h);
}

ImplicitIntegrator::Refresh ImplicitIntegrator::refresh_matrices(double t, const Eigen::VectorXd& x,
                                                                 double h, int trial) {
  // The reuse ladder (DESIGN.md section 2, Drake's MaybeFreshenMatrices),
  // without its two no-ops: refactoring the last Jacobian at the h it was
  // factored with, and recomputing a Jacobian already evaluated for this very
  // step start (and h, where the Jacobian depends on it), reproduce the
  // matrix that just failed.
  const bool fresh =
      jacobian_step_t_ == t && (!jacobian_depends_on_step() || jacobian_step_h_ == h);
  if (!reuse_enabled() || !jacobians_valid_) {
    compute_jacobian_and_factor(t, x, h);
    return Refresh::kProceed;
  }
  if (!iteration_matrix_factored() && trial == 1) {
    form_and_factor(h);
    return Refresh::kProceed;
  }
  switch (trial) {
    case 1:  // reuse the last factorization, even from another h...
      // ...within a factor of kReuseStepRatio. Departure from Drake, which
      // reuses it from any h: formed for a much larger h, the matrix scales
      // the stiff directions' updates down by about (h / h_f)^2, the
      // iteration crawls there while soft directions converge, and its rate
      // test can pass the step unconverged (an 8x8 cloth: a matrix from
      // h = 1e-3 at h = 1.4e-5 left a velocity residual of 1e-3 m/s with the
      // Newton tolerance at 5e-5). Refactoring from the last Jacobian, as
      // Hairer's codes do whenever h changes, is the second rung anyway.
      if (formed_far_from(h)) {
        form_and_factor(h);
      }
      return Refresh::kProceed;
    case 2:  // refactor with the current h from the last Jacobian
      if (matrices_[active_].h != h) {
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

bool ImplicitIntegrator::newton(double t0, double h, const Eigen::VectorXd& x0,
                                const Eigen::VectorXd& guess, int trial, Eigen::VectorXd* x,
                                bool rescue, bool last) {
  const double tf = t0 + h;
  const int offset = unknowns_offset();
  const int n = static_cast<int>(r_.size());
  *x = guess;
  complete_iterate(h, x0, x);
  // The last rung before shrinking h is a full Newton iteration: a step that
  // starts where the linearization is degenerate (a flat membrane at rest has
  // no transverse stiffness) converges once the Jacobian follows the iterate.
  const bool full_newton = implicit_.full_newton || trial == kFullNewtonTrial;
  // The Krylov path (trial 1 once chosen) applies the exact Jacobian at
  // every iterate matrix-free; it only needs a factorization to
  // precondition with, and one formed for a step within kReuseStepRatio of
  // h.
  const bool krylov = trial == kKrylovTrial && !implicit_.full_newton;
  const bool structured = trial == kStructuredTrial;
  // Full Newton searches on G wherever its last rung does: a fresh matrix
  // per iterate costs more than G's damping evaluation.
  const bool search_on_g = !krylov && potential_search(full_newton ? kFullNewtonTrial : trial);
  tension_positions_ = x0.segment(0, dims_.nq);
  tension_carried_ = false;
  // Only at fixed steps (large ones: under error control a step's
  // transverse motion, and so the second-order stretch the estimate leaves
  // out, is small) and where the search is on G, which keeps the iteration
  // a descent on G whatever the matrix. With the estimate on every direct
  // rung (searches on |r| too), models/box_on_rope.yaml took a halving and
  // a 3-node rope under error control a path to an energy-guard rejection.
  estimate_tensions_ = implicit_.tension_estimate && settings_.fixed_step && search_on_g;
  if (structured) {
    // factored at every iterate below
  } else if (krylov) {
    if (!iteration_matrix_factored() || formed_far_from(h)) refactor_first_ = true;
    // The cost model looks ahead at a solve's start too: where the last
    // solve's Krylov products beyond the first cost more than
    // kStartRefactorShare of a factorization, the preconditioner is
    // refactored now. The matrix drifts from step to step (a falling sheet
    // turns), so the old factorization would cost this solve more still, and
    // one made now serves every iteration of the step, where the rule above
    // refactors only once the excess has been paid, part-way through.
    if (solve_excess_seconds_ > kStartRefactorShare * last_factorization_seconds_) {
      refactor_due_ = true;
    }
    solve_excess_seconds_ = 0.0;
    fresh_solve_products_ = 1.0;
  } else if (!full_newton) {
    if (refresh_matrices(t0, x0, h, trial) != Refresh::kProceed) return false;
    if (!iteration_matrix_factored()) return false;
  }
  ++stats_.newton_trials;
  solve_tolerance_ = newton_tolerance_;
  begin_newton(t0, h, x0);
  residual(tf, h, x0, *x, &r_);
  double r_merit = merit(r_);
  // The merits of the last accepted iterates, newest first (Krylov path).
  std::array<double, kMeritMemory> recent_merits;
  recent_merits.fill(0.0);
  double last_norm = std::numeric_limits<double>::infinity();
  // The last rung converges (at least linearly with the definite clamp) but
  // may need more iterations than a fresh modified Newton; giving it three
  // times the budget is cheaper than halving the step. The Krylov path,
  // whose iterations cost a few solves each, gets five times: on a stiff
  // sheet (k = 1e6) folding at h = 1/60 its iteration converges linearly
  // but surely, and the solves that converge within three times took 4-30
  // iterations, evenly spread. cloth_stiff.yaml at 1/60 over 2 s took 4-5
  // halvings and 3,000 Newton iterations with five times, 39-53 and
  // 3,700-4,200 with three, and 0.57x the time (two runs each, in
  // alternation); cloth.yaml and the 60x60 and 100x100 sheets, whose solves
  // rarely fail, took equal times.
  const int budget = krylov   ? kKrylovIterationFactor * implicit_.max_newton_iterations
                     : rescue ? kRescueIterationFactor * implicit_.max_newton_iterations
                     : trial == kFullNewtonTrial || structured ? 3 * implicit_.max_newton_iterations
                                                               : implicit_.max_newton_iterations;
  // Full Newton as the last rung before the step is halved may end up
  // circling the root: the rescue of a folding step of cloth.yaml at a
  // fixed 1/60 held the clamped iteration's updates at 2-5 tolerances and
  // its residual at 7-40 for 25 iterations before it converged at the
  // 34th. So past its budget it goes on while its last iterate was near
  // the root, by both measures (kChordTestGate, kNearRootResidual); far
  // from it (the first step of a flat sheet of k = 1e9, residuals of 1e6
  // tolerances, and the k = 1e6 sheet's clamped iterations crawling at
  // 1e5) the budget ends it as before. Measured on cloth.yaml at 1/60 for
  // 2 s (30 starts each, bench/ensemble.py): halvings in 3-5 runs of 30
  // with the budget alone, in none extended, at equal time.
  const bool extend = implicit_.extend_near_root && last && full_newton && !structured;
  const int max_iterations =
      extend ? std::max(budget, kExtendedFactor * implicit_.max_newton_iterations) : budget;
  bool near_root = false;  // the last iterate, as the extension means it
  // Whether the iteration after i may run (the last one judges its iterate
  // as it is).
  auto another_iteration = [&](int i) {
    return i + 1 < budget || (i + 1 < max_iterations && near_root);
  };
  // The forcing term, the linear solve's relative tolerance.
  // - Recursive path: Eisenstat-Walker (their choice 2, with Kelley's
  //   safeguards). The relative tolerance follows the nonlinear residual's
  //   decrease, so early iterations solve loosely and the last ones well.
  //   Its preconditioner is exact but for the velocity products, so a
  //   solve costs about two products whatever the tolerance.
  // - Krylov path: constant. Choice 2 reads the first iteration's large
  //   drop (the predictor's error is mostly linear) as fast convergence and
  //   asks the second solve for 1e-3. That exact direction often lowered
  //   |r| less than a loose one, where the sheet buckles, and paid 10-25
  //   products for it. The iteration is ended by the residual and chord
  //   tests, which do not depend on the forcing, so nothing needs a tight
  //   last solve. A constant 0.2 took cloth.yaml at a fixed 1/60 over 2 s
  //   from 189-215 factorizations and 3,200-4,000 products to 127-154 and
  //   2,200-2,800, at equal Newton iterations (five runs each).
  // - Krylov path after a failed Newton solve: Eisenstat-Walker again for
  //   the next kEisenstatWalkerSolves Newton solves on this path (chord
  //   starts under auto do not count them down). Where solves fail (the k = 1e6 sheet's
  //   residual cycling as it folds), nearly exact directions fail less:
  //   cloth_stiff.yaml over 1 s took 26-45 halvings with the constant alone
  //   and 15-21 with choice 2 throughout, in equal time (six runs each); on
  //   cloth.yaml, whose solves rarely fail, the constant keeps its gain.
  const bool eisenstat_walker = structured || (krylov && eisenstat_walker_solves_left_ > 0);
  if (krylov && eisenstat_walker) {
    --eisenstat_walker_solves_left_;
    ++stats_.krylov_eisenstat_walker_solves;
  }
  const double ceiling =
      krylov && !eisenstat_walker ? implicit_.krylov_forcing : implicit_.max_forcing;
  double forcing = ceiling;
  double last_r_norm = 0.0;
  // Full Newton finishes with GMRES (below): whether the next iteration
  // does, whether finishing failed in this solve (no more of it then), and
  // the size of the last finishing update.
  bool finishing = false, finishing_failed = false;
  double finishing_update = 0.0;
  int stalled_updates = 0;  // updates in a row cut below the stall threshold
  bool polished = false;    // the tolerance cut for the energy guard (below)
  // Full Newton factors the exact Hessian of G near the root
  // (ImplicitSettings::exact_hessian_near_root). The clamped matrix on the
  // tension estimate converges only linearly there, where the compressed
  // springs' negative transverse stiffness (which it drops) is what a
  // folding sheet's curvature is made of: on cloth_stiff.yaml solves ran
  // 10-25 iterations at updates of 1-3 tolerances, contracting at rates
  // near 1. A root of a passive step is a minimizer of G, so near it the
  // exact Hessian is positive definite, a Cholesky LL^T proves it, and
  // Newton converges quadratically. Where the LL^T fails (the iterate is
  // not yet in the minimizer's basin), or the search cuts the exact
  // direction, the solve keeps the clamped matrix. Not on the last rung
  // before a halving: on cloth.yaml (k = 1e3) under --newton-solve fresh
  // the exact Hessian took 2.7x the halvings (8 starts each), and on the
  // rescue rung a successful but misleading exact direction ended an
  // extension near the root. search_on_g: descent on G is what makes a
  // definite matrix's direction safe.
  bool exact_allowed =
      implicit_.exact_hessian_near_root && full_newton && !structured && !last && search_on_g;
  bool exact_next = false;  // the next iteration tries the exact Hessian
  bool exact_used = false;  // this iteration's matrix is the exact Hessian
  bool near_root_finish = false;  // finishing begun by the chord's update (below)
  for (int i = 0; i < max_iterations; ++i) {
    if (i >= budget) {
      if (!near_root) return false;
      if (i == budget) ++stats_.last_rung_extensions;
    }
    const bool finishing_now = finishing;
    exact_used = false;
    if (structured) {
      if (!factor_structured(*x, h)) return false;
    } else if (full_newton && !finishing_now) {
      exact_used = exact_next && factor_exact_hessian(tf, h, x0, *x);
      if (exact_next && !exact_used) exact_allowed = false;
      if (!exact_used) {
        compute_jacobian_at_iterate(tf, h, x0, *x);
        if (!form_and_factor(h, true)) return false;
      }
    }
    ++stats_.newton_raphson_iterations;
    if (krylov || structured) {
      const double r_norm = std::sqrt(r_merit);
      if (eisenstat_walker && i > 0 && last_r_norm > 0.0) {
        double ew = 0.9 * (r_norm / last_r_norm) * (r_norm / last_r_norm);
        const double previous = 0.9 * forcing * forcing;
        if (previous > 0.1) ew = std::max(ew, previous);
        forcing = std::min(ceiling, ew);
        // No oversolving: a linear residual below half the Newton
        // tolerance cannot change the outcome of the convergence test. (A
        // constant forcing, and the first iteration's, is the ceiling.)
        const double residual_size = residual_norm(r_);
        if (std::isfinite(residual_size) && residual_size > 0.0) {
          forcing = std::min(ceiling, std::max(forcing, 0.5 * solve_tolerance_ / residual_size));
        }
      }
      last_r_norm = r_norm;
    }
    r_ = -r_;
    if (structured) {
      double seconds = 0.0;
      newton_gmres(tf, h, x0, *x, r_, forcing, 0.0, &dy_, &seconds);
    } else if (krylov) {
      if (!krylov_direction(tf, h, x0, *x, r_, forcing, !eisenstat_walker, &dy_)) return false;
    } else if (finishing_now) {
      if (near_root_finish) ++stats_.fresh_near_root_finishes;
      near_root_finish = false;
      // A direction GMRES left short of its forcing is still judged by the
      // search; the next iteration refactors.
      if (!finishing_direction(tf, h, x0, *x, r_, &dy_)) {
        finishing = false;
        finishing_failed = true;
      }
    } else {
      solve_iteration_matrix(r_, &dy_);
    }
    // Line search. Where the method has a potential G (VIE's incremental
    // potential), the Newton direction of an SPD iteration matrix descends
    // G whatever approximations it holds, so the search heads for a
    // minimizer of G and never climbs to a saddle, a spurious root of the
    // step equations. Otherwise the residual norm is the merit. The full
    // step is taken whenever it qualifies; the trial residual is then the
    // next iteration's, at no extra cost.
    // An update at the level of round-off cannot decrease any merit
    // measurably; it is taken, and the convergence test calls it zero. Nor
    // can an update below the Newton tolerance lead the iteration astray;
    // near round-off its merit is noise, and a search would fail a
    // converged iterate. Such updates are taken without a search (below the
    // solve's tolerance, widened or not: see use_step_error_tolerance()).
    auto at_round_off = [&] {
      for (int k = 0; k < n; ++k) {
        if (std::abs(dy_[k]) > std::max(std::abs((*x)[offset + k]), 1.0) * kZeroUpdate)
          return false;
      }
      return true;
    };
    const bool take_as_is = dy_.lpNorm<Eigen::Infinity>() <= solve_tolerance_ || at_round_off();
    // The Krylov path is globalized from its first iteration on the
    // residual merit: an inexact Newton direction with forcing < 1 on the
    // true Jacobian descends it (Eisenstat & Walker 1994).
    const bool use_potential = search_on_g;
    double g_current = 0.0, slope = 0.0;
    if (use_potential) {
      // G itself is only needed by a search.
      if (!take_as_is) {
        g_current = potential(tf, x0, *x, h, true,
                              full_newton && !finishing_now && !structured &&
                                  implicit_.jacobian == JacobianScheme::kAnalytic);
      }
      slope = -r_.dot(dy_);  // r_ holds minus the residual = minus grad G
    }
    const bool descend_potential = use_potential && slope < 0.0;
    double alpha = 1.0;
    bool retry = false;
    for (int backtrack = 0;; ++backtrack) {
      x_trial_ = *x;
      x_trial_.segment(offset, n) += alpha * dy_;
      complete_iterate(h, x0, &x_trial_);
      residual(tf, h, x0, x_trial_, &r_trial_);
      const double trial_merit = merit(r_trial_);
      bool accept = std::isfinite(trial_merit);
      if (take_as_is) {
        // accept as is
      } else if (accept && descend_potential) {
        const double g_trial = potential(tf, x0, x_trial_, h, false);
        // Near the solution G changes by less than its own round-off; there
        // a G that did not measurably rise and a smaller residual decide.
        const double roundoff = potential_roundoff(g_current);
        accept = g_trial <= g_current + 1e-4 * alpha * slope ||
                 (g_trial <= g_current + roundoff && trial_merit < r_merit);
      } else if (accept && krylov) {
        // Non-monotone: the residual may rise above the current one as long
        // as it falls below the largest of the last few. Where the sheet
        // buckles, the full Newton step that leads to the root often raises
        // |r| first; a monotone search cut it to alpha = 1/64 for 20
        // iterations. Measured on cloth.yaml at a fixed 1/60 for 2 s (three
        // runs each, the machine shared): 8-12 halvings and 1,093-1,152
        // Newton iterations monotone, 1-4 and 952-1,054 with a memory of 3
        // (now kMeritMemory, which says why it is longer).
        const double reference =
            std::max(r_merit, *std::max_element(recent_merits.begin(), recent_merits.end()));
        accept = trial_merit <= (1.0 - 1e-4 * alpha) * reference;
      } else if (accept) {
        accept = trial_merit <= (1.0 - 1e-4 * alpha) * r_merit;
      }
      if (accept) {
        std::copy_backward(recent_merits.begin(), recent_merits.end() - 1, recent_merits.end());
        recent_merits[0] = r_merit;
        r_merit = trial_merit;
        break;
      }
      if (backtrack == kMaxBacktracks) {
        // A finishing direction that does not descend: the iteration is
        // repeated at this iterate with a new factorization.
        if (finishing_now) {
          finishing = false;
          finishing_failed = retry = true;
          break;
        }
        // A Krylov direction that does not descend came from a solve
        // against an old preconditioner that missed its tolerance: the
        // iteration is repeated with a fresh factorization at this iterate.
        if (!krylov || preconditioner_fresh_) return false;
        refactor_failed_ = retry = true;
        break;
      }
      alpha *= 0.5;
      ++stats_.line_search_backtracks;
    }
    if (retry) {
      r_ = -r_;  // back to the residual at the unchanged iterate
      continue;
    }
    // A Krylov iteration whose updates the search keeps cutting to a small
    // fraction has stalled: its directions no longer lead to a root (the
    // first step of a flat sheet at rest, whose membrane has no transverse
    // stiffness: on cloth_stiff.yaml 50 iterations at alpha = 1/256 while
    // the residual grew, before full Newton on the estimate converged in
    // 8). The ladder's next rung, or a halved step, takes over.
    if (krylov) {
      stalled_updates = alpha < kStalledStep ? stalled_updates + 1 : 0;
      if (stalled_updates == kStalledUpdates) {
        ++stats_.krylov_stalled_solves;
        return false;
      }
    } else if (!full_newton && !structured && !last && implicit_.direct_stall_updates > 0) {
      // The same for a direct trial that a rung follows: its old matrix
      // misleads it (ImplicitSettings::direct_stall_updates).
      stalled_updates = alpha < kDirectStalledStep ? stalled_updates + 1 : 0;
      if (stalled_updates == implicit_.direct_stall_updates) {
        ++stats_.direct_stalled_trials;
        return false;
      }
    }
    dx_ = x_trial_ - *x;
    if (estimate_tensions_) {
      tension_positions_ = x->segment(0, dims_.nq);
      tension_carried_ = true;
    }
    x->swap(x_trial_);
    r_.swap(r_trial_);
    const double norm = state_change_norm(dx_);
    // The residual itself: with W >= M the error of the iterate's
    // unknowns is at most its residual in their units (r_i / m_i; in the
    // generic Newton form, M^-1 times the mass-matrix form's residual, the
    // bound holds in the M-norm). The Krylov path has always ended on it;
    // on the direct paths too it ends the iteration as soon as it holds,
    // where the rate test (from the third iteration on) would pay two more
    // updates. Measured on the 8x8 cloth under error control at accuracy
    // 1e-5: 1.6 Newton iterations per solve instead of 3.0, 0.65x the run
    // time, the same error against RK45 at 1e-11 (to 0.5%, accuracies 1e-3
    // to 1e-5); the 8x8 stiff cloth (k = 1e6) at 1e-5 is 0.87x the time
    // at 1.38x the error (1.66e-4 against 1.20e-4). On the direct paths two
    // cases go on to the rate test:
    // - the extrapolated methods: 2 x_small - x_big amplifies the errors of
    //   its three solves, and their tolerance rule
    //   (extrapolation_newton_tolerance) assumes solves the rate test ended
    //   (under error control at 1e-5 the 8x8 cloth's vie2 error rose tenfold
    //   with the residual test);
    // - an iterate whose energy rose beyond round-off: the energy guard then
    //   judges the root by an identity that holds at the root itself.
    const double residual_size = residual_norm(r_);
    bool residual_converged =
        residual_size <= solve_tolerance_ &&
        (krylov || (!implicit_.extrapolate && energy_within_round_off(x0, *x)));
    // The chord test (Krylov path). The residual bounds the error only in
    // the mass's units, r_i / m_i: where the Newton matrix is hundreds of
    // times M (a cloth's stretch springs at h = 1/60: h^2 k / m = 700) it
    // overstates the error as much. The last factorization's solve of the
    // new residual is the chord's next update, the iterate's error as far
    // as that matrix knows it: one preconditioner solve, where another
    // Newton iteration costs a GMRES solve and the residuals of its search.
    // Tried only after an update within kChordTestGate of the tolerance: on
    // cloth.yaml at a fixed 1/60 for 2 s, 89 of the 98 tests that passed
    // came after such updates, and 9 of the 269 after larger ones.
    // Not with a factorization GMRES just failed with, and scaled where it
    // was formed for a larger step: its stiff directions, h^2 K, then
    // understate the current matrix's error by up to (h_f / h)^2.
    const double h_f = matrices_[active_].h;
    const bool chord_usable = krylov && !refactor_failed_;
    const double chord_scale = h_f > h ? (h_f / h) * (h_f / h) : 1.0;
    const double update_size = dx_.segment(offset, n).lpNorm<Eigen::Infinity>();
    // Solved at most once per iterate (a NaN update never agrees).
    bool chord_solved = false;
    auto chord_within = [&](double tolerances) {
      return chord_scale * chord_update_.lpNorm<Eigen::Infinity>() <= tolerances * solve_tolerance_;
    };
    auto chord_agrees = [&] {
      // Minus the chord's update: an estimate, solved with the factor as it
      // is where it leaves the covered couplings out, as on the Krylov path
      // (refined, it cost 3-4 products more; cloth_stiff.yaml over 12
      // starts: 0.96 of the time unrefined, the same factorization and
      // Newton counts, iterates 10-18 tolerances from the root at most
      // against 14-22, --verify-roots, 3 starts each), and as GMRES's
      // preconditioner solves are: in single precision where those are
      // (a float factor has no double one to solve with; its first solve
      // missed by a relative residual of at most 1e-3, in an estimate
      // judged against 1 or 10 tolerances).
      if (!chord_solved) {
        solve_iteration_matrix(r_, &chord_update_, true, false);
        ++stats_.chord_solves;
        chord_residual_ = r_;
        chord_solver_ = &current_solver();
        chord_factorizations_ = chord_solver_->counters().factorizations;
      }
      chord_solved = true;
      return chord_within(1.0);
    };
    // The update test (Krylov path): a full update that met its forcing and
    // is within the tolerance ends the solve, as a finishing update does
    // (below) and as the rate test's first update does with no rate: the
    // iterate it started from was that far from the root, to first order,
    // and Newton on the exact Jacobian brought it closer. Where a sheet
    // folds, the iteration otherwise circled its nearly singular root:
    // updates within the tolerance alternated with ones of 2-4 tolerances
    // that the search cut to 1/8-1/16, and neither the residual nor the
    // chord test passed for 10-20 more iterations (the 100x100 sheet at
    // 1/60). That sheet to 0.5 s at h = 0.0166667 took a paired median of
    // 0.64 of the time without the test (6 starts, 170 factorizations
    // instead of 229), at h = 1/60 to 16 digits 0.93 (7 starts);
    // cloth.yaml and cloth_stiff.yaml, where it ends few solves, equal
    // times. With --verify-roots on cloth.yaml at a fixed 1/60 for 2 s
    // (4 starts), the iterates it accepted lay a median 0.69 tolerances
    // from the root (90% within 6.4), those of the chord test 0.84 (90%
    // within 3.9): an estimate, as the others are.
    // (chord_usable: the Krylov solve met its forcing.)
    if (chord_usable && !residual_converged && alpha == 1.0 && update_size <= solve_tolerance_ &&
        energy_within_round_off(x0, *x)) {
      residual_converged = true;
      ++stats_.krylov_update_convergences;
    }
    if (chord_usable && !residual_converged && update_size <= kChordTestGate * solve_tolerance_ &&
        chord_agrees()) {
      residual_converged = true;
      ++stats_.krylov_chord_convergences;
    }
    // Full Newton has the same test for free but one solve: the matrix
    // just factored at the previous iterate gives the next update, where
    // the rate test needs another iteration (a Jacobian, a factorization
    // and a search) to measure it. Not for the extrapolated methods, nor
    // where the iterate gained energy (as the residual test above).
    // --newton-solve fresh on cloth_stiff.yaml at 1/60 for 2 s: 705
    // Newton iterations instead of 823 (cloth.yaml: 664 instead of 749).
    near_root = update_size <= kChordTestGate * solve_tolerance_ &&
                residual_size <= kNearRootResidual * solve_tolerance_;
    if (exact_used && alpha < 1.0) exact_allowed = false;
    exact_next = exact_allowed && update_size <= kExactHessianGate * solve_tolerance_;
    if (finishing_now) {
      // A full update of (inexact) Newton on the exact Jacobian within the
      // tolerance leaves an error of about the forcing term times it, plus
      // its square: converged, as the rate test's first update is with no
      // rate (check_newton_convergence). Not where the energy rose (as the
      // residual test). At a forcing of 0.2 one step of a 16x16 stiff sheet
      // so ended 1.05 tolerances from a solve 100 times tighter; at 0.1,
      // every step within 0.5 of one (FullNewtonFinishesOnTheExact-
      // JacobianAtTheSameSteps), in equal time on cloth_stiff.yaml.
      if (!residual_converged && finishing && alpha == 1.0 && update_size <= solve_tolerance_ &&
          energy_within_round_off(x0, *x)) {
        residual_converged = true;
        ++stats_.fresh_finishing_convergences;
      }
      // Where the exact direction was cut or did not contract, the
      // clamped matrix at a new iterate does better: back to refactoring.
      // Where it was cut hard (or not accepted at all, above) it points
      // away from the root: the exact Jacobian is indefinite where a sheet
      // of soft springs folds, and on cloth.yaml's rescues such
      // directions, taken at alpha = 1/16 to 1/256 after every refactored
      // iteration, spent the budget: 3 runs of 12 took a halving (5 of 10
      // when a search that failed also failed the solve), none of 12 once
      // they end finishing for the solve. On cloth_stiff.yaml finishing
      // often resumes after a direction that merely contracted too little,
      // and pays.
      if (alpha < 1.0 || update_size > kFinishingContraction * finishing_update) {
        finishing = false;
        if (alpha < kFinishingCut) finishing_failed = true;
      }
      finishing_update = update_size;
      // No rate across finishing updates and the refactored ones after.
      last_norm = std::numeric_limits<double>::infinity();
      if (!residual_converged) continue;
    } else if (full_newton && !structured && !residual_converged && !implicit_.extrapolate &&
               update_size <= kChordTestGate * solve_tolerance_ &&
               energy_within_round_off(x0, *x)) {
      ++stats_.fresh_chord_tests;
      if (chord_agrees()) {
        residual_converged = true;
        ++stats_.fresh_chord_convergences;
      } else if (implicit_.finish_near_root && krylov_ && !finishing_failed &&
                 implicit_.finishing_share > 0.0 && chord_within(kFinishingChordGate)) {
        // The chord's update within kFinishingChordGate tolerances: the
        // iterate is nearly converged (the chord, on the clamped matrix
        // with estimated tensions, overstates the error there: on
        // cloth_stiff.yaml after an update of 2-3 tolerances it said
        // 1.1-3.6 tolerances where the exact Hessian's next update was
        // 0.15-0.33). GMRES on the exact Jacobian against the
        // factorization just made finishes it in a few products, where the
        // exact Hessian costs a Jacobian, an assembly and a factorization;
        // so finishing comes first there, whatever the cost model says
        // (cloth_stiff.yaml, 10 starts: 0.85x the time, 415 factorizations
        // instead of 484; cloth.yaml, which rarely starts with full Newton,
        // equal times). Gates of 3 and 30 took 1.02x and 0.97x the time of
        // 10 (8 starts each, within the noise); with no gate, 1.25x the
        // time and 700 Newton iterations instead of 485: far from the
        // root, finishing's linear rate loses to the exact Hessian's
        // quadratic one.
        near_root_finish = true;
        exact_next = false;
        finishing = true;
        finishing_update = std::numeric_limits<double>::infinity();
      } else if (!exact_next && krylov_ && !finishing_failed && finishing_pays()) {
        // The chord's update, within kChordTestGate of the tolerance, says
        // the iterate is near the root, but not near enough: there full
        // Newton's matrix (compressed springs clamped, the damping's
        // derivative through the spring directions dropped, the tension
        // estimated) makes the iteration converge linearly, at rates of
        // 0.7-0.9 on cloth_stiff.yaml, a factorization per iteration. The
        // exact Jacobian applied by GMRES and preconditioned by the
        // factorization just made (the Krylov path's operator) finishes
        // the solve in a few products per iteration instead.
        finishing = true;
        finishing_update = std::numeric_limits<double>::infinity();
      }
    }
    if (alpha < 1.0 && !residual_converged) {
      // A damped step says nothing about the rate of the undamped
      // iteration: the next full update is measured against the last full
      // one (or, with none yet, against the tolerance alone).
      continue;
    }
    if (!residual_converged) {
      const Convergence c = check_newton_convergence(i, *x, dx_, norm, last_norm);
      // A search that decreased the potential made progress whatever the
      // update sizes say (a descent method on G cannot diverge); only the
      // iteration budget ends it.
      if (c == Convergence::kDiverged && !descend_potential && !krylov) return false;
      last_norm = norm;
      if (c != Convergence::kConverged) continue;
      // On the Krylov path the rate test alone is a poor guide: inexact
      // updates shrink with the forcing term as well as by contraction.
      // Under Eisenstat-Walker forcing (which tightened as |r| fell) it
      // accepted steps of a falling 24x24 cloth at h = 1/60 40 times the
      // tolerance from the root; under the constant forcing, 7.3-29 times.
      // The chord's estimate must agree (RateTestNeedsTheChordsAgreement:
      // 2.7-7.0 times, an estimate still). Ending only on the residual or on an
      // update within the tolerance gave 1.3-1.7 at 15-25% more Newton
      // iterations on cloth.yaml at a fixed 1/60 (under Eisenstat-Walker
      // forcing, as what follows); without the rate test,
      // the chord and residual tests alone took 650-750 Newton iterations
      // and 3-6 halvings there (two runs), against 540-630 and 0-1 (three).
      if (krylov && !at_round_off() && !(chord_usable && chord_agrees())) {
        ++stats_.krylov_rate_test_vetoes;
        continue;
      }
    }
    // A tolerance widened by the step's own error (use_step_error_tolerance)
    // is narrowed back to kappa * accuracy for the rest of the solve where
    // the iterate it accepted gained energy beyond round-off: the energy
    // guard's identity holds at the root, not a widened step's distance
    // from it (the 16x16 stiff cloth at 1/60 had 44 steps rejected by the
    // guard otherwise).
    // On the last iteration the guard judges the iterate as it is (halving
    // the step would cost more than its judgement).
    const double accuracy_tolerance = implicit_.newton_kappa * settings_.accuracy;
    if (solve_tolerance_ > accuracy_tolerance && another_iteration(i) &&
        !energy_within_round_off(x0, *x)) {
      solve_tolerance_ = accuracy_tolerance;
      ++stats_.newton_tolerance_narrowed;
      // No rate across the narrowing: the next update is measured against
      // the tolerance alone (as after a damped step).
      last_norm = std::numeric_limits<double>::infinity();
      continue;
    }
    // Nor is an iterate within the tolerance the root: its distance from
    // the root moves the energy to first order (v.M dv), which on a stiff
    // undamped spring exceeds the O(h^2) gain the guard allows a genuine
    // root. So an iterate that gained energy beyond round-off is polished
    // to kGuardPolish of the tolerance before it is judged. The chord's
    // iterates used to approach the root from the step's start, v = v_n,
    // and the error they kept lost energy; from the predictor and step
    // doubling's corrected guesses they also approach it from beyond (a
    // 3-node undamped rope at accuracy 1e-3: 11 steps of 2,928 rejected
    // unpolished, none polished).
    if (!polished && guard_energy_ && !energy_guard_suspended_ && another_iteration(i) &&
        !energy_within_round_off(x0, *x)) {
      polished = true;
      solve_tolerance_ *= kGuardPolish;
      ++stats_.newton_tolerance_narrowed;
      last_norm = std::numeric_limits<double>::infinity();
      continue;
    }
    if (!passes_energy_guard(tf, h, x0, *x)) return false;
    if (implicit_.verify_roots) check_root(tf, h, x0, *x);
    const double ratio = residual_size / solve_tolerance_;
    double& largest = stats_.largest_final_residual_ratio;
    if (std::isfinite(ratio) && !(ratio <= largest)) largest = ratio;  // NaN: none yet
    return true;
  }
  return false;
}

double ImplicitIntegrator::energy_gain(const Eigen::VectorXd& x0, const Eigen::VectorXd& x,
                                       double* allowance) {
  const double before = guard_energy(x0);
  const double after = guard_energy(x);
  // Round-off of the energy sums and the Newton tolerance's share.
  *allowance = 1e-8 * (std::abs(before) + std::abs(after)) + 1e-12;
  return after - before;
}

bool ImplicitIntegrator::energy_within_round_off(const Eigen::VectorXd& x0,
                                                 const Eigen::VectorXd& x) {
  if (!guard_energy_ || energy_guard_suspended_) return true;
  double allowance = 0.0;
  return energy_gain(x0, x, &allowance) <= allowance;
}

double ImplicitIntegrator::guard_energy(const Eigen::VectorXd& x) {
  // Comparing states costs a fraction of an energy evaluation (which visits
  // every element); about half the guard's evaluations are repeats.
  for (const RememberedEnergy& r : remembered_energy_) {
    if (r.x.size() == x.size() && r.x == x) return r.value;
  }
  energy_state_.x = x;
  RememberedEnergy& slot = remembered_energy_[next_remembered_];
  next_remembered_ = 1 - next_remembered_;
  slot.value = system_.energy(*data_, energy_state_);
  slot.x = x;
  return slot.value;
}

double ImplicitIntegrator::negative_curvature(double t, const Eigen::VectorXd& q,
                                              const Eigen::VectorXd& dq) {
  // At v = 0 the damping forces (linear in v) have no q-derivative, so the
  // exact dF/dq is minus the potential's Hessian.
  JacobianRequest exact;
  exact.complete = true;
  guard_v_.setZero(dims_.nv);
  system_.force_jacobians(*data_, t, q, guard_v_, guard_z_, exact, &guard_jacobians_);
  return dq.dot(guard_jacobians_.dF_dq * dq);
}

bool ImplicitIntegrator::incremental_hessian_definite(double t, double h,
                                                      const Eigen::VectorXd& x) {
  // The Hessian of the step's incremental potential
  // G(v) = 1/2 |v - v_n|_M^2 + Phi(q_n + h v) - h/2 v^T D v, exact (no
  // clamped transverse stiffness): M - h D - h^2 K with K = -Hess Phi from
  // the Jacobian at v = 0 and D = dF/dv at the root. Its symmetric part is
  // tested: x^T H x > 0 for all x. A sparse LL^T fails exactly when a pivot
  // is not positive.
  const Dimensions& d = dims_;
  JacobianRequest exact;
  exact.complete = true;
  guard_q_ = x.segment(0, d.nq);
  guard_v_ = x.segment(d.nq, d.nv);
  system_.force_jacobians(*data_, t, guard_q_, guard_v_, guard_z_, exact, &guard_jacobians_);
  const SparseMatrix D = guard_jacobians_.dF_dv;
  guard_v_.setZero();
  system_.force_jacobians(*data_, t, guard_q_, guard_v_, guard_z_, exact, &guard_jacobians_);
  const SparseMatrix H = mass_matrix_at(guard_q_) - h * D - (h * h) * guard_jacobians_.dF_dq;
  const SparseMatrix Ht = H.transpose();
  const SparseMatrix symmetric = 0.5 * (H + Ht);
  Eigen::SimplicialLLT<SparseMatrix> llt(symmetric);
  return llt.info() == Eigen::Success;
}

bool ImplicitIntegrator::passes_energy_guard(double tf, double h, const Eigen::VectorXd& x0,
                                             const Eigen::VectorXd& x) {
  // A converged step is a root of the step equations, not necessarily the
  // one implicit Euler means: at a large h a stiff spring can buckle or
  // invert into a root that is a saddle of the incremental potential G
  // (whose minimizer is the step) and gains energy. Energy alone does not
  // tell them apart: with constant M, N = I and damping forces F_d (v.F_d
  // <= 0), any root satisfies the identity
  //   E+ - E_n = -1/2 |v+ - v_n|_M^2 + h v+.F_d - B,
  //   B = Phi(q_n) - Phi(q+) - grad Phi(q+).(q_n - q+)
  //     = int_0^1 (1 - s) dq^T Hess Phi(q+ - s dq) dq ds,  dq = q+ - q_n,
  // so on a non-convex Phi (a compressed spring's transverse stiffness
  // k (1 - L/l) < 0) the genuine root gains up to
  //   1/2 max_s dq^T K(q(s)) dq,  K = -Hess Phi,
  // which is O(h^2) (one spring, k = 100, at l = 0.95 moving at 10 m/s
  // across it gains 4.1e-4 of its energy at h = 0.01). The criterion, only
  // evaluated when the energy rose beyond round-off:
  // 1. the gain must stay within that bound, K sampled at q_n, the midpoint
  //    and q+ and the largest value doubled for the curvature's variation
  //    between the samples;
  // 2. where G is the step's potential (N = I, no z states), its Hessian
  //    M - h D - h^2 K at the root must be positive definite: a root where
  //    it is not is no minimizer of G.
  if (!guard_energy_ || energy_guard_suspended_) return true;
  double allowance = 0.0;
  const double gain = energy_gain(x0, x, &allowance);
  if (gain <= allowance) return true;
  ++stats_.energy_guard_checks;
  const Dimensions& d = dims_;
  const double tn = tf - h;
  const Eigen::VectorXd q0 = x0.segment(0, d.nq), q1 = x.segment(0, d.nq);
  const Eigen::VectorXd dq = q1 - q0;
  double curvature = 0.0;
  for (double s : {0.0, 0.5, 1.0}) {
    const Eigen::VectorXd q = q0 + s * dq;
    curvature = std::max(curvature, negative_curvature(tn + s * h, q, dq));
  }
  bool spurious = gain > curvature + allowance;  // 2 x 1/2 max dq^T K dq
  if (!spurious && caps_.identity_velocity_map && d.nz == 0) {
    spurious = !incremental_hessian_definite(tf, h, x);
  }
  if (spurious) ++stats_.energy_guard_rejections;
  return !spurious;
}

void ImplicitIntegrator::use_step_error_tolerance(double local_error) {
  const bool widened = implicit_.step_error_tolerance && local_error > settings_.accuracy;
  const double error = std::min(local_error, kMaxToleranceWidening * settings_.accuracy);
  newton_tolerance_ =
      widened ? implicit_.step_error_kappa * error : implicit_.newton_kappa * settings_.accuracy;
  if (widened) ++stats_.newton_tolerance_from_step_error;
}

bool ImplicitIntegrator::solve_step(double t0, double h, const Eigen::VectorXd& x0,
                                    const Eigen::VectorXd& guess, Eigen::VectorXd* x) {
  ++stats_.newton_solves;
  estimate_tensions_ = false;  // until a direct solve begins
  // The rungs to climb. The chord ladder: reuse (1), refactor (2), fresh
  // Jacobian (3), full Newton (4). The Krylov path starts with its own rung
  // (the exact Jacobian at every iterate) and is the chord's last
  // rung where it is available. `auto` runs whichever start has cost less per unit of
  // simulated time lately (choose_start()).
  // The strategy is chosen at the first factorization (it depends on the
  // solver picked for the matrix): made here, the first solve uses it too.
  if (structured_) {
    const bool solved = newton(t0, h, x0, guess, kStructuredTrial, x);
    if (solved && caps_.has_quaternions) system_.project_positions(x->segment(0, dims_.nq));
    return solved;
  }
  if (!newton_solve_chosen_ && reuse_enabled()) {
    factor_reason_ = FactorReason::kFirst;
    compute_jacobian_and_factor(t0, x0, h);
  }
  int rungs[4] = {1, 2, 3, kFullNewtonTrial};
  int count = 4;
  const bool auto_start = krylov_ && implicit_.newton_solve == NewtonSolve::kAuto;
  const int start = krylov_ ? (auto_start ? choose_start() : kKrylovStart) : kChordStart;
  // Only a solve that starts on the Krylov path leaves the covered
  // couplings out of its preconditioner (ImplicitSettings::
  // drop_covered_couplings): a Krylov rung after a failed chord or fresh
  // start meets the steps where the sheet folds, and there the bend springs
  // leave their stretch springs' directions. cloth_stiff.yaml (8-12 starts):
  // halvings in 3 runs of 20 with them left out on every Krylov rung,
  // against none in 28 before.
  covered_allowed_ = start == kKrylovStart;
  if (start == kFreshStart) {
    // Full Newton on the direct path: a fresh Jacobian and factorization at
    // every iterate, with the springs' tension estimate and the search on
    // G. Where stiff springs dominate (cloth_stiff.yaml) that estimate
    // makes Newton converge in a few iterations where the exact Jacobian
    // needs tens, so the fresh start beats a Krylov start there. A fresh
    // start that fails goes on to the Krylov rung, as a failed chord start
    // does, and is charged as a failure: where the damping's derivative
    // decides (the 100x100 sheet folding), full Newton with the estimate
    // fails, and a run that chose it on a stale sample took 8 halvings
    // and 4x the time.
    rungs[0] = kFullNewtonTrial;
    rungs[1] = kKrylovTrial;
    count = 2;
    ++stats_.fresh_first_solves;
  } else if (start == kKrylovStart) {
    // No clamped full-Newton rung after a failed Krylov solve: that path
    // already iterates on the exact Jacobian with a preconditioner
    // refactored at the iterate whenever a direction fails, so full Newton
    // on the same matrix repeats it at a factorization per iteration;
    // halving the step is cheaper (cloth.yaml at 1/60 for 2 s: see the
    // README's table). Full Newton on the tension estimate is another
    // iteration, and ends the ladder at fixed steps (below).
    rungs[0] = kKrylovTrial;
    count = 1;
    ++stats_.krylov_first_solves;
  } else if (krylov_) {
    // A chord start that failed goes on to the Krylov rung: refactoring at
    // the current h first where h changed (the cheap fix for a reused
    // matrix), but not the fresh-Jacobian chord and clamped full-Newton
    // rungs, which the exact-Jacobian iteration beats (it converges
    // quadratically where the clamped matrix converges linearly). On
    // cloth.yaml at a fixed 1/60 for 2 s, three runs each: 239-316
    // factorizations and 0-5 halvings with those rungs, 196-243 and 0-3
    // without.
    if (matrices_[active_].h != h) {
      rungs[2] = kKrylovTrial;
      count = 3;
    } else {
      rungs[1] = kKrylovTrial;
      count = 2;
    }
  }
  // At fixed steps, with the tension estimate, every ladder ends with full
  // Newton on the estimate before h is halved. Where a Krylov solve fails
  // (the k = 1e6 sheet folding, and the first step of a sheet at rest,
  // whose flat membrane has no transverse stiffness) it usually converges,
  // in 3-10 iterations on cloth_stiff.yaml, 12-18 on cloth.yaml. It gets
  // twice the ordinary budget (max_newton_iterations), not the last rung's
  // three times: on the 16x16 sheet of k = 1e9 the rescues that failed
  // all ran out the 30 iterations, and the run took 1.6x the time. With
  // the ordinary budget cloth.yaml's rescues failed (3 runs of 5 took a
  // halving); with twice it none of 5 did. cloth_stiff.yaml at 1/60 for
  // 2 s took 0-3 halvings before, none after, and about 0.7x the time
  // (the README).
  int rescue_rung = -1;
  if (krylov_ && settings_.fixed_step && implicit_.tension_estimate &&
      std::find(rungs, rungs + count, kFullNewtonTrial) == rungs + count) {
    rescue_rung = count;
    rungs[count++] = kFullNewtonTrial;
  }
  // The time of the rung that converged, and of all the rungs (without the
  // root check, a diagnostic).
  root_check_seconds_ = 0.0;
  double solver_seconds = 0.0;
  const auto began = WallClock::now();
  long krylov_rung_iterations = 0;
  bool solved = false;
  int solved_by = -1;
  for (int k = 0; k < count && !solved; ++k) {
    const auto rung_began = WallClock::now();
    const long iterations_before = stats_.newton_raphson_iterations;
    const bool last = k + 1 == count || !reuse_enabled();
    solved = newton(t0, h, x0, guess, rungs[k], x, k == rescue_rung, last);
    const int owner = rungs[k] == kKrylovTrial       ? kKrylovStart
                      : rungs[k] == kFullNewtonTrial ? kFreshStart
                                                     : kChordStart;
    if (solved) solver_seconds = seconds_since(rung_began) - root_check_seconds_;
    if (rungs[k] == kKrylovTrial) {
      krylov_rung_iterations += stats_.newton_raphson_iterations - iterations_before;
    }
    if (solved) solved_by = owner;
    if (solved && k == rescue_rung) ++stats_.fresh_rescues;
    if (!solved && rungs[k] == kKrylovTrial) {
      ++stats_.krylov_newton_failures;
      eisenstat_walker_solves_left_ = kEisenstatWalkerSolves;
    }
    if (!solved && !reuse_enabled()) break;
  }
  // Where Krylov solves fail, nearly exact directions fail less (newton()):
  // armed by a failed Krylov rung whether or not a later rung converged.
  if (!solved) eisenstat_walker_solves_left_ = kEisenstatWalkerSolves;
  if (auto_start) {
    // Costs decay by half in about seven solves of that start, so the
    // choice follows the scene as it changes (a sheet that starts to fold).
    // A start that a later rung rescued failed: the rungs before the one
    // that converged are charged to it with no simulated time, that rung to
    // the start it belongs to (the Krylov rung to the Krylov start, the
    // fresh rung to the fresh start), with the step. Credited with the
    // step instead, a chord that failed every step but cost less than a
    // Krylov start's factorizations kept being chosen (cloth.yaml at 1/60
    // for 2 s: 13-15 Newton iterations on most steps, 10 of them the
    // chord's, 1,829 in all; now 40 chord iterations in 790-880). A solve
    // that failed is the start's alone: a rescue that failed with it (the
    // first step of a sheet at rest, which no rung solves at h) charged to
    // the fresh start kept it from being chosen on the 16x16 sheet of
    // k = 1e8 until its solves on the Krylov start took 35 iterations.
    const double total = seconds_since(began) - root_check_seconds_;
    auto charge = [this](int which, double seconds, double simulated) {
      StartCost& c = start_costs_[which];
      c.seconds = kStartCostDecay * c.seconds + seconds;
      c.simulated = kStartCostDecay * c.simulated + simulated;
      ++c.solves;
    };
    if (solved && solved_by != start) {
      charge(start, total - solver_seconds, 0.0);
      charge(solved_by, solver_seconds, h);
    } else {
      charge(start, total, solved ? h : 0.0);
    }
    if (start == kKrylovStart) {
      StartCost& c = start_costs_[kKrylovStart];
      c.iterations = kStartCostDecay * c.iterations + static_cast<double>(krylov_rung_iterations);
      c.weight = kStartCostDecay * c.weight + 1.0;
    }
  }
  if (solved && caps_.has_quaternions) system_.project_positions(x->segment(0, dims_.nq));
  return solved;
}

int ImplicitIntegrator::choose_start() {
  // Every factorization of the Krylov path evaluates a Jacobian at the
  // iterate, where the chord reuses one over many steps; where a Jacobian
  // costs more than a factorization (a compliant chain: seeded forward
  // mode over free bodies against a banded LU), the chord wins. Not even
  // tried then: on a 1000-link compliant chain its explorations tripled a
  // 50-step run (1.16 s against 0.40 s, when every Krylov iteration also
  // evaluated the exact Jacobian).
  if (last_jacobian_seconds_ > last_factorization_seconds_ && last_factorization_seconds_ > 0.0) {
    return kChordStart;
  }
  // The reuse starts are tried first (the chord, then Krylov); then the
  // cheapest per simulated second, with the others tried in turn every
  // kStartExploration solves so a change of regime is noticed. The fresh
  // start waits for the first exploration: at a run's start every step is
  // easy, and a sample from there made it look cheap (a 100x100 sheet paid
  // a factorization per iteration for it).
  for (int s : {kChordStart, kKrylovStart}) {
    if (start_costs_[s].solves == 0) return s;
  }
  auto cost = [](const StartCost& c) {
    return c.simulated > 0.0 ? c.seconds / c.simulated : std::numeric_limits<double>::infinity();
  };
  int best = cost(start_costs_[kKrylovStart]) < cost(start_costs_[kChordStart]) ? kKrylovStart
                                                                                : kChordStart;
  // The fresh start must cost less than kFreshStartMargin of the better
  // reuse start. Its cost is often the stale sample of an easy phase (the
  // sheet's first steps converge in two iterations whatever the matrix),
  // and where it loses it loses by 2x or more (cloth.yaml: a fresh start
  // costs twice a Krylov start's time per step); where it wins it wins by
  // as much (cloth_stiff.yaml: 0.25-0.85 of a Krylov start's recent cost).
  // Without the margin, cloth.yaml at a fixed 1/60 took 22 fresh starts in
  // one run of three, and 1.4x the time. The fresh start exists where the
  // tension estimate does (fixed steps; error control keeps two starts),
  // and only while Krylov starts take kFreshStartIterations Newton
  // iterations or more per solve: the estimate saves iterations, where
  // each of full Newton's costs a factorization. Krylov starts averaged 15
  // on cloth_stiff.yaml, 8 on the 100x100 sheet (where fresh starts chosen
  // on a cheap first sample then took up to 30 and 1.2x the time) and 5 on
  // cloth.yaml.
  const StartCost& krylov = start_costs_[kKrylovStart];
  const bool fresh_may_pay =
      krylov.weight > 0.0 && krylov.iterations >= kFreshStartIterations * krylov.weight;
  const int starts =
      settings_.fixed_step && implicit_.tension_estimate && fresh_may_pay ? kStarts : 2;
  if (starts == kStarts &&
      cost(start_costs_[kFreshStart]) < kFreshStartMargin * cost(start_costs_[best])) {
    best = kFreshStart;
  }
  // An exploration that lost doubles the interval to the next one (up to
  // 16 times the shortest), so a start many times costlier than the other
  // (the Krylov path on a chain of small dense bodies) is rarely paid for.
  if (explored_) {
    explored_ = false;
    exploration_interval_ = best == last_best_
                                ? std::min(2 * exploration_interval_, 16 * kStartExploration)
                                : kStartExploration;
  }
  last_best_ = best;
  if (++solves_since_exploration_ >= exploration_interval_) {
    solves_since_exploration_ = 0;
    explored_ = true;
    last_explored_ = (last_explored_ + 1) % starts;
    if (last_explored_ == best) last_explored_ = (last_explored_ + 1) % starts;
    return last_explored_;
  }
  return best;
}

void ImplicitIntegrator::compute_jacobian_at_iterate(double tf, double h, const Eigen::VectorXd& x0,
                                                     const Eigen::VectorXd& x) {
  // Linearize at the iterate itself, with the step's own mean acceleration
  // (v - v_n) / h in the inertial term.
  if (!caps_.constant_mass_matrix && dims_.nv > 0) {
    inertial_acceleration_ = (x.segment(dims_.nq, dims_.nv) - x0.segment(dims_.nq, dims_.nv)) / h;
    iterate_acceleration_ = true;
  }
  compute_jacobian(tf, x, 0.0);
  iterate_acceleration_ = false;
  mark_jacobian_stale();
}

GmresResult ImplicitIntegrator::newton_gmres(double tf, double h, const Eigen::VectorXd& x0,
                                             const Eigen::VectorXd& x, const Eigen::VectorXd& rhs,
                                             double forcing, double abandon_products,
                                             Eigen::VectorXd* dy, double* seconds,
                                             bool refactor_when_stale) {
  // The operator is the exact Jacobian of the residual, applied matrix-free
  // by a difference of residuals: one residual per product, O(n) like the
  // forces. The structured matrix leaves out the Jacobian terms of the
  // velocity products and of the configuration dependence of M and gravity
  // (on a stiff chain at h = 1e-3 they are of the order of M itself, and
  // Newton on the structured matrix alone diverged where exact Newton took
  // three iterations); the assembled preconditioner clamps compressed
  // springs and drops the damping's derivative through the spring
  // directions (with both, Newton converges quadratically; without the
  // damping term it cycled on a 32x32 cloth at h = 1/60, where h c / m = 21
  // makes damping the largest force). Assembling that exact Jacobian at
  // every Newton iteration instead cost cloth.yaml at a fixed 1/60 over
  // 2 s 0.45 s of Jacobians and 0.10 s of assembly, against 0.18 s for
  // the products' residuals (two runs each, at equal Newton and Krylov
  // counts). The difference step is the usual sqrt(eps) relative to the
  // unknowns, so the product's relative error (~1e-8) stays far below any
  // forcing term.
  const int offset = unknowns_offset();
  const int n = static_cast<int>(rhs.size());
  const double scale = 1.0 + x.segment(offset, n).lpNorm<Eigen::Infinity>();
  auto apply = [&](const Eigen::VectorXd& p, Eigen::VectorXd* Ap) {
    const double size = p.lpNorm<Eigen::Infinity>();
    if (size == 0.0) {
      Ap->setZero(n);
      return;
    }
    const double eps = 1.5e-8 * scale / size;
    x_product_ = x;
    x_product_.segment(offset, n) += eps * p;
    complete_iterate(h, x0, &x_product_);
    residual(tf, h, x0, x_product_, &r_product_);
    // rhs is minus the residual at x.
    *Ap = (r_product_ + rhs) / eps;
  };
  // GMRES's first basis vector is rhs / |rhs| (a uniform scaling cancels):
  // after a chord test at this iterate and factorization, its solve is
  // -chord_update_ / |rhs|. Near a fold's root, where the chord test is
  // tried, most Newton iterations would otherwise begin with that solve
  // again.
  bool chord_start = chord_starts_gmres(rhs);
  auto precondition = [&](const Eigen::VectorXd& r, Eigen::VectorXd* z) {
    if (chord_start) {
      chord_start = false;
      *z = chord_update_ * (-1.0 / rhs.norm());
      ++stats_.krylov_chord_starts;
      return;
    }
    solve_iteration_matrix(r, z, true);
  };
  const auto start = WallClock::now();
  // Abandoned where the products still needed, at the rate the solve has
  // shown so far (rel^(1/k) per product), exceed abandon_products.
  auto give_up = [&](int k, double rel) {
    if (abandon_products <= 0.0 || k < std::max(kFreshSolveProducts, 0.5 * abandon_products)) {
      return false;
    }
    if (k >= abandon_products || !(rel < 1.0)) return true;
    return k + k * std::log(forcing / rel) / std::log(rel) > abandon_products;
  };
  // Where the solve is given up, the iterate's own factorization replaces
  // the preconditioner (refactor_when_stale); its time is not the solve's.
  double refactor_seconds = 0.0;
  auto switch_preconditioner = [&] {
    if (!refactor_when_stale) return false;
    ++stats_.krylov_stale_solves_abandoned;
    const auto refactor_start = WallClock::now();
    const bool factored = refactor_preconditioner(tf, h, x0, x, FactorReason::kKrylovFailed);
    refactor_seconds = seconds_since(refactor_start);
    return factored;
  };
  const double setup_before = preconditioner_setup_seconds_;
  const GmresResult krylov =
      gmres(apply, precondition, rhs, residual_scaling(), forcing, implicit_.max_krylov_iterations,
            &gmres_, dy, give_up, switch_preconditioner);
  const double elapsed = seconds_since(start);
  stats_.krylov_seconds += elapsed - refactor_seconds;
  const double setup = preconditioner_setup_seconds_ - setup_before;
  *seconds = elapsed - refactor_seconds - setup;
  last_factorization_seconds_ += setup;
  last_refactor_seconds_ += setup;
  if (krylov.iterations > 0) product_seconds_ = *seconds / krylov.iterations;
  ++stats_.krylov_solves;
  stats_.krylov_iterations += krylov.iterations;
  stats_.krylov_max_iterations = std::max<long>(stats_.krylov_max_iterations, krylov.iterations);
  // A solve that missed its tolerance still lowered the linearized
  // residual; the line search judges the direction.
  if (!krylov.converged && !krylov.abandoned) ++stats_.krylov_failures;
  return krylov;
}

void ImplicitIntegrator::check_root(double tf, double h, const Eigen::VectorXd& x0,
                                    const Eigen::VectorXd& x) {
  // Only where there is a factorization to precondition GMRES with.
  if (!structured_ && !iteration_matrix_factored()) return;
  const auto start = WallClock::now();
  // The check's residuals, products and solves would count as the run's.
  const IntegratorStatistics kept = stats_;
  const double kept_product_seconds = product_seconds_;
  const int offset = unknowns_offset();
  const int n = static_cast<int>(root_r_.size());
  root_x_ = x;
  bool reached = false;
  for (int k = 0; k < kRootCheckIterations && !reached; ++k) {
    residual(tf, h, x0, root_x_, &root_r_);
    root_r_ = -root_r_;
    double seconds = 0.0;
    newton_gmres(tf, h, x0, root_x_, root_r_, kRootCheckForcing, 0.0, &root_dy_, &seconds);
    if (!root_dy_.allFinite()) break;
    root_x_.segment(offset, n) += root_dy_;
    complete_iterate(h, x0, &root_x_);
    reached = root_dy_.lpNorm<Eigen::Infinity>() <= kRootCheckUpdate * solve_tolerance_;
  }
  const double distance =
      (root_x_ - x).segment(offset, n).lpNorm<Eigen::Infinity>() / solve_tolerance_;
  stats_ = kept;
  product_seconds_ = kept_product_seconds;
  ++stats_.root_checks;
  if (reached) {
    double& largest = stats_.largest_root_distance_ratio;
    if (!(distance <= largest)) largest = distance;  // NaN: none yet
  } else {
    ++stats_.root_checks_unfinished;
  }
  root_check_seconds_ += seconds_since(start);
}

bool ImplicitIntegrator::factor_exact_hessian(double tf, double h, const Eigen::VectorXd& x0,
                                              const Eigen::VectorXd& x) {
  const IterationMatrix& m = matrices_[active_];
  if (!m.solver.solver || !m.solver.solver->has_cholesky()) return false;
  exact_jacobian_ = true;
  compute_jacobian_at_iterate(tf, h, x0, x);
  exact_jacobian_ = false;
  factor_if_definite_ = true;
  const bool factored = form_and_factor(h, true);
  factor_if_definite_ = false;
  ++(factored ? stats_.exact_hessian_factorizations : stats_.exact_hessian_indefinite);
  return factored;
}

bool ImplicitIntegrator::finishing_pays() const {
  if (implicit_.finishing_share <= 0.0) return false;
  // Tried until a finishing solve and a product have been measured.
  if (product_seconds_ <= 0.0 || finishing_weight_ <= 0.0) return true;
  return finishing_products_ / finishing_weight_ * product_seconds_ <
         implicit_.finishing_share * (last_jacobian_seconds_ + last_factorization_seconds_);
}

bool ImplicitIntegrator::finishing_direction(double tf, double h, const Eigen::VectorXd& x0,
                                             const Eigen::VectorXd& x, const Eigen::VectorXd& rhs,
                                             Eigen::VectorXd* dy) {
  double seconds = 0.0;
  const GmresResult g = newton_gmres(tf, h, x0, x, rhs, kFinishingForcing, 0.0, dy, &seconds);
  ++stats_.fresh_finishing_solves;
  finishing_products_ = kStartCostDecay * finishing_products_ + g.iterations;
  finishing_weight_ = kStartCostDecay * finishing_weight_ + 1.0;
  return g.converged;
}

bool ImplicitIntegrator::refactor_preconditioner(double tf, double h, const Eigen::VectorXd& x0,
                                                 const Eigen::VectorXd& x, FactorReason reason) {
  // The preconditioner: the definite (clamped, symmetric) matrix at this
  // iterate, so a sparse Cholesky keeps working.
  factor_reason_ = reason;
  refactor_first_ = false;
  preconditioner_fresh_ = true;
  const auto start = WallClock::now();
  compute_jacobian_at_iterate(tf, h, x0, x);
  bool symmetric = false;
  const SparseMatrix& preconditioner = form_iteration_matrix(h, &symmetric);
  const bool factored = factor_iteration_matrix(preconditioner, symmetric, h, covered_allowed_);
  last_refactor_seconds_ = seconds_since(start);
  return factored;
}

bool ImplicitIntegrator::krylov_direction(double tf, double h, const Eigen::VectorXd& x0,
                                          const Eigen::VectorXd& x, const Eigen::VectorXd& rhs,
                                          double forcing, bool may_abandon, Eigen::VectorXd* dy) {
  preconditioner_fresh_ = false;
  if (refactor_first_ || refactor_due_ || refactor_failed_ || !iteration_matrix_factored()) {
    if (!refactor_preconditioner(tf, h, x0, x,
                                 refactor_failed_ ? FactorReason::kKrylovFailed
                                 : refactor_due_  ? FactorReason::kCostModel
                                                  : FactorReason::kFirst)) {
      return false;
    }
  }
  // A solve against a stale preconditioner is given up once the products
  // it still needs, at the rate it has shown, would cost more than
  // refactoring here (Jacobian, assembly, factorization) and a fresh
  // solve's few products; the preconditioner is then refactored at this
  // iterate and the solve goes on with it (newton_gmres: the products
  // made are kept, and the next direction is the fresh factorization's
  // solve of the current residual). Where the sheet buckles, a
  // factorization one Newton iteration old often left GMRES at a relative
  // residual of 0.2-0.9 after all 40 products (the 100x100 cloth at 1/60:
  // 60 of its 237 solves to t = 0.25 s, 70 s in all), where the same
  // iterate's fresh factorization converges in 1-6.
  double abandon_products = 0.0;
  if (may_abandon && !preconditioner_fresh_ && product_seconds_ > 0.0) {
    // Until the Krylov path has refactored once, the ladder's last
    // Jacobian and factorization stand in.
    const double refactor_seconds =
        std::max(last_refactor_seconds_, last_jacobian_seconds_ + last_factorization_seconds_);
    abandon_products = refactor_seconds / product_seconds_ + kFreshSolveProducts;
  }
  double seconds = 0.0;
  const GmresResult krylov =
      newton_gmres(tf, h, x0, x, rhs, forcing, abandon_products, dy, &seconds, true);
  // Given up only where the refactoring it called for failed.
  if (krylov.abandoned) return false;
  if (!krylov.converged) {
    // 40 products did not meet the tolerance: a stale preconditioner under
    // Eisenstat-Walker forcing (never abandoned), or even this iterate's
    // own (the Jacobian is indefinite where the sheet buckles, its
    // preconditioner clamped definite). The iteration goes on with what
    // GMRES has, which still lowers the linearized residual; the next
    // iteration refactors.
    refactor_failed_ = true;
    return true;
  }
  // Cost model: the Krylov iterations beyond those a fresh factorization
  // takes accumulate until they cost more than the last factorization did;
  // then the next iteration refactors. A preconditioner that stays exact is
  // never replaced. What a fresh one takes is what this Newton solve's
  // last one did (one product until it has made one): where a sheet folds
  // its iterate's own factorization (the clamped matrix, whose Jacobian is
  // indefinite there) left GMRES at 10-16 products, and charging those
  // against one product refactored at every iteration for nothing.
  // A solve whose preconditioner was replaced part way is charged nothing;
  // its products since then are what a fresh one took.
  const bool switched = krylov.switched_at >= 0;
  if (preconditioner_fresh_) {
    fresh_solve_products_ = switched ? krylov.iterations - krylov.switched_at : krylov.iterations;
  }
  const double excess =
      switched ? 0.0 : stale_solve_excess(seconds, krylov.iterations, fresh_solve_products_);
  krylov_excess_seconds_ += excess;
  solve_excess_seconds_ += excess;
  if (krylov_excess_seconds_ > last_factorization_seconds_) refactor_due_ = true;
  return true;
}

double ImplicitIntegrator::stale_solve_excess(double seconds, int products, double fresh_products) {
  if (products <= 0) return 0.0;
  return seconds * std::max(0.0, products - std::max(fresh_products, 1.0)) / products;
}

void ImplicitIntegrator::add_estimator_share(const IntegratorStatistics& before,
                                             IntegratorStatistics* stats) {
  stats->error_estimator_derivative_evaluations +=
      stats->derivative_evaluations - before.derivative_evaluations;
  stats->error_estimator_derivative_evaluations_for_jacobian +=
      stats->derivative_evaluations_for_jacobian - before.derivative_evaluations_for_jacobian;
  stats->error_estimator_jacobian_evaluations +=
      stats->jacobian_evaluations - before.jacobian_evaluations;
  stats->error_estimator_iteration_matrix_factorizations +=
      stats->iteration_matrix_factorizations - before.iteration_matrix_factorizations;
  stats->error_estimator_newton_raphson_iterations +=
      stats->newton_raphson_iterations - before.newton_raphson_iterations;
}

double ImplicitIntegrator::extrapolation_newton_tolerance(double h) const {
  // x_e = 2 x_small - x_big amplifies the Newton errors d of its three
  // solves (|2 d_small1 + 2 d_small2 - d_big| up to 5 d) while its own local
  // error is O(h^3), far below |x_big - x_small| = O(h^2), the quantity
  // kappa * accuracy was chosen against. For the global error to stay
  // second order the solves' errors must be O(h^3) too, so the tolerance is
  // tied to an estimate of the extrapolated local error. With one time
  // scale tau = |x'| / |x''| = |x''| / |x'''| of the motion, the correction
  // c = |x_big - x_small| ~ h^2 |x''| / 4 and the step's motion
  // m = |x_small - x_n| ~ h |x'|, that error is ~ h^3 |x'''| ~ c^2 / m (up
  // to a constant of order one). The last extrapolated step gives c and m,
  // scaled to this h by (h / h_last)^3; the tolerance is kappa times that,
  // never above kappa * accuracy (the other methods' tolerance), never below
  // kappa^3 * accuracy (where convergence is limited by round-off and
  // noise), and kappa^2 * accuracy for the first step.
  // Measured on models/chain10.yaml, vie2 at accuracy 1e-3, fixed h = 1e-3,
  // 5e-4, 2.5e-4 over 0.5 s against rk45 at 1e-10: 5.85e-3, 1.44e-3,
  // 3.52e-4 rad (orders 2.02, 2.03; the same errors as at accuracy 1e-8),
  // where kappa * accuracy gave 5.56e-3, 8.5e-4, 9.1e-4 and kappa^2 *
  // accuracy 5.82e-3, 1.40e-3, 2.7e-4 (still off the curve at the last h).
  //
  // Under error control the rule does not pay: the controller holds the
  // estimate |x_big - x_small| near the accuracy, so the solves' errors at
  // kappa * accuracy (amplified at most 5x) stay below the error the user
  // asked for, and tightening them buys smaller errors at a higher price per
  // digit. Measured with the quick precision report, time at equal error
  // against kappa * accuracy: 1.45-2.0x on the 8x8 cloth, 1.1-2.0x on the
  // rope, 0.9-1.7x on the stiff cloth (floors kappa^2, kappa^1.5 and kappa
  // times kappa * accuracy alike). So the rule applies to fixed steps only,
  // where the accuracy sets nothing but the Newton tolerance.
  const double kappa = implicit_.newton_kappa, base = kappa * settings_.accuracy;
  if (!settings_.fixed_step) return base;
  if (!(extrapolated_h_ > 0.0) || !(extrapolated_motion_ > 0.0)) return kappa * base;
  const double r = h / extrapolated_h_;
  const double local_error =
      extrapolated_correction_ * extrapolated_correction_ / extrapolated_motion_ * r * r * r;
  return std::max(kappa * kappa * base, std::min(base, kappa * local_error));
}

bool ImplicitIntegrator::keep_lowest_root(double t0, double h, const Eigen::VectorXd& x0,
                                          Eigen::VectorXd* x) {
  // The step is the minimizer of the incremental potential G, but on a
  // non-convex potential G has other local minimizers, and Newton from the
  // predictor can converge to one where the sheet of a very stiff cloth
  // folds the other way: passes_energy_guard() cannot tell, since such a
  // root is a minimizer (a definite Hessian) and its gain is within the
  // curvature bound, which at stretch k = 1e9 allows nearly any gain.
  // Taken again from the step's start without the predictor, the same
  // step and 2-16 substeps lose energy there (models/cloth.yaml, 16x16,
  // k = 1e9, at 1/60: a root that gained 0.11 J on a kinetic energy of
  // 1.5 J lay 0.026-0.027 m from all of them).
  // Two half steps end at q_half; v = (q_half - q_n) / h is a point of the
  // full step's G. Near the genuine root it is O(h) away from it, where G
  // is convex, so G is not lower there; where it is lower, the root is not
  // G's minimizer, and the half steps' end, itself two implicit Euler
  // steps, is taken instead. Only steps that gained energy are compared:
  // a root that loses energy is what the method means, and the half steps
  // would triple the cost of every step.
  if (!guard_energy_ || energy_guard_suspended_ || !has_potential()) return true;
  double allowance = 0.0;
  if (energy_gain(x0, *x, &allowance) <= allowance) return true;
  if (!solve_step(t0, 0.5 * h, x0, x0, &x_half_)) return false;
  if (!solve_step(t0 + 0.5 * h, 0.5 * h, x_half_, x_half_, &x_small_)) return false;
  const double g_root = potential(t0 + h, x0, *x, h, true);
  const Dimensions& d = dims_;
  x_big_ = *x;
  x_big_.segment(d.nq, d.nv) = (x_small_.segment(0, d.nq) - x0.segment(0, d.nq)) / h;
  complete_iterate(h, x0, &x_big_);
  const double g_halves = potential(t0 + h, x0, x_big_, h, true);
  if (g_halves < g_root - potential_roundoff(g_root)) {
    ++stats_.energy_guard_rejections;
    x->swap(x_small_);
  }
  return true;
}

const Eigen::VectorXd& ImplicitIntegrator::corrected_guess(double t0, double h,
                                                           const Eigen::VectorXd& x0,
                                                           const Eigen::VectorXd& guess, double c,
                                                           bool decide,
                                                           Eigen::VectorXd* corrected) {
  // The estimate is the last accepted step's, or an attempt's from t0, and
  // only a smooth one (see step_doubling()) is used.
  if (!implicit_.corrected_guesses || !second_derivative_smooth_ ||
      !(second_derivative_t0_ >= previous_.t && second_derivative_t0_ <= t0)) {
    return guess;
  }
  if (!decide && !second_derivative_trusted_) return guess;
  *corrected = guess + c * second_derivative_;
  if (decide) {
    // Trusted where the corrected guess is the lower point of G. A stiff
    // sheet's estimate holds its stiff springs' stretch, which differs
    // between steps of h and h/2 rather than along the motion; corrected
    // by it the guess stretches them. On the 16x16 sheet of k = 1e6 under
    // error control at 1e-2..1e-4: 1.08-1.12x the time with smooth
    // estimates trusted, 0.99-1.03x guarded. One decision per step: a
    // second for the half step cost 4% on the 16x16 sheet of k = 1e3.
    if (has_potential() &&
        !(guess_potential(t0, h, x0, *corrected) < guess_potential(t0, h, x0, guess))) {
      return guess;
    }
    second_derivative_trusted_ = true;
  }
  ++stats_.step_guesses_corrected;
  return *corrected;
}

bool ImplicitIntegrator::step_doubling(double h) {
  const double t0 = state_.t;
  const Eigen::VectorXd& x0 = state_.x;
  // The large step is the error estimator's share of the work (as in Drake).
  // It is tried first because it fails to converge more often.
  if (implicit_.extrapolate) newton_tolerance_ = extrapolation_newton_tolerance(h);
  const IntegratorStatistics before = stats_;
  // First iterates. With the acceleration linear over the step, a(t_n + s)
  // = a_n + s x'', and x'' estimated by the last doubling (x_big - x_small
  // = h^2 x'' / 4 to leading order):
  // - the big step's predictor extrapolates the last step's change (its
  //   size p) and is off by (h^2 + h p / 4) x'', which is added;
  // - the first half step's midpoint of x0 and x_big is off by h^2 x'' / 4,
  //   which is subtracted;
  // - the second half step's x_half + (x_big - x0) / 2 is right to that
  //   order with no estimate (x_big, used before, is off by the error
  //   estimate itself).
  // The predictor now starts the chord too (it started only the Krylov
  // path): a chord iteration ended by its rate test leaves an error in
  // proportion to where it started, and the rejected steps fell with it.
  // Measured against the guesses before (3 runs each, medians; error
  // against RK45 at 1e-10 unchanged within the runs' spread): the chain of
  // 10 links 0.77x and 0.72x the time at accuracy 1e-3 and 1e-5
  // (rejections 554 -> 184 at 1e-5; under vie2 the error 6.9e-4 -> 1.7e-5),
  // the rope of 50 nodes 0.95x and 0.84x, the 16x16 sheets of k = 1e3
  // 0.94-1.02x (1e-3..1e-5) and of k = 1e6 0.98-1.04x (1e-2, 1e-3).
  const Eigen::VectorXd& predicted = predictor(h, x0);
  const double p = t0 - previous_.t;
  second_derivative_trusted_ = false;  // until the big step's guess takes it
  const Eigen::VectorXd& guess =
      &predicted == &x0 ? x0
                        : corrected_guess(t0, h, x0, predicted, h * h + h * p / 4, true, &x_guess_);
  const bool big_ok = solve_step(t0, h, x0, guess, &x_big_);
  add_estimator_share(before, &stats_);
  if (!big_ok) return false;

  x_half_ = 0.5 * (x0 + x_big_);
  const Eigen::VectorXd& half_guess =
      corrected_guess(t0, 0.5 * h, x0, x_half_, -0.25 * h * h, false, &x_guess_);
  if (!solve_step(t0, 0.5 * h, x0, half_guess, &x_small_)) return false;
  x_half_.swap(x_small_);
  if (implicit_.corrected_guesses) {
    x_guess_ = x_half_ + 0.5 * (x_big_ - x0);
  } else {
    x_guess_ = x_big_;
  }
  if (!solve_step(t0 + 0.5 * h, 0.5 * h, x_half_, x_guess_, &x_small_)) return false;
  // The corrections assume x'' constant over a step and the next: an
  // estimate is used where it agrees with the one before within half of
  // itself. (Trusted without G, the chain of 10 links took 0.74x the time
  // at accuracy 1e-5, against 0.82x where only G could trust it.)
  second_derivative_previous_.swap(second_derivative_);
  second_derivative_ = (4.0 / (h * h)) * (x_big_ - x_small_);
  second_derivative_smooth_ =
      !std::isnan(second_derivative_t0_) &&
      (second_derivative_ - second_derivative_previous_).norm() <= 0.5 * second_derivative_.norm();
  second_derivative_t0_ = t0;
  // x_big - x_small = (h^2/4) x'' + O(h^3): the local error of the half-step
  // result to leading order. For the extrapolated result 2 x_small - x_big,
  // whose local error is O(h^3), it is a conservative bound: the controller
  // keeps order 2 (see error_estimate_order()).
  if (estimating_error()) error_ = x_big_ - x_small_;
  if (implicit_.extrapolate) {
    extrapolated_h_ = h;
    extrapolated_correction_ = state_change_norm(x_big_ - x_small_);
    extrapolated_motion_ = state_change_norm(x_small_ - x0);
    // x_e = 2 x_small - x_big cancels the h^2 term of the local error. Its
    // stability function 2 / (1 - z/2)^2 - 1 / (1 - z) is bounded by 1 on
    // the imaginary axis and tends to 0 as z -> -inf: still L-stable.
    candidate_ = 2.0 * x_small_ - x_big_;
    if (caps_.has_quaternions) system_.project_positions(candidate_.segment(0, dims_.nq));
    // Linear stability is not the whole story on stiff nonlinear scenes: the
    // two results lie near the manifold where stiff springs sit at their
    // rest lengths, but a combination of two points of a curved manifold is
    // off it, and a stiff spring turns that distance into energy. In a
    // passive scene such a step propagates x_small, which passed the guard.
    double allowance = 0.0;
    if (guard_energy_ && energy_gain(x0, candidate_, &allowance) > allowance) {
      ++stats_.extrapolation_rejections;
      candidate_.swap(x_small_);
    }
  } else {
    candidate_.swap(x_small_);
  }
  return true;
}

IntegratorReport ImplicitIntegrator::report() const {
  IntegratorReport r = IntegratorBase::report();
  r.jacobian_scheme = to_string(implicit_.jacobian);
  r.jacobian_colours = jacobian_evaluator_.colours();
  r.newton_form = to_string(implicit_.newton_form);
  if (newton_solve_chosen_) {
    r.newton_solve = structured_            ? "recursive"
                     : implicit_.full_newton ? "fresh"
                     : krylov_               ? "krylov"
                                             : "chord";
    r.newton_solve_reason = newton_solve_reason_;
    if (krylov_ && !structured_) {
      r.preconditioner_precision =
          preconditioner_precision_name(implicit_.single_precision_preconditioner);
    }
  }
  r.extrapolated = implicit_.extrapolate;
  const LinearSolverChoice& solver = matrices_[0].solver;
  if (solver.solver) {
    r.linear_solver = solver.solver->method();
    r.linear_solver_reason = solver.reason;
    if (!solver.solver->factorization_note().empty()) {
      r.linear_solver_reason += "; " + solver.solver->factorization_note();
    }
    r.linear_solver_fallback = solver.solver->fallback_note();
  }
  return r;
}

}  // namespace stiffsim
