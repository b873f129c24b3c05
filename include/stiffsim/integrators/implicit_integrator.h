#pragma once
// What implicit methods share (DESIGN.md sections 2-4): the Jacobians, the
// four-trial reuse ladder, the Hairer-style Newton convergence test and the
// linear solver behind the iteration matrix. Subclasses hold only their
// method.

#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "stiffsim/integrators/integrator_base.h"
#include "stiffsim/integrators/jacobian_evaluator.h"
#include "stiffsim/integrators/jacobian_scheme.h"
#include "stiffsim/linalg/gmres.h"
#include "stiffsim/linalg/linear_solver.h"
#include "stiffsim/structured_newton_matrix.h"

namespace stiffsim {

enum class NewtonForm {
  kMassMatrix,  // W = M - h D - h^2 K N (v rows scaled by M): keeps sparsity and symmetry
  kGeneric,     // A = I - h J_l, J_l = dl/dy (Drake's form), for checking
};
NewtonForm parse_newton_form(const std::string& name);  // "mass-matrix" | "generic"
std::string to_string(NewtonForm form);

// How IE estimates its local error (DESIGN.md section 3).
enum class ImplicitErrorEstimate {
  kStepDoubling,  // a full step and two half steps; the half steps are propagated
  kTrapezoid,     // the implicit trapezoid rule fed by the IE result; IE is propagated
};

// How a Newton iteration solves its linear systems (DESIGN.md section 2).
enum class NewtonSolve {
  // kRecursive on large exact trees (VIE); otherwise each solve starts on
  // kChord or kKrylov, whichever cost less lately, where the iteration
  // matrix is factored sparse (CHOLMOD or UMFPACK); kChord for small dense
  // systems.
  kAuto,
  kChord,   // the reuse ladder: the last factorization is the Newton matrix
  kKrylov,  // GMRES on the exact Jacobian at the iterate, preconditioned by the last factorization
  kFresh,   // a fresh Jacobian and factorization every iteration (full Newton)
  // The system's structured Newton matrix (structured_newton_matrix.h: an
  // exact tree's articulated-body recursion, O(n)) factored at every
  // iterate, with the exact residual; kAuto takes it for VIE on trees of
  // at least kRecursiveMinDofs velocities.
  kRecursive,
};
NewtonSolve parse_newton_solve(const std::string& name);  // "auto" | ... | "recursive"
std::string to_string(NewtonSolve solve);

// What sets the Newton tolerance of fixed steps without an error estimate
// (ImplicitSettings::step_error_tolerance): "step-error" (true) or
// "accuracy" (false).
bool parse_newton_tolerance(const std::string& name);
std::string newton_tolerance_name(bool step_error_tolerance);

// The precision of GMRES's preconditioner solves
// (ImplicitSettings::single_precision_preconditioner): "single" (true) or
// "double" (false).
bool parse_preconditioner_precision(const std::string& name);
std::string preconditioner_precision_name(bool single);

ImplicitErrorEstimate parse_error_estimator(const std::string& name);  // "trapezoid" | "doubling"
std::string to_string(ImplicitErrorEstimate estimator);

struct ImplicitSettings {
  JacobianScheme jacobian = JacobianScheme::kAnalytic;
  LinearSolverKind linear_solver = LinearSolverKind::kAuto;
  NewtonForm newton_form = NewtonForm::kMassMatrix;
  bool full_newton = false;  // fresh Jacobian and factorization every iteration
  NewtonSolve newton_solve = NewtonSolve::kAuto;  // kFresh sets full_newton
  // Krylov path: GMRES products per linear solve before the solve counts
  // as failed (the preconditioner is then refactored), and its forcing
  // term, the constant relative tolerance of its linear solves (but in the
  // Newton solves that follow a failed one: see newton()).
  int max_krylov_iterations = 40;
  double krylov_forcing = 0.2;
  // The largest Eisenstat-Walker forcing term (recursive path; Krylov path
  // after a failed solve).
  double max_forcing = 0.1;
  bool reuse = true;  // false: fresh Jacobian and factorization every step attempt
  // Fixed steps: the direct Newton solves that search on G form their
  // matrices with the springs' primal-dual tension estimate
  // (JacobianRequest::tension_positions). false: the exact tension.
  bool tension_estimate = true;
  // Step doubling (error control, --error-estimate): the big and first half
  // steps start from first iterates corrected by the last doubling's
  // estimate of x'' where that estimate is smooth and, for methods with an
  // incremental potential G, where the corrected big-step guess lowers G;
  // the second half step from x_half + (x_big - x_n) / 2 (see
  // ImplicitIntegrator::step_doubling). false: the uncorrected guesses
  // (the midpoint and x_big; the predictor stays).
  bool corrected_guesses = true;
  // Fixed steps without an estimate (VIE): Newton starts this share of the
  // way from v_n to the predictor (v_n + h a_n, the last step's velocity
  // change extrapolated), where that point is lower on the incremental
  // potential than v_n (VelocityImplicitEuler::first_iterate), unless the
  // predictor missed the last step's result by less than a tenth of its
  // velocity change: then the predictor. The predictor itself still sets
  // the step's Newton tolerance. 1: the predictor.
  double predictor_share = 0.5;
  // Full Newton on the Krylov path's machinery (auto's fresh start, the
  // rescue at fixed steps) finishes with GMRES on the exact Jacobian where
  // a finishing solve's products cost less than this share of a Jacobian
  // and factorization (see ImplicitIntegrator::finishing_pays). 0: never.
  double finishing_share = 0.3;
  // Where full Newton's chord test fails but its update is within
  // kFinishingChordGate tolerances, finishing follows at once, ahead of the
  // exact Hessian and of the cost model (see newton()); finishing_share = 0
  // still turns finishing off. false: only where finishing_share allows.
  bool finish_near_root = true;
  // The Krylov path's preconditioner is factored, for large symmetric
  // iteration matrices, without the couplings the system says stiffer
  // elements cover (System::covered_couplings: a cloth's or rope's bend
  // springs), which make most of the factor's fill; it then approximates W
  // within 2 / kCoverageRatio where the sheet is flat. The chord, whose
  // Newton matrix it would be, factors W (full Newton leaves them out and
  // refines: refine_without_covered), and so does a Krylov rung after a
  // failed chord or fresh start (see solve_step()). false: W everywhere,
  // full Newton's too.
  bool drop_covered_couplings = true;
  // Full Newton (the fresh start, the rescue, --newton-solve fresh, and
  // the exact Hessian) factors W without the covered couplings too, where
  // drop_covered_couplings leaves any out, and solves with W itself: GMRES
  // on W, held beside its factor, preconditioned by that factor, to a
  // relative residual of kRefinedSolveTolerance, so the Newton direction
  // is W's to well below the tolerances that judge it. W is factored whole
  // where GMRES needs more than refined_solve_products products. On
  // cloth_stiff.yaml, whose steps are mostly full Newton, a factorization
  // without the bend couplings costs 0.6x one of W. false: full Newton
  // factors W whole.
  bool refine_without_covered = true;
  int refined_solve_products = 20;
  // Full Newton as the last rung before the step is halved (the rescue at
  // fixed steps, the direct ladder's last rung, --newton-solve fresh) goes
  // on past its iteration budget, up to kExtendedFactor times
  // max_newton_iterations, while its iterate stays near the root (see
  // ImplicitIntegrator::newton). false: the budget ends it.
  bool extend_near_root = true;
  // A direct trial (the chord, on the last factorization) that another
  // rung follows is given up once the line search has cut this many of its
  // updates in a row below kDirectStalledStep; 0: never. Its matrix then
  // misleads it: on the first step of a flat sheet at rest, whose membrane
  // had no transverse stiffness when the matrix was formed, the 100x100
  // sheet at 1/60 took 10 chord iterations at alpha = 1/8 to 1/32 before
  // the Krylov rung converged in 9; given up after 3, that step took
  // 14-15 Newton iterations instead of 19-20, and 0.83 s instead of 0.98 s
  // (medians of 5 alternated runs). The Krylov path's own rule is
  // kStalledUpdates.
  int direct_stall_updates = 3;
  // Full Newton on a rung that another follows (auto's fresh start, which
  // the Krylov rung follows) factors the exact Hessian of
  // the incremental potential G (compressed springs' transverse stiffness
  // kept, each spring's tension as the iterate has it) once its update is
  // within kExactHessianGate tolerances, wherever a Cholesky LL^T finds that
  // matrix positive definite. Where it is not, and for the rest of the
  // solve once it was not or the search cut its direction, the clamped
  // matrix on the tension estimate (see newton()). false: that matrix
  // throughout.
  bool exact_hessian_near_root = true;
  // A diagnostic of the convergence tests: from every iterate a Newton
  // solve accepts, Newton on the exact Jacobian (GMRES on residual
  // differences, preconditioned by the last factorization, full steps) is
  // run on to the root, and the iterate's distance from it is recorded in
  // tolerances (IntegratorStatistics::largest_root_distance_ratio). The
  // tests judge an iterate by estimates (the chord's update from a matrix
  // formed at another iterate, a rate, a residual bound that holds for
  // W >= M); this measures what they accepted. The run itself is
  // unchanged: its counters and the cost model leave the check out, the
  // wall time includes it.
  bool verify_roots = false;
  int max_newton_iterations = 10;
  // Newton stops when eta |dx| (or the residual) <= kappa * accuracy
  // (Hairer & Wanner IV.8; see step_error_tolerance for fixed steps); 0.05
  // is the middle of their recommended [0.01, 0.1].
  double newton_kappa = 0.05;
  // Iteration matrices may use the definite spring approximation
  // (JacobianRequest::definite) so CHOLMOD's LL^T keeps working.
  bool definite_iteration_matrix = true;
  // In passive scenes (Capabilities::passive) a converged step whose energy
  // rose is examined: it is rejected as a spurious root when it is a saddle
  // of the incremental potential (M - h D - h^2 K not positive definite) or
  // when it gained more than implicit Euler's O(h^2) gain allows (see
  // passes_energy_guard()); at fixed steps without an error estimate it is
  // also compared with two half steps and replaced by their end where that
  // is a lower point of the incremental potential (keep_lowest_root()).
  bool energy_guard = true;
  // Fixed steps without an error estimate (VIE): a Newton solve converges to
  // kappa times the larger of the accuracy and the step's own local error
  // (estimated from the last step), not to kappa * accuracy alone. Error
  // control keeps the local error below the accuracy, so there the two
  // agree; at a fixed step the local error may be orders of magnitude
  // larger, and converging far below it buys nothing the step keeps (the
  // widening is bounded: kMaxToleranceWidening). False:
  // kappa * accuracy always (a solve to the accuracy, for comparisons with
  // the exact implicit Euler recursion).
  bool step_error_tolerance = true;
  // The kappa of that widened tolerance: a solve's error at most this
  // fraction of its step's own local error, as CVODE's nonlinear
  // convergence coefficient (0.1 of the error its step's test allows).
  // With 0.05 the folds of a falling sheet at 1/60 circled their nearly
  // singular roots at updates of 1-4 tolerances for 10-40 iterations; on
  // models/cloth.yaml at 1/60 to 0.5 s the trajectory's distance from the
  // same steps solved to 0.0005 of their own error was alike at 0.05 and
  // 0.1 (5e-5 to 7e-3 m, against 4e-3 to 0.12 m from steps 83 times
  // smaller), at 0.78-0.89 the Newton iterations (README: "Newton tolerance at
  // fixed steps").
  double step_error_kappa = 0.1;
  // GMRES's preconditioner solves (the Krylov path) in single precision
  // where the factor is a supernodal LL^T whose float solve passes its
  // check (CholmodSolver::solve_preconditioner); false: in double always.
  bool single_precision_preconditioner = true;
  // Step-doubling methods propagate 2 x_small - x_big (second order) rather
  // than x_small; fixed-step mode then also takes the three solves.
  bool extrapolate = false;
  // IE only: how the local error is estimated.
  ImplicitErrorEstimate error_estimator = ImplicitErrorEstimate::kTrapezoid;
};

class ImplicitIntegrator : public IntegratorBase {
 public:
  ImplicitIntegrator(const System& system, IntegratorSettings settings, ImplicitSettings implicit);
  IntegratorReport report() const override;
  const ImplicitSettings& implicit_settings() const { return implicit_; }
  // Local extrapolation of the step-doubling pair: x_e = 2 x_small - x_big.
  bool extrapolating() const { return implicit_.extrapolate; }
  // The Krylov path's cost model: the share of a GMRES solve's seconds
  // spent on products beyond fresh_products (at least 1), those a fresh
  // factorization takes; what a new factorization would save.
  static double stale_solve_excess(double seconds, int products, double fresh_products);

