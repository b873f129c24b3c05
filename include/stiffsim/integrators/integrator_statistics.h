#pragma once
// Statistics of an integration run, named as Drake names them, plus the
// counters that prove which work was skipped.

#include <limits>
#include <string>
#include <vector>

namespace stiffsim {

struct IntegratorStatistics {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

  long steps_taken = 0;
  long derivative_evaluations = 0;
  long derivative_evaluations_for_jacobian = 0;
  long jacobian_evaluations = 0;
  long iteration_matrix_factorizations = 0;
  long newton_raphson_iterations = 0;
  // The share of the five counters above spent on the error estimate (for
  // VIE: the large step, as in Drake).
  long error_estimator_derivative_evaluations = 0;
  long error_estimator_derivative_evaluations_for_jacobian = 0;
  long error_estimator_jacobian_evaluations = 0;
  long error_estimator_iteration_matrix_factorizations = 0;
  long error_estimator_newton_raphson_iterations = 0;
  long substep_failures = 0;
  long step_shrinkages_from_substep_failures = 0;
  long step_shrinkages_from_error_control = 0;
  double smallest_adapted_step_size_taken = kNaN;
  double largest_step_size_taken = kNaN;
  double actual_initial_step_size_taken = kNaN;

  // Work counters beyond Drake's.
  long newton_solves = 0;              // per step: 1, or 3 with the estimate or extrapolation
  long newton_trials = 0;              // Newton iterations started (ladder rungs that ran)
  long line_search_backtracks = 0;     // halved Newton steps
  long merit_damping_evaluations = 0;  // damping matrices for the line-search merit
  // Converged solves of passive scenes whose energy rose, so the energy
  // criterion examined them (definiteness of the incremental potential's
  // Hessian, the curvature bound on the gain), and those it rejected.
  long energy_guard_checks = 0;
  long energy_guard_rejections = 0;
  // Extrapolated steps (vie2, ie2) that would have gained energy in a
  // passive scene and propagated the half-step result instead.
  long extrapolation_rejections = 0;
  // Fixed VIE steps whose Newton iteration started from the step's start
  // rather than from the predictor, which was a higher point of the
  // incremental potential (see VelocityImplicitEuler::first_iterate()).
  long predictor_declined = 0;
  // Step doubling's first iterates that took the correction by the last
  // estimate of x'' (see ImplicitSettings::corrected_guesses).
  long step_guesses_corrected = 0;
  long velocity_map_evaluations = 0;  // N(q) products and assemblies (0 when N = I)
  long mass_matrix_assemblies = 0;    // 1 for a constant M
  long symbolic_analyses = 0;         // sparse orderings / elimination trees
  long linear_solves = 0;
  long dense_output_evaluations = 0;     // derivative evaluations spent on dense output
  long jacobian_approximated_terms = 0;  // definite clamps in iteration matrices (Choi & Ko)
  long iteration_matrix_nonzeros = 0;
  long factor_nonzeros = 0;
  // Krylov path (NewtonSolve::kKrylov): GMRES solves of the current Newton
  // system, their products with it (total and the most in one solve), the
  // solves that missed their tolerance within the iteration budget, and why
  // each factorization happened.
  long krylov_first_solves = 0;  // Newton solves that started on the Krylov path
  long fresh_first_solves = 0;   // Newton solves that started with full Newton (auto)
  // Fixed steps with the tension estimate: Newton solves on the Krylov rung
  // that failed, and solves that full Newton with the estimate converged
  // after every other rung had failed (instead of halving the step).
  long krylov_newton_failures = 0;
  long fresh_rescues = 0;
  // Full Newton solves, the last rung before a halving, that went on past
  // their iteration budget near the root (ImplicitSettings::extend_near_root).
  long last_rung_extensions = 0;
  // Full Newton near the root (ImplicitSettings::exact_hessian_near_root):
  // factorizations of the exact Hessian, and attempts that found it
  // indefinite (each then factors the clamped matrix too). Both count in
  // iteration_matrix_factorizations.
  long exact_hessian_factorizations = 0;
  long exact_hessian_indefinite = 0;
  // ImplicitSettings::verify_roots: accepted iterates checked, checks whose
  // Newton iteration did not reach a root within its budget (no distance
  // then), and the largest distance from the root found, in tolerances of
  // the solve (NaN with no check).
  long root_checks = 0;
  long root_checks_unfinished = 0;
  double largest_root_distance_ratio = kNaN;
  // Factorizations without the covered couplings: the Krylov path's
  // preconditioner (ImplicitSettings::drop_covered_couplings) and full
  // Newton's matrix (ImplicitSettings::refine_without_covered).
  long covered_coupling_factorizations = 0;
  // Direct solves against such a factor refined on W itself
  // (ImplicitSettings::refine_without_covered), their GMRES products, and
  // the solves that missed their tolerance, after which W was factored
  // whole.
  long refined_solves = 0;
  long refined_solve_products = 0;
  long refined_solve_fallbacks = 0;
  // Fixed steps without an error estimate: step attempts (a halved step's
  // retries included) whose Newton tolerance the step's own local error
  // set (ImplicitSettings::step_error_tolerance).
  long newton_tolerance_from_step_error = 0;
  // ... and of those, solves narrowed back to kappa * accuracy because an
  // iterate gained energy (the energy guard judges roots, see newton());
  // also the solves whose tolerance was cut to kGuardPolish of itself
  // because the iterate it accepted gained energy.
  long newton_tolerance_narrowed = 0;
  long krylov_solves = 0;
  long krylov_iterations = 0;
  long krylov_max_iterations = 0;
  long krylov_failures = 0;
  // Krylov-path iterates accepted by the chord test: the last
  // factorization's solve of the residual (the chord's next update) within
  // the tolerance. The solve then ends, unless a widened tolerance is
  // narrowed (newton_tolerance_narrowed) or the energy guard rejects it.
  long krylov_chord_convergences = 0;
  // Krylov-path iterates accepted by the update test: a full update, from a
  // GMRES solve that met its forcing, within the tolerance.
  long krylov_update_convergences = 0;
  // GMRES solves that started from the chord test's solve at the same
  // iterate and factorization instead of solving again (one preconditioner
  // solve saved each).
  long krylov_chord_starts = 0;
  // The same test in full Newton (the fresh factorization at the previous
  // iterate gives the next update): its solves, and the iterates it
  // accepted.
  long fresh_chord_tests = 0;
  long fresh_chord_convergences = 0;
  // Full Newton's finishing iterations after a chord test that failed: the
  // GMRES solves on the exact Jacobian against that factorization, and the
  // solves they ended (an update within the tolerance).
  long fresh_finishing_solves = 0;
  long fresh_finishing_convergences = 0;
  // Finishing begun because the chord's update came within
  // kFinishingChordGate tolerances (ImplicitSettings::finish_near_root),
  // ahead of the exact Hessian and of the cost model.
  long fresh_near_root_finishes = 0;
  // Krylov solves given up because the line search cut kStalledUpdates
  // updates in a row to a small fraction (ImplicitIntegrator::newton()).
  long krylov_stalled_solves = 0;
  // Direct trials given up for the next rung because the line search cut
  // ImplicitSettings::direct_stall_updates updates in a row below
  // kDirectStalledStep.
  long direct_stalled_trials = 0;
  // The largest ratio, over the Newton solves that converged, of the final
  // iterate's residual (VIE: |r_i / m_i|, the velocity error bound where
  // W >= M) to that solve's tolerance; NaN where the method has no such
  // norm. Above 1 where the rate or chord test ended a solve: the
  // residual overstates the error where W is many times M.
  double largest_final_residual_ratio = kNaN;
  // Krylov-path iterates whose updates passed the rate test while the
  // chord's update was not within the tolerance (or no factorization could
  // give one): the solve went on.
  long krylov_rate_test_vetoes = 0;
  // Newton solves on the Krylov path whose GMRES solves took
  // Eisenstat-Walker forcing instead of the constant one: the ten Krylov
  // Newton solves after a failed Newton solve.
  long krylov_eisenstat_walker_solves = 0;
  // GMRES solves against a stale preconditioner (formed at an earlier
  // iterate) abandoned because the products they still needed, at the rate
  // shown, would cost more than refactoring: the preconditioner was
  // refactored at the iterate (a factorizations_krylov_failed) and the
  // solve went on with it, its products kept (one krylov_solve; not in
  // krylov_failures).
  long krylov_stale_solves_abandoned = 0;
  // GMRES's preconditioner solves made in single precision (a supernodal
  // LL^T: CholmodSolver::solve_preconditioner), and factorizations whose
  // first float solve missed W by more than kSinglePrecisionResidual, so
  // that their preconditioner solves ran in double.
  long single_precision_solves = 0;
  long single_precision_declined = 0;
  // Factorizations without the covered couplings made in single precision
  // only (LinearSolver::factorize_preconditioner).
  long single_precision_factorizations = 0;
  // The chord tests' solves (both paths): an estimate of the iterate's
  // error with the last factorization, solved as GMRES's preconditioner
  // solves are (in single precision where those are).
  long chord_solves = 0;
  long factorizations_ladder = 0;      // the chord's reuse ladder and full Newton
  long factorizations_first = 0;       // no factorization yet, or one for another h (x4)
  long factorizations_cost_model = 0;  // GMRES time since the last one exceeded a factorization's
  // A GMRES solve missed its tolerance, or its direction failed the search.
  long factorizations_krylov_failed = 0;
  // Newton matrices factored by the system's own structure (the
  // articulated-body recursion, O(n)), one per Newton iteration; not in
  // iteration_matrix_factorizations, which counts assembled matrices.
  long recursive_factorizations = 0;

