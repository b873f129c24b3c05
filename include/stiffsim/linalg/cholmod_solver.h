#pragma once
// Sparse Cholesky (CHOLMOD, raw C API) for symmetric iteration matrices that
// are expected to be positive definite. The matrix is read through its lower
// triangle only (stype = -1), wrapped without copying.
//
// LL^T is simplicial or supernodal by the pattern: analyze() keeps CHOLMOD's
// own rule (simplicial when the flops per entry of L, after ordering, are
// below Common->supernodal_switch = 40), says which in method() and why in
// factorization_note(). Banded patterns (ropes, chains) go simplicial; 2-D
// grids (cloth) of more than a few hundred nodes go supernodal.
//
// Fallbacks, each taken at most once and then kept for the solver's life:
// LL^T -> simplicial LDL^T when CHOLMOD reports the matrix not
// positive definite (LDL^T without pivoting still handles most mildly
// indefinite matrices), then LDL^T -> UMFPACK when LDL^T meets a zero or tiny
// pivot (UMFPACK pivots for stability). Each switch is printed once to stderr
// and recorded in fallback_note(). A matrix that is positive definite but
// numerically singular makes factorize() return false without a fallback:
// Cholesky is stable there, so another method would not do better.
//
// solve_preconditioner() applies a supernodal LL^T in single precision from
// a float copy of the factor (half the bytes a bandwidth-bound solve reads),
// where the first such solve after each factorization misses the factored
// matrix by at most kSinglePrecisionResidual; otherwise that factorization's
// preconditioner solves run in double.

#include <cholmod.h>

#include <memory>
#include <string>
#include <vector>

#include "stiffsim/linalg/float_cholesky.h"
#include "stiffsim/linalg/float_kernels.h"
#include "stiffsim/linalg/linear_solver.h"
#include "stiffsim/linalg/umfpack_solver.h"

namespace stiffsim {

class CholmodSolver final : public LinearSolver {
 public:
  CholmodSolver();
  ~CholmodSolver() override;
  CholmodSolver(const CholmodSolver&) = delete;
  CholmodSolver& operator=(const CholmodSolver&) = delete;

  // Throws std::invalid_argument for a non-square pattern and
  // std::runtime_error if CHOLMOD fails (e.g. out of memory).
  void analyze(const SparseMatrix& pattern) override;
  // Throws std::invalid_argument if A's pattern differs from the analyzed one.
  // counters().factorizations counts calls; an analysis redone for a fallback
  // counts in counters().analyses and its time in analysis_seconds.
  bool factorize(const SparseMatrix& A) override;
  bool has_cholesky() const override { return mode_ == Mode::kLLT; }
  // A failed attempt counts in counters().factorizations too.
  bool factorize_if_definite(const SparseMatrix& A) override;
  // A supernodal LL^T is factored in single precision (FloatCholesky), the
  // factor the float sweeps apply; where float finds A not definite, as
  // factorize() (or factorize_if_definite()) in double. Counted in
  // counters().single_precision_factorizations.
  bool factorize_preconditioner(const SparseMatrix& A, bool if_definite) override;
  void solve(const Eigen::VectorXd& b, Eigen::VectorXd* x) override;
  void solve_preconditioner(const Eigen::VectorXd& b, Eigen::VectorXd* x) override;
  std::string method() const override;
  // Supernodal: L->xsize, the entries stored in the supernodes (including the
  // explicit zeros that make supernodes dense). Simplicial LL^T and LDL^T: the
  // sum of the column counts L->nz (D on the diagonal of L). UMFPACK: its count.
  long factor_nonzeros() const override;

 private:
  // kLLT is simplicial or supernodal as the last LL^T analysis chose.
  enum class Mode { kLLT, kLDLT, kUmfpack };

  // A view of A (both triangles held) for CHOLMOD, which reads the lower
  // triangle (stype -1) or the upper one (+1).
  cholmod_sparse wrap(const SparseMatrix& A, int stype = -1) const;
  void analyze_with_cholmod(const SparseMatrix& pattern);
  // A supernodal LL^T factor of P A P^T (P: the analysis's permutation)
  // analyzed in the natural ordering, fed by prepermuted_ (see the
  // definition); false, with the factor left as it was, where the
  // reanalysis does not reproduce it.
  bool prepermute(const SparseMatrix& pattern);
  // prepermuted_'s values from A's slots.
  void gather_prepermuted(const SparseMatrix& A);
  // CHOLMOD's view of prepermuted_'s matrix.
  cholmod_sparse prepermuted_view();
  void check_pattern(const SparseMatrix& A, const char* who) const;
  // The double factor of the values factorize_preconditioner() factored in
  // float, for a solve() (no fallback: float found them definite).
  bool factor_double_now();
  // One numeric factorization in the current mode, taking the fallbacks.
  bool factorize_with_fallback(const SparseMatrix& A);
  void switch_mode(Mode next, const std::string& why);
  // Off during factorize_if_definite(): a pivot that is not positive fails
  // the factorization instead of switching to LDL^T.
  bool fallback_allowed_ = true;
  void free_factor_and_workspace();