 protected:
  enum class Convergence { kConverged, kDiverged, kNotYet };
  // The test of DESIGN.md section 2 / Drake's CheckNewtonConvergence, on the
  // weighted norm of the full-state change dx. `iteration` counts from 0.
  Convergence check_newton_convergence(int iteration, const Eigen::VectorXd& x,
                                       const Eigen::VectorXd& dx, double dx_norm,
                                       double last_dx_norm);
  // The Newton tolerance is kappa * accuracy, below it for an
  // extrapolating step (extrapolation_newton_tolerance()), and for a fixed
  // step without an error estimate set here from the step's estimated
  // local error (weighted norm; 0 when unknown), as
  // ImplicitSettings::step_error_tolerance says.
  void use_step_error_tolerance(double local_error);
  // ... by at most this factor over kappa * accuracy. Beyond it a violent
  // step's estimate left the stiff modes loosely converged, and the next
  // steps paid in halvings: the 16x16 stiff cloth (k = 1e6) at 1/60 over
  // 2 s, three runs each, had 22-62 halvings unbounded, 3-7 at 100x, 5-8
  // at 30x, 4-13 at 10x, and 15-17 with no widening; the 32x32 cloth of
  // models/cloth.yaml gained up to 100x (1 halving, 2.9-3.0 s; 10x: 2-4,
  // 3.3-4.3 s).
  static constexpr double kMaxToleranceWidening = 100.0;
  bool reuse_enabled() const { return implicit_.reuse && !implicit_.full_newton; }
  // Takes the system's structured Newton matrix when the settings ask for
  // it (or, under kAuto, when the system has one and `auto_allowed`); the
  // method calls it from its constructor. Throws InputError when
  // kRecursive is asked for and the method or system cannot do it.
  void choose_structured_newton_matrix(bool method_allows, const std::string& why_not);
  bool structured() const { return structured_ != nullptr; }
  // Below this many velocities the chord on the assembled dense matrix
  // (one factorization reused over many steps, analytic Jacobians) costs
  // less per step than the recursion's three factorizations and eight
  // residuals: BM_ExactChainStep (k = 1e4, h = 1 ms) measured 0.103 against
  // 0.235 ms at 100 links, 0.92 against 0.78 ms at 300, 7.0 against 2.5 ms
  // at 1000; the ratio's power law crosses 1 near 250.
  static constexpr int kRecursiveMinDofs = 250;
  // The assembled matrices' patterns into jacobians_ (not needed, and not
  // built, on the structured path).
  void load_jacobian_patterns() { jacobians_ = system_.jacobian_pattern(); }