  // Wall time split, seconds.
  double jacobian_seconds = 0.0;
  double assembly_seconds = 0.0;
  double factorization_seconds = 0.0;
  double solve_seconds = 0.0;
  double derivative_seconds = 0.0;
  double krylov_seconds = 0.0;  // GMRES solves, their preconditioner solves included
};

// What an integrator says about itself for reports and stats files.
struct IntegratorReport {
  std::string method;           // "vie", ...
  std::string mode;             // "fixed-step" or "error-controlled"
  bool error_estimate = false;  // whether the estimate was computed
  std::string error_estimator;  // how, where a method has a choice
  bool extrapolated = false;
  std::string jacobian_scheme;         // empty for explicit methods
  int jacobian_colours = 0;            // finite differences: column groups of the pattern
  std::string newton_form;             // "mass-matrix" or "generic"
  std::string newton_solve;            // "chord", "krylov", "fresh" or "recursive"
  std::string newton_solve_reason;     // why
  // GMRES's preconditioner solves: "single" or "double" (where the path
  // may solve with GMRES)
  std::string preconditioner_precision;
  std::string linear_solver;           // method in use
  std::string linear_solver_reason;    // why it was chosen
  std::string linear_solver_fallback;  // set if it fell back
  std::vector<std::string> skipped;    // work left out because the scene does not need it
};

}  // namespace stiffsim