  cholmod_common common_;
  cholmod_factor* factor_ = nullptr;
  // cholmod_solve2 reuses these when their sizes fit, so that steady-state
  // solves allocate nothing.
  cholmod_dense* solution_ = nullptr;
  cholmod_dense* solve_workspace_y_ = nullptr;
  cholmod_dense* solve_workspace_e_ = nullptr;
  std::unique_ptr<UmfpackSolver> umfpack_;  // only after the last fallback
  Mode mode_ = Mode::kLLT;
  bool llt_supernodal_ = false;  // set by each LL^T analysis
  int n_ = -1;                   // -1 until analyze()
  // The analyzed pattern, to reject a matrix with another one: CHOLMOD would
  // silently factor garbage.
  std::vector<int> outer_, inner_;
  bool factored_ = false;
  // factor_ holds the last factorization in double (not where
  // factorize_preconditioner() factored in float only).
  bool double_current_ = false;
  FloatCholesky float_cholesky_;  // analyzed at its first use
  // A float factor's first solve missed by more than
  // kSinglePrecisionResidual: factorize_preconditioner() factors in double.
  bool float_factorization_declined_ = false;
  // The supernodal path: tril(P A P^T) in CHOLMOD's column form, each entry
  // taken from A's slot source[k] at every factorization; perm[k] is the
  // row of A that row k of it holds. Right-hand sides and solutions are
  // permuted here (through rhs).
  struct Prepermuted {
    bool active = false;
    std::vector<int> outer, inner, source, perm;
    std::vector<double> values;
    Eigen::VectorXd rhs;
  } prepermuted_;
  // The supernodal factor in single precision (solve_preconditioner), made
  // from the factor at the first such solve after each factorization.
  struct Single {
    // kStale until the first preconditioner solve after a factorization,
    // which checks the float solve's residual and leaves kSingle or kDouble;
    // kUnchecked after a float factorization, until that check.
    enum class State { kStale, kUnchecked, kSingle, kDouble } state = State::kStale;
    // CHOLMOD's supernodal layout, with each diagonal entry replaced by its
    // reciprocal at the first solve (the sweeps' kernels take them).
    std::vector<float> values;
    Eigen::VectorXf y, gathered;
    Eigen::VectorXd residual;
  } single_;
  // The float sweeps' block kernels: AVX2 where the CPU has it
  // (float_kernels.h).
  const FloatSweepKernels* float_kernels_ = &float_sweep_kernels();
  // The float solve's largest relative residual |b - A z| / |b| that
  // solve_preconditioner keeps: a preconditioner that close to A^-1 adds no
  // GMRES products at forcing terms of 0.1-0.2. The shipped cloths' float
  // solves miss by 1e-7 to 2e-4; W's condition times float's epsilon
  // beyond ~1e3 would not.
  static constexpr double kSinglePrecisionResidual = 1e-3;
  // The float sweeps prefetch the factor this many entries (4 KiB) ahead of
  // the supernode they work on: most supernodes of a sheet's factor are
  // small blocks (1,273 of the 100x100 sheet's 1,771 have 8-15 columns
  // and some 85 rows), too short for the hardware's stream
  // prefetcher to find before the sweep has moved on, and the sweeps ran
  // at a quarter of the speed of a plain pass over the same bytes (see
  // solve_preconditioner()). Only factors of more than kPrefetchFromBytes
  // are prefetched: a smaller one stays in this machine's 32 MB L3 from
  // solve to solve, and the requests only cost (BM_SolvePreconditioner
  // medians, alternated rounds: a 32x32 sheet's 1.7 MB factor 0.137 ms
  // against 0.125 ms, a 48x48 sheet's 5 MB 0.36-0.42 ms against
  // 0.28-0.36 ms; a 64x64 sheet's ~10 MB alike both ways).
  static constexpr long kPrefetchAhead = 1024;
  static constexpr long kPrefetchFromBytes = 8L << 20;
  // L_jj -> 1 / L_jj in single_.values (float_kernels.h).
  void invert_single_diagonals();
  double single_precision_residual(const Eigen::VectorXd& b, const int* perm, double scale);
};

}  // namespace stiffsim