  // Sizes the shared Newton workspaces for `unknowns` Newton unknowns
  // (nv + nz for VIE, nx for IE); subclasses call it from do_initialize().
  void initialize_newton(int unknowns);

  // --- The method, as the shared Newton solver sees it. ---
  // Force Jacobians for a step of size h from (t, x); VIE linearizes at
  // q + h N(q) v, IE at x itself (h unused). Must end in
  // compute_force_jacobians().
  virtual void compute_jacobian(double t, const Eigen::VectorXd& x, double h) = 0;
  // False when compute_jacobian() ignores h (a failure at h then leaves a
  // Jacobian that is still fresh for h / 2).
  virtual bool jacobian_depends_on_step() const = 0;
  // Assembles the iteration matrix of the current solve for step h from the
  // last Jacobian; *symmetric says whether its values are symmetric (and
  // expected positive definite, with the definite spring approximation).
  virtual const SparseMatrix& form_iteration_matrix(double h, bool* symmetric) = 0;
  // form_iteration_matrix() and factor_iteration_matrix(); refined: full
  // Newton's matrix, which may leave the covered couplings out of its
  // factor and refine each solve (ImplicitSettings::refine_without_covered).
  bool form_and_factor(double h, bool refined = false);
  // Sets the dependent parts of an iterate from its unknowns (VIE: q from v).
  virtual void complete_iterate(double h, const Eigen::VectorXd& x0, Eigen::VectorXd* x) {
    (void)h, (void)x0, (void)x;
  }
  // Offset of the unknowns in x (VIE: nq, IE: 0).
  virtual int unknowns_offset() const = 0;
  // Residual of the step equations at the iterate x (exact, whatever the
  // iteration matrix lags).
  virtual void residual(double t, double h, const Eigen::VectorXd& x0, const Eigen::VectorXd& x,
                        Eigen::VectorXd* r) = 0;
  // Squared norm the line search decreases.
  virtual double merit(const Eigen::VectorXd& r) const { return r.squaredNorm(); }
  // Infinity norm of the residual in the units of the unknowns' changes
  // (VIE: velocities, r_i / m_i), where the iteration matrix bounds the
  // error by it (W >= M); infinity where no such bound is known.
  virtual double residual_norm(const Eigen::VectorXd& r) const {
    (void)r;
    return std::numeric_limits<double>::infinity();
  }
  // Row scaling under which the merit is the residual's squared 2-norm
  // (VIE: 1 / m_i on the v rows); empty for none. Krylov solves minimize
  // the linear residual in that norm, so their directions descend the merit.
  virtual const Eigen::VectorXd& residual_scaling() { return residual_scale_; }
  Eigen::VectorXd residual_scale_;
  // Where the method can extrapolate the unknowns of the step from the last
  // accepted steps (VIE: v_n + h (v_n - v_{n-1}) / h_{n-1}), the first
  // iterate of a step from the current state; otherwise x0 itself.
  virtual const Eigen::VectorXd& predictor(double h, const Eigen::VectorXd& x0) {
    (void)h;
    return x0;
  }
  // True when the Newton iterations solve by GMRES on the exact Jacobian
  // (decided at the first factorization, see NewtonSolve).
  bool krylov_path() const { return krylov_; }
  // Called once per Newton trial before the first iteration.
  virtual void begin_newton(double t0, double h, const Eigen::VectorXd& x0) {
    (void)t0, (void)h, (void)x0;
  }
  // An optional potential G whose gradient is the residual (VIE's incremental
  // potential): when potential_search() is true for a rung, the line search
  // demands sufficient decrease of G rather than of the merit.
  virtual bool potential_search(int trial) const {
    (void)trial;
    return false;
  }
  // Whether potential() is available at all (the Krylov path searches on it
  // from the first iteration).
  virtual bool has_potential() const { return false; }
  // G (without its damping term) at the first iterate x, completed, of a
  // step of size h from x0 at t0; NaN where the method has no potential.
  virtual double guess_potential(double t0, double h, const Eigen::VectorXd& x0,
                                 const Eigen::VectorXd& x) {
    (void)t0, (void)h, (void)x0, (void)x;
    return std::numeric_limits<double>::quiet_NaN();
  }
  // G at the iterate x (new_iterate: a new Newton iterate, where G's
  // frozen terms are taken; false: a line-search trial point, with those
  // of the last iterate). jacobian_at_x: jacobians_ were just evaluated at
  // x itself by the analytic scheme (full Newton's iterate), so their dF/dv
  // is x's damping matrix (JacobianRequest).
  virtual double potential(double t, const Eigen::VectorXd& x0, const Eigen::VectorXd& x, double h,
                           bool new_iterate, bool jacobian_at_x = false) {
    (void)t, (void)x0, (void)x, (void)h, (void)new_iterate, (void)jacobian_at_x;
    return 0.0;
  }
  // Round-off level of G near g (differences below it are noise).
  virtual double potential_roundoff(double g) const { return 1e-11 * std::abs(g); }

