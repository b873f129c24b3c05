#pragma once
// One small interface for the Newton systems: analyze(pattern) once,
// factorize(values) when the reuse ladder asks, solve(rhs) per iteration.
// Integrators never name a concrete solver.

#include <Eigen/Core>
#include <memory>
#include <string>

#include "stiffsim/linalg/sparse_pattern.h"

namespace stiffsim {

enum class LinearSolverKind { kAuto, kDenseLU, kDenseLDLT, kCholmod, kUmfpack };

// "auto", "dense", "dense-lu", "dense-ldlt", "cholmod", "umfpack". "dense"
// means kDenseLU whatever the symmetry (LU needs neither symmetry nor
// definiteness); only kAuto picks dense LDLT by itself. Throws
// std::invalid_argument naming the valid names.
LinearSolverKind parse_linear_solver_kind(const std::string& name);
std::string to_string(LinearSolverKind kind);

struct LinearSolverCounters {
  long analyses = 0;        // symbolic analyses (ordering, elimination tree),
                            // including one redone by a fallback
  long factorizations = 0;  // factorize() calls, failed ones included
  long solves = 0;          // right-hand sides solved
  // solve_preconditioner(): solves in single precision, and factorizations
  // whose check of the float solve's residual sent them to double.
  long single_precision_solves = 0;
  long single_precision_declined = 0;
  // Single-precision solves that prefetched their factor (a large one:
  // CholmodSolver::kPrefetchFromBytes).
  long prefetched_solves = 0;
  // factorize_preconditioner() calls factored in single precision only.
  long single_precision_factorizations = 0;
  // The float copies of factors and their checks, within solve_seconds: a
  // cost of each factorization, paid at its first preconditioner solve.
  double single_precision_setup_seconds = 0.0;
  double analysis_seconds = 0.0;
  double factorization_seconds = 0.0;
  double solve_seconds = 0.0;
};

class LinearSolver {
 public:
  virtual ~LinearSolver() = default;

  // Symbolic analysis of the pattern of A (values ignored). Called once per
  // pattern by the caller (make_linear_solver does not call it), before any
  // factorize(); factorize() requires compressed matrices with exactly this
  // pattern (sparse solvers throw std::invalid_argument otherwise).
  virtual void analyze(const SparseMatrix& pattern) = 0;
  // Numeric factorization. Returns false if A is numerically singular (or
  // contains non-finite values); the solver then cannot solve until the next
  // successful factorize(). "Numerically singular" means the same for every
  // solver: smallest / largest pivot magnitude <= n * machine epsilon, the
  // size rounding leaves in place of a zero pivot. The solver keeps its own
  // copy of whatever solve() needs, so A may be overwritten after this returns.
  virtual bool factorize(const SparseMatrix& A) = 0;
  // Whether factorize_if_definite() can tell: the solver factors by a
  // Cholesky LL^T now, which succeeds exactly on positive definite matrices.
  virtual bool has_cholesky() const { return false; }
  // Factorizes A by the solver's LL^T only where A is positive definite:
  // false where it is not (or the solver has no LL^T in use), with no
  // fallback to another method, so the next factorize() of a definite matrix
  // works as before. For callers that have a definite matrix to fall back to
  // themselves (an exact Hessian that may be indefinite, its clamped form
  // that is not).
  virtual bool factorize_if_definite(const SparseMatrix& A) {
    (void)A;
    return false;
  }
  // Factorizes A for solve_preconditioner(), as factorize() (if_definite:
  // as factorize_if_definite()), where the solver may keep the factor in
  // single precision only (a supernodal LL^T); solve() then factors A in
  // double first. For callers whose solves with A are a preconditioner's.
  virtual bool factorize_preconditioner(const SparseMatrix& A, bool if_definite) {
    return if_definite ? factorize_if_definite(A) : factorize(A);
  }
  // x = A^-1 b with the last factorization; allocates nothing once x has size
  // n and one solve has been done. x may not alias b. Throws std::logic_error
  // without a successful factorize().
  virtual void solve(const Eigen::VectorXd& b, Eigen::VectorXd* x) = 0;
  // x ~ A^-1 b for a preconditioner: the same factorization applied in
  // single precision where the solver holds one (a supernodal LL^T), which
  // halves the bytes a bandwidth-bound solve reads; solve() otherwise. The
  // result is a fixed function of b but not exactly linear in it: for
  // callers that tolerate that (flexible GMRES, which keeps P^-1 v).
  virtual void solve_preconditioner(const Eigen::VectorXd& b, Eigen::VectorXd* x) { solve(b, x); }

  // What is in use now ("cholmod-supernodal-llt", "cholmod-simplicial-llt",
  // "cholmod-ldlt", "umfpack", "dense-lu", ...); a fallback changes it, and a
  // solver that picks its variant by the pattern says so only after analyze().
  virtual std::string method() const = 0;
  // Nonzeros of the factor(s) after the last factorization.
  virtual long factor_nonzeros() const = 0;
  // Set once when the solver fell back to another method (e.g. the matrix was
  // not positive definite), empty otherwise.
  const std::string& fallback_note() const { return fallback_note_; }
  // Set by analyze() when the solver picks its variant by the pattern (CHOLMOD:
  // simplicial or supernodal LL^T), with the figures that decided; empty
  // otherwise. For the stats, next to LinearSolverChoice::reason.
  const std::string& factorization_note() const { return factorization_note_; }
  const LinearSolverCounters& counters() const { return counters_; }

 protected:
  LinearSolverCounters counters_;
  std::string fallback_note_;
  std::string factorization_note_;
};

struct LinearSolverChoice {
  std::unique_ptr<LinearSolver> solver;
  std::string reason;  // why this solver was picked, for the stats
};

// make_linear_solver's bound on small systems (see SmallSystems).
inline constexpr long kSmallSystemMaxSize = 200;

// How kAuto treats systems of at most kSmallSystemMaxSize unknowns.
enum class SmallSystems {
  kDense,      // always dense
  kByDensity,  // symmetric ones dense only when nnz / n^2 > 50%
};

// Picks and constructs a solver; the caller then calls analyze(pattern). For
// kAuto: dense (LDLT if `symmetric`, else LU) when n <= 200 (with
// SmallSystems::kByDensity and `symmetric`: n <= 200 and nnz / n^2 > 50%) or
// nnz / n^2 > 10%,
// else CHOLMOD when `symmetric` (values symmetric and expected positive
// definite), UMFPACK otherwise. Explicit kinds are honoured as asked.
// `symmetric` must be true for kCholmod and kDenseLDLT (std::invalid_argument
// otherwise). Store both triangles of a symmetric A: CHOLMOD and dense LDLT read
// only the lower one, but CHOLMOD's UMFPACK fallback reads all of A.
LinearSolverChoice make_linear_solver(LinearSolverKind kind, const SparseMatrix& pattern,
                                      bool symmetric, SmallSystems small = SmallSystems::kDense);

}  // namespace stiffsim