  // One implicit solve of a step of size h from (t0, x0) starting at the
  // guess: the reuse ladder's trials 1-3, then full Newton, each with a
  // line search. Counts one newton_solves. Result in *x.
  bool solve_step(double t0, double h, const Eigen::VectorXd& x0, const Eigen::VectorXd& guess,
                  Eigen::VectorXd* x);

  // The step-doubling step: full step, two half steps from the same
  // solver; the half steps are propagated (or, when extrapolating,
  // 2 x_small - x_big), the error is x_big - x_small. The full step's work
  // counts as the error estimator's (as in Drake).
  bool step_doubling(double h);
  // guess + c x'' (the estimate from the last step doubling, where it is
  // smooth) into *corrected, or guess. With decide (the big step), the
  // correction is trusted where G of the step of size h from x0 at t0 is
  // lower there (or the method has no G); otherwise (the first half step)
  // it follows that decision.
  const Eigen::VectorXd& corrected_guess(double t0, double h, const Eigen::VectorXd& x0,
                                         const Eigen::VectorXd& guess, double c, bool decide,
                                         Eigen::VectorXd* corrected);
  // Fixed steps without an error estimate: whether the converged step *x of
  // size h from (t0, x0) is the step's root, or a root of the step
  // equations the minimizer of G is not (see the definition). Consulted
  // only where the step gained energy beyond round-off; then two half
  // steps are solved (into x_half_, x_small_: not within step_doubling())
  // and where their end is a lower point of G, it replaces *x (counted in
  // energy_guard_rejections). False when the half steps fail.
  bool keep_lowest_root(double t0, double h, const Eigen::VectorXd& x0, Eigen::VectorXd* x);
  // The Newton tolerance of the three solves of an extrapolating step of
  // size h.
  double extrapolation_newton_tolerance(double h) const;
  // Adds the work done since `before` to the error_estimator_* counters.
  static void add_estimator_share(const IntegratorStatistics& before, IntegratorStatistics* stats);

  // Force Jacobians at the predicted state (q + h N(q) v, v, z): linearized
  // where the step is heading, as Drake's VIE does (a flat cloth at rest has
  // no transverse stiffness at x itself). The point is left in
  // linearization_.
  void compute_force_jacobians_ahead(double t, const Eigen::VectorXd& x, double h);
  // Evaluates dF/dq, dF/dv, ... at (t, x) into jacobians_ by the configured
  // scheme, counting jacobian_evaluations and the derivative evaluations it
  // used.
  void compute_force_jacobians(double t, const Eigen::VectorXd& x);
  // Chooses, analyzes (once) and factors the iteration matrix of the current
  // solve, formed for step h; counts factorizations. Returns false if the
  // matrix is singular. preconditioner: the covered couplings may be left
  // out; refined: that factor will precondition full Newton's refined
  // solves only, and may be made in single precision.
  bool factor_iteration_matrix(const SparseMatrix& matrix, bool symmetric, double h,
                               bool preconditioner = false, bool refined = false);
  // dx = A^-1 rhs with the current factorization; as a preconditioner
  // (GMRES), in the solver's single precision where it has one
  // (LinearSolver::solve_preconditioner). refine: a factor without the
  // covered couplings made for full Newton is refined to W's solve
  // (solve_refined()); false: its own solve (an estimate, as the chord
  // test's).
  void solve_iteration_matrix(const Eigen::VectorXd& rhs, Eigen::VectorXd* dx,
                              bool preconditioner = false, bool refine = true);
  // dx = W^-1 rhs for a factor without the covered couplings: GMRES on the
  // whole W it was formed from, that factor preconditioning; W is factored
  // whole (and the slot solves directly from then on) where GMRES misses
  // kRefinedSolveTolerance within ImplicitSettings::refined_solve_products.
  void solve_refined(const Eigen::VectorXd& rhs, Eigen::VectorXd* dx);
  bool iteration_matrix_factored() const { return matrices_[active_].factored; }
  void invalidate_factorization() {
    for (auto& m : matrices_) m.factored = false;
  }
  // Methods with a second iteration matrix (IE's trapezoid estimate: I - h/2 J
  // beside I - h J) switch between them; the Jacobian is shared.
  void use_iteration_matrix(int index) { active_ = index; }
  int active_iteration_matrix() const { return active_; }
  // While suspended, converged solves skip the energy guard (a solve whose
  // result is only compared, never propagated).
  void suspend_energy_guard(bool suspended) { energy_guard_suspended_ = suspended; }
  // Marks the Jacobian stale, so the ladder's trial 3 recomputes it.
  void mark_jacobian_stale() { jacobian_step_t_ = std::numeric_limits<double>::quiet_NaN(); }

  ImplicitSettings implicit_;
  JacobianEvaluator jacobian_evaluator_;
  ForceJacobians jacobians_;
  bool jacobians_valid_ = false;
  Eigen::VectorXd x_big_, x_half_, x_small_;
  // Step doubling's estimate of x'' (4 (x_big - x_small) / h^2), made by
  // the doubling that started at second_derivative_t0_, the one before it,
  // whether the two agree (smooth) and whether this step's big-step guess
  // took it (trusted), and the first iterates built with it
  // (corrected_guess()).
  Eigen::VectorXd second_derivative_, second_derivative_previous_, x_guess_;
  double second_derivative_t0_ = std::numeric_limits<double>::quiet_NaN();
  bool second_derivative_smooth_ = false, second_derivative_trusted_ = false;
  Eigen::VectorXd linearization_;  // where compute_force_jacobians_ahead() linearized
  // Acceleration (and the rates it comes from) where the Jacobian is taken,
  // for the inertial term of a configuration-dependent M.
  Eigen::VectorXd inertial_F_, inertial_zdot_, inertial_acceleration_;
  bool iterate_acceleration_ = false;  // inertial_acceleration_ set by a full Newton iterate
  // The next Jacobian exact (no definite clamp, no tension estimate), and
  // the next factorization only where the matrix is positive definite
  // (factor_exact_hessian()).
  bool exact_jacobian_ = false;
  bool factor_if_definite_ = false;

 private:
  // The refresh ladder: kSkip when the rung would rebuild the matrix that
  // just failed, kGiveUp at trial 4.
  enum class Refresh { kProceed, kSkip, kGiveUp };
  Refresh refresh_matrices(double t, const Eigen::VectorXd& x, double h, int trial);
  void compute_jacobian_and_factor(double t, const Eigen::VectorXd& x, double h);
  // `rescue`: the ladder's rescue rung (solve_step), with twice the
  // ordinary iteration budget. `last`: no rung follows before the step is
  // halved (full Newton then goes on near the root:
  // ImplicitSettings::extend_near_root).
  bool newton(double t0, double h, const Eigen::VectorXd& x0, const Eigen::VectorXd& guess,
              int trial, Eigen::VectorXd* x, bool rescue = false, bool last = false);
  // The Krylov path's Newton direction at the iterate x: GMRES
  // (newton_gmres()) preconditioned by the last factorization, which is
  // refactored at x when the cost model or a failed solve says so. False
  // when no usable matrix could be factored.
  bool krylov_direction(double tf, double h, const Eigen::VectorXd& x0, const Eigen::VectorXd& x,
                        const Eigen::VectorXd& rhs, double forcing, bool may_abandon,
                        Eigen::VectorXd* dy);
  // Decides the Newton solve strategy once the first matrix is factored.
  void choose_newton_solve(long unknowns);
  // Jacobian at the iterate x itself (full Newton, the Krylov path); marks
  // it stale for the reuse ladder.
  void compute_jacobian_at_iterate(double tf, double h, const Eigen::VectorXd& x0,
                                   const Eigen::VectorXd& x);
  // Whether the factorization was formed for a step more than
  // kReuseStepRatio away from h.
  bool formed_far_from(double h) const {
    const double h_f = matrices_[active_].h;
    return h_f > kReuseStepRatio * h || h > kReuseStepRatio * h_f;
  }
  // Factors the current iteration matrix for the Krylov path, timing it for
  // the cost model.
  bool refactor_preconditioner(const SparseMatrix& matrix, bool symmetric, double h);
  // False when the converged step x of size h from x0 is a spurious root in
  // a passive scene (see the definition); counted in energy_guard_checks
  // and energy_guard_rejections.
  bool passes_energy_guard(double tf, double h, const Eigen::VectorXd& x0,
                           const Eigen::VectorXd& x);
  // E(x) - E(x0), and its round-off allowance in *allowance.
  double energy_gain(const Eigen::VectorXd& x0, const Eigen::VectorXd& x, double* allowance);
  // True unless the energy guard is on and x gained energy over x0 beyond
  // round-off (then passes_energy_guard() would consult its criterion).
  bool energy_within_round_off(const Eigen::VectorXd& x0, const Eigen::VectorXd& x);
  // E(x) for the guard (a passive scene: no dependence on t), remembered for
  // the last two states: a step's end is the next solve's start, and the
  // solves of step doubling share their starts.
  double guard_energy(const Eigen::VectorXd& x);
  // dq^T K(q) dq with K = dF/dq of the conservative forces alone (the
  // exact Jacobian at v = 0): minus the potential's curvature along dq.
  double negative_curvature(double t, const Eigen::VectorXd& q, const Eigen::VectorXd& dq);
  // Whether M - h D - h^2 K at the state x (exact K, D; symmetric part) is
  // positive definite: the Hessian of the incremental potential there.
  bool incremental_hessian_definite(double t, double h, const Eigen::VectorXd& x);

  // Relative size of an update at the level of round-off (Drake's
  // IsUpdateZero tolerance).
  static constexpr double kZeroUpdate = 10 * std::numeric_limits<double>::epsilon();
  // Trials 1-3 are the reuse ladder; trial 4 iterates with a fresh Jacobian
  // at every iterate before the step is given up.
  static constexpr int kFullNewtonTrial = 4;
  // The Krylov path's rung (see solve_step).
  static constexpr int kKrylovTrial = 5;
  // NewtonSolve::kAuto: the ways a solve can start (the fresh start only at
  // fixed steps), the decay of their measured costs per solve, and how
  // often the costlier ones are retried.
  static constexpr int kChordStart = 0, kKrylovStart = 1, kFreshStart = 2;
  static constexpr int kStarts = 3;
  static constexpr double kFreshStartMargin = 0.8;       // see choose_start()
  static constexpr double kFreshStartIterations = 10.0;  // likewise
  static constexpr double kStartCostDecay = 0.9;
  static constexpr int kStartExploration = 16;
  int choose_start();
  // The structured path's rung: the recursion at every iterate.
  static constexpr int kStructuredTrial = 6;
  // Factors the structured matrix at the iterate x, timed and counted.
  bool factor_structured(const Eigen::VectorXd& x, double h);
  // The Newton direction at the iterate x (rhs = minus the residual there)
  // to the forcing term's relative tolerance: GMRES on the exact Jacobian,
  // applied matrix-free by a difference of residuals, preconditioned by the
  // current factorization (the structured matrix at x, or the Krylov path's
  // last assembled one). Counts the Krylov statistics; *seconds is its wall
  // time.
  // With refactor_when_stale, a solve given up (abandon_products) goes on
  // with the iterate's own factorization (refactor_preconditioner()); it
  // is abandoned only where that fails.
  GmresResult newton_gmres(double tf, double h, const Eigen::VectorXd& x0, const Eigen::VectorXd& x,
                           const Eigen::VectorXd& rhs, double forcing, double abandon_products,
                           Eigen::VectorXd* dy, double* seconds, bool refactor_when_stale = false);
  // ImplicitSettings::verify_roots: runs Newton on the exact Jacobian from
  // the accepted iterate x to the root and records x's distance from it in
  // the root_* statistics, leaving every other counter, and the cost
  // model's timings, as they were. At most kRootCheckIterations updates;
  // the root is reached once an update is below kRootCheckUpdate
  // tolerances.
  void check_root(double tf, double h, const Eigen::VectorXd& x0, const Eigen::VectorXd& x);
  static constexpr int kRootCheckIterations = 10;
  static constexpr double kRootCheckUpdate = 1e-3;
  static constexpr double kRootCheckForcing = 1e-4;
  Eigen::VectorXd root_x_, root_r_, root_dy_;
  double root_check_seconds_ = 0.0;  // this solve's, left out of its cost
  Eigen::VectorXd x_product_, r_product_;
  std::unique_ptr<StructuredNewtonMatrix> structured_;
  // A factorization formed for a step more than this factor away from the
  // current one is refactored before its first use (refresh_matrices).
  static constexpr double kReuseStepRatio = 4.0;
  // The tolerance an iterate that gained energy is polished to before the
  // energy guard judges it, in the solve's tolerance (see newton()).
  static constexpr double kGuardPolish = 0.01;
  // The Krylov path's Newton iteration budget, in max_newton_iterations
  // (see newton()).
  static constexpr int kKrylovIterationFactor = 5;
  // Covered couplings are left out of matrices of at least this size.
  static constexpr long kCoveredMinUnknowns = 2000;
  // A direct solve against a factor without the covered couplings is
  // refined by GMRES on W to this relative residual (see solve_refined()
  // and ImplicitSettings::refine_without_covered). Looser
  // tolerances changed full Newton's path: on cloth_stiff.yaml at 1e-3,
  // 1e-4 and 1e-5 (8 starts each) runs took 12%, 10% and 6% more
  // factorizations than at 1e-6, which took as many as with W factored
  // whole. The unweighted residual is that of the stiff directions; the
  // soft ones' share of the direction is resolved only well below it.
  static constexpr double kRefinedSolveTolerance = 1e-6;
  // The rescue rung's budget, the last rung's extension near the root, in
  // max_newton_iterations, and what near means: the last update within
  // kChordTestGate of the Newton tolerance and the residual within
  // kNearRootResidual of it (see newton()).
  static constexpr int kRescueIterationFactor = 2;
  static constexpr int kExtendedFactor = 8;
  static constexpr double kNearRootResidual = 100.0;
  // Halvings of a Newton step before the iteration counts as diverged.
  static constexpr int kMaxBacktracks = 8;
  // The Krylov path's line search compares a trial's residual with the
  // largest of the current one and the last kMeritMemory accepted ones
  // (Grippo, Lampariello & Lucidi's non-monotone rule; see newton()).
  // Eight rather than three: paired against three (starts at accuracy 1e-3
  // (1 + k 1e-7)), the 100x100 sheet at 1/60 to 0.5 s 0.96x the time (20
  // starts, 0.96 and 0.97 in two ensembles), cloth_stiff.yaml 0.95-0.96x
  // (30), cloth.yaml at 1/60 for 2 s 0.95x and 1.01x (12 and 20), with no
  // halving in any run either way; six gave 0.88x, 1.01x and 0.97x (6, 12
  // and 10 starts), none (monotone) 1.26x on the 100x100 sheet.
  static constexpr int kMeritMemory = 8;
  // The Krylov path's chord test (see newton()) runs after updates at most
  // this many times the Newton tolerance.
  static constexpr double kChordTestGate = 10.0;
  // Full Newton factors the exact Hessian after updates at most this many
  // times the Newton tolerance (ImplicitSettings::exact_hessian_near_root).
  // On cloth_stiff.yaml (8 starts each, alternated; 8 starts leave about
  // 8% of noise) the first update from the predictor is 35-55 tolerances,
  // the second 2-10. With the exact Hessian from the second iteration on:
  // 1.8x the time and halvings in 2 runs of 8. Against the exact Hessian
  // from the third iteration on, whatever the update: a gate of 10 took
  // 1.08x the time, a gate of 20 0.92x (it also takes the second
  // iteration where the first update came within 20); a gate of 30 took
  // 1.12x the time of 20.
  static constexpr double kExactHessianGate = 20.0;
  // Full Newton's finishing iterations (see newton()): GMRES's forcing
  // term, and the contraction an update must show to go on finishing.
  static constexpr double kFinishingForcing = 0.1;
  static constexpr double kFinishingContraction = 0.5;
  // A finishing update the search cut below this ends finishing for the
  // solve.
  static constexpr double kFinishingCut = 0.25;
  // Full Newton finishes, ahead of the exact Hessian and whatever the cost
  // model says, where the chord's update is within this many tolerances
  // (ImplicitSettings::finish_near_root).
  static constexpr double kFinishingChordGate = 10.0;
  // Whether a finishing solve is expected to cost less than
  // ImplicitSettings::finishing_share of the Jacobian and factorization it
  // replaces, at the products finishing solves took lately (decayed as the
  // starts' costs) and the measured time of a product. Only about one
  // finishing solve in three ends the Newton solve, and a finishing
  // iteration that fails costs an iteration; so the share. Measured
  // against no finishing
  // (alternated runs): a 48x48 sheet of k = 1e6 springs at 1/60 for
  // 0.5 s 0.74x the time at 0.3 and 0.92x at 1; cloth_stiff.yaml (32x32)
  // 1.00x and 0.98x. The 16x16 sheet of k = 1e8, where a product costs a
  // larger share of a factorization, took 1.07-1.13x the time of 1a682af
  // (before finishing) at 1, and 0.89x of that at 0.3.
  bool finishing_pays() const;
  // Full Newton's exact Hessian at the iterate x (exact_hessian_near_root),
  // factored where it is positive definite; false where it is not, or
  // where the solver in use cannot tell (no Cholesky LL^T).
  bool factor_exact_hessian(double tf, double h, const Eigen::VectorXd& x0,
                            const Eigen::VectorXd& x);
  // The finishing direction at the iterate x (rhs = minus the residual):
  // GMRES on the exact Jacobian against the factorization made at an
  // earlier iterate of this solve. False where GMRES missed its forcing.
  bool finishing_direction(double tf, double h, const Eigen::VectorXd& x0, const Eigen::VectorXd& x,
                           const Eigen::VectorXd& rhs, Eigen::VectorXd* dy);
  double finishing_products_ = 0.0, finishing_weight_ = 0.0;  // decayed, per finishing solve
  // A Krylov solve whose search cut this many updates in a row below
  // kStalledStep has stalled and is given up (see newton()).
  static constexpr int kStalledUpdates = 5;
  static constexpr double kStalledStep = 1.0 / 32;
  // The direct trial's threshold (ImplicitSettings::direct_stall_updates):
  // higher than the Krylov path's, as a chord iteration's updates cost a
  // solve each and the rung after it recovers at a factorization.
  static constexpr double kDirectStalledStep = 1.0 / 8;

  struct IterationMatrix {
    LinearSolverChoice solver;
    bool factored = false;
    double h = 0.0;  // the step it was formed for
    // The factorization without the covered couplings (a preconditioner's:
    // see factored_matrix()), and whether it is the one in use.
    LinearSolverChoice covered;
    bool covered_active = false;
    // Full Newton's W where its factor leaves the covered couplings out
    // (ImplicitSettings::refine_without_covered): the direct solves apply
    // it and refine (solve_refined()).
    bool refined = false;
    bool if_definite = false;  // factored by factorize_if_definite (an exact Hessian)
    SparseMatrix whole;
  };
  IterationMatrix matrices_[2];
  int active_ = 0;
  // W without the covered couplings (ImplicitSettings::drop_covered_couplings):
  // each left-out block W_ab is added to W_aa, which removes the covering
  // spring's whole share of W. Returns W itself where nothing is left out.
  // W must be symmetric.
  const SparseMatrix& factored_matrix(const SparseMatrix& W);
  struct CoveredCouplings {
    bool examined = false;  // the pattern was built, or found not to apply
    SparseMatrix matrix;
    std::vector<int> source;          // per entry of matrix: the entry of W it copies
    std::vector<int> left_out, twin;  // W's entries left out; where each adds in matrix
  };
  CoveredCouplings covered_;
  bool covered_allowed_ = false;  // this Newton solve started on the Krylov path
  // Krylov path state: chosen once per run; the cost model compares the
  // GMRES time spent since the last factorization beyond one product per
  // converged solve (what a fresh factorization would have cost in
  // products) with the measured time of that factorization.
  // Why the next factorization happens, for the stats.
  enum class FactorReason { kLadder, kFirst, kCostModel, kKrylovFailed };
  // The Krylov path's preconditioner, refactored at the iterate x.
  bool refactor_preconditioner(double tf, double h, const Eigen::VectorXd& x0,
                               const Eigen::VectorXd& x, FactorReason reason);
  FactorReason factor_reason_ = FactorReason::kLadder;
  bool newton_solve_chosen_ = false;
  bool krylov_ = false;
  std::string newton_solve_reason_;
  double last_factorization_seconds_ = 0.0;
  double last_jacobian_seconds_ = 0.0;  // the last force Jacobian's evaluation
  // The Krylov path's last refactoring (Jacobian, assembly, factorization)
  // and last GMRES product (residual and preconditioner solve), measured;
  // they set a stale preconditioner's budget of products (krylov_direction).
  double last_refactor_seconds_ = 0.0;
  double product_seconds_ = 0.0;
  // The linear solvers' single-precision setups (a float copy of the factor
  // and its check, LinearSolverCounters), made at a factorization's first
  // preconditioner solve: newton_gmres counts them with the factorization,
  // not as products (a fresh solve of one or two products would otherwise
  // report a product time several times the real one, and the next stale
  // solve's budget of products would shrink by as much).
  double preconditioner_setup_seconds_ = 0.0;
  // The products a solve with a fresh preconditioner is expected to take
  // at the constant forcing (1-6 on the folding 100x100 sheet); no solve
  // is abandoned before this many.
  static constexpr double kFreshSolveProducts = 3.0;
  double krylov_excess_seconds_ = 0.0;
  // The Krylov excess of the current (or last) solve, and the share of a
  // factorization beyond which the next solve starts with a fresh one.
  // Measured on cloth.yaml at a fixed 1/60 over 0.2 s (--newton-solve
  // krylov, five runs): without the rule 55 Newton iterations and 315 Krylov
  // products for 12 factorizations, 0.30 s (median); at 0.3, 43 and 181 for
  // the same 12, 0.24 s; at 1, 53 and 243.
  double solve_excess_seconds_ = 0.0;
  static constexpr double kStartRefactorShare = 0.3;
  // The products the current Newton solve's last fresh preconditioner took
  // (1 until it has made one): the cost model charges a solve only the
  // products beyond them (stale_solve_excess).
  double fresh_solve_products_ = 1.0;
  // Krylov solves left that take Eisenstat-Walker forcing after a failed
  // solve (newton()).
  int eisenstat_walker_solves_left_ = 0;
  static constexpr int kEisenstatWalkerSolves = 10;
  bool refactor_due_ = false;          // the cost model asks for a factorization
  bool refactor_first_ = false;        // none yet, or one formed for another h
  bool refactor_failed_ = false;       // the last Krylov solve missed its tolerance
  bool preconditioner_fresh_ = false;  // factored at the current iterate
  // The springs' tension estimate of the iteration matrices formed in a
  // direct Newton solve that searches on G (JacobianRequest::
  // tension_positions): the step's start until the first update, then the
  // iterate before the last update, carried. The Krylov path's operator is
  // the exact Jacobian, and so its preconditioner is too.
  Eigen::VectorXd tension_positions_;
  bool tension_carried_ = false;
  bool estimate_tensions_ = false;
  // Decayed sums of the wall time and of the simulated time (h of solves
  // that converged) of the solves each start began.
  struct StartCost {
    double seconds = 0.0, simulated = 0.0;
    double iterations = 0.0, weight = 0.0;  // Newton iterations per solve, decayed alike
    long solves = 0;
  };
  StartCost start_costs_[kStarts];
  int last_explored_ = kChordStart;  // the costlier starts are explored in turn
  int solves_since_exploration_ = 0;
  int exploration_interval_ = kStartExploration;
  int last_best_ = kChordStart;
  bool explored_ = false;  // the last choice tried the costlier start
  GmresWorkspace gmres_;
  GmresWorkspace refine_gmres_;  // solve_refined()'s
  // Step start and h of the Jacobian the ladder last evaluated (NaN after a
  // full-Newton iterate replaced it).
  double jacobian_step_t_ = 0.0, jacobian_step_h_ = 0.0;
  double newton_tolerance_ = 0.0;
  // The current solve's tolerance: newton_tolerance_, narrowed to
  // kappa * accuracy where a widened solve met an energy rise (newton()).
  double solve_tolerance_ = 0.0;
  // The last extrapolated step: its size, |x_big - x_small| and
  // |x_small - x_n| (weighted norms), for the next step's tolerance.
  double extrapolated_h_ = 0.0, extrapolated_correction_ = 0.0, extrapolated_motion_ = 0.0;
  bool guard_energy_ = false;
  ForceJacobians guard_jacobians_;  // exact Jacobians for the energy criterion
  Eigen::VectorXd guard_q_, guard_v_, guard_z_;
  bool energy_guard_suspended_ = false;
  State energy_state_;
  struct RememberedEnergy {
    Eigen::VectorXd x;
    double value = 0.0;
  };
  std::array<RememberedEnergy, 2> remembered_energy_;
  int next_remembered_ = 0;
  Eigen::VectorXd r_, dy_, dx_, x_trial_, r_trial_, x_prev_, predictor_qdot_, chord_update_;
  // The chord test's solve, chord_update_ = P^-1 chord_residual_, and the
  // factorization that made it (its solver and that solver's count).
  // Where the next GMRES solve's right-hand side is -chord_residual_ and
  // the factorization the same, its first preconditioned vector is that
  // solve, scaled (chord_starts_gmres()).
  Eigen::VectorXd chord_residual_;
  const LinearSolver* chord_solver_ = nullptr;
  long chord_factorizations_ = -1;
  // The factorization solve_iteration_matrix() solves with now (the one
  // without the covered couplings where that is active).
  LinearSolver& current_solver();
  // Whether newton_gmres may take -chord_update_ / |rhs| as its first
  // preconditioned vector: rhs is -chord_residual_, the factorization is
  // the chord's, and the residual's scaling (residual_scaling()) is a
  // multiple of the identity, so that GMRES's first basis vector is
  // rhs / |rhs|.
  bool chord_starts_gmres(const Eigen::VectorXd& rhs);
};

}  // namespace stiffsim
