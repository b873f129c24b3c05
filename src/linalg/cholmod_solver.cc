#include "stiffsim/linalg/cholmod_solver.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>
#include <string>

#if defined(__SSE2__)
#include <xmmintrin.h>
#endif

#include "stiffsim/linalg/blas_threads.h"
#include "stiffsim/linalg/float_kernels.h"

// CHOLMOD as Debian builds it times every BLAS call of its supernodal
// factorization, two clock reads per call, for statistics in cholmod_common
// that nothing reads (neither stiffsim nor SuiteSparse's own decisions:
// CHOLMOD's and UMFPACK's timings are reports). On cloth_stiff.yaml those
// reads were 2.5% of the run's samples (perf: __vdso_clock_gettime under
// SuiteSparse_time under cholmod_super_numeric). A program linked with
// this solver defines SuiteSparse_time itself; the dynamic linker resolves
// the libraries' calls to the program's definition before their own, and
// it reads no clock. (SuiteSparseTimersAreNotRead checks that CHOLMOD's
// calls reach it.)
extern "C" double SuiteSparse_time(void) { return 0.0; }

namespace stiffsim {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// CHOLMOD does not test for NaN/Inf: it would return a factor full of NaN.
bool all_finite(const SparseMatrix& A) {
  const double* values = A.valuePtr();
  return std::all_of(values, values + A.nonZeros(), [](double v) { return std::isfinite(v); });
}

std::string cholmod_error(const char* call, int status) {
  return std::string("CholmodSolver: ") + call + " failed with CHOLMOD status " +
         std::to_string(status);
}

// cholmod_rcond is the ratio of the smallest to the largest pivot of A (D in
// LDL^T, the squared diagonal of L in LL^T). Rounding leaves pivots of about
// n * epsilon, rarely exact zeros, when A is singular, so CHOLMOD's own zero
// test alone misses most singular matrices; at or below that ratio, A cannot
// be told from singular (the same test as the other solvers).
bool pivot_ratio_acceptable(double rcond, int n) {
  return rcond > n * std::numeric_limits<double>::epsilon();  // false for NaN too
}

std::string format_ratio(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%.3g", value);
  return text;
}

// CHOLMOD's view of a square compressed matrix of n columns: CHOLMOD takes
// non-const pointers but only reads them (analyze, factorize).
cholmod_sparse view(int n, std::size_t nonzeros, const int* outer, const int* inner,
                    const double* values, int stype) {
  cholmod_sparse header{};
  header.nrow = header.ncol = static_cast<std::size_t>(n);
  header.nzmax = nonzeros;
  header.p = const_cast<int*>(outer);
  header.i = const_cast<int*>(inner);
  header.x = const_cast<double*>(values);
  header.stype = stype;
  header.itype = CHOLMOD_INT;
  header.xtype = CHOLMOD_REAL;
  header.dtype = CHOLMOD_DOUBLE;
  header.sorted = 1;
  header.packed = 1;
  return header;
}

// Flush-to-zero and denormals-are-zero for SSE arithmetic in a scope (the
// float solves); the caller's floating-point environment is restored.
class FlushSubnormals {
 public:
#if defined(__SSE2__)
  FlushSubnormals() : saved_(_mm_getcsr()) {
    _mm_setcsr(saved_ | kFlushToZero | kDenormalsAreZero);
  }
  ~FlushSubnormals() { _mm_setcsr(saved_); }

 private:
  static constexpr unsigned int kFlushToZero = 0x8000, kDenormalsAreZero = 0x0040;
  unsigned int saved_;
#endif
};

}  // namespace

CholmodSolver::CholmodSolver() {
  apply_blas_threads();
  cholmod_start(&common_);
  // Failures become exceptions or return values carrying the status; CHOLMOD's
  // own messages would go to stdout, which the CLI may use for results.
  common_.print = 0;
  common_.final_ll = true;
}

CholmodSolver::~CholmodSolver() {
  free_factor_and_workspace();
  cholmod_finish(&common_);
}

void CholmodSolver::free_factor_and_workspace() {
  cholmod_free_factor(&factor_, &common_);
  cholmod_free_dense(&solution_, &common_);
  cholmod_free_dense(&solve_workspace_y_, &common_);
  cholmod_free_dense(&solve_workspace_e_, &common_);
}

cholmod_sparse CholmodSolver::wrap(const SparseMatrix& A, int stype) const {
  // The Eigen matrix holds both triangles; CHOLMOD reads the one stype
  // names and ignores the rest, which saves building a triangular copy.
  return view(static_cast<int>(A.rows()), static_cast<std::size_t>(A.nonZeros()), A.outerIndexPtr(),
              A.innerIndexPtr(), A.valuePtr(), stype);
}

void CholmodSolver::analyze(const SparseMatrix& pattern) {
  if (pattern.rows() != pattern.cols() || !pattern.isCompressed()) {
    throw std::invalid_argument(
        "CholmodSolver::analyze: matrix is " + std::to_string(pattern.rows()) + " x " +
        std::to_string(pattern.cols()) + (pattern.isCompressed() ? "" : " and not compressed") +
        "; a square compressed matrix is required");
  }
  const auto start = Clock::now();
  n_ = static_cast<int>(pattern.rows());
  outer_.assign(pattern.outerIndexPtr(), pattern.outerIndexPtr() + n_ + 1);
  inner_.assign(pattern.innerIndexPtr(), pattern.innerIndexPtr() + pattern.nonZeros());
  factored_ = false;
  if (mode_ == Mode::kUmfpack) {
    umfpack_->analyze(pattern);
  } else {
    analyze_with_cholmod(pattern);
  }
  ++counters_.analyses;
  counters_.analysis_seconds += seconds_since(start);
}

void CholmodSolver::analyze_with_cholmod(const SparseMatrix& pattern) {
  free_factor_and_workspace();
  prepermuted_.active = false;
  float_cholesky_ = FloatCholesky();
  // LL^T: CHOLMOD_AUTO lets cholmod_analyze pick simplicial when the ordered
  // pattern's flops per factor entry are below supernodal_switch (40): a banded
  // rope gives supernodes too thin for dense kernels to pay for their explicit
  // zeros and bookkeeping, a 2-D grid gives wide fronts that BLAS runs well.
  // LDL^T exists only in simplicial form.
  const bool ldlt = mode_ == Mode::kLDLT;
  common_.supernodal = ldlt ? CHOLMOD_SIMPLICIAL : CHOLMOD_AUTO;
  common_.final_ll = !ldlt;
  cholmod_sparse header = wrap(pattern);
  factor_ = cholmod_analyze(&header, &common_);
  if (factor_ == nullptr)
    throw std::runtime_error(cholmod_error("cholmod_analyze", common_.status));
  if (ldlt) return;  // the LL^T choice and its note stay as they were
  llt_supernodal_ = factor_->is_super != 0;
  // fl and lnz are those of the ordering cholmod_analyze kept.
  const double flops_per_entry = common_.lnz > 0 ? common_.fl / common_.lnz : 0.0;
  const double fill = common_.anz > 0 ? common_.lnz / common_.anz : 0.0;
  factorization_note_ = method() + ": flops/nnz(L) = " + format_ratio(flops_per_entry) +
                        (llt_supernodal_ ? " >= " : " < ") +
                        format_ratio(common_.supernodal_switch) +
                        ", nnz(L) = " + std::to_string(static_cast<long>(common_.lnz)) + " (" +
                        format_ratio(fill) + "x tril(A))";
  if (llt_supernodal_ && prepermute(pattern)) {
    factorization_note_ += "; P A P^T formed at the analysis, factored as given";
  }
}

bool CholmodSolver::prepermute(const SparseMatrix& pattern) {
  // cholmod_factorize permutes A into tril(P A P^T) at every factorization
  // by a permuted transpose, into a copy it allocates and frees (4.5% of
  // cloth_stiff.yaml's samples under perf, after the upper triangle had
  // saved the second transpose). That matrix's pattern is fixed: it is
  // built here once, with the slot of A each entry comes from, and
  // analyzed again in the natural ordering (P already holds the
  // postordering), which CHOLMOD factors as it is given.
  const int n = n_;
  const int* P = static_cast<const int*>(factor_->Perm);
  Prepermuted pre;
  pre.perm.assign(P, P + n);
  std::vector<int> position(n);
  for (int k = 0; k < n; ++k) position[P[k]] = k;
  std::vector<std::vector<std::pair<int, int>>> columns(n);  // (row, slot of A)
  for (int j = 0; j < n; ++j) {
    for (int s = pattern.outerIndexPtr()[j]; s < pattern.outerIndexPtr()[j + 1]; ++s) {
      const int row = position[pattern.innerIndexPtr()[s]], column = position[j];
      if (row >= column) columns[column].emplace_back(row, s);
    }
  }
  pre.outer.assign(1, 0);
  for (auto& column : columns) {
    std::sort(column.begin(), column.end());
    for (const auto& [row, slot] : column) {
      pre.inner.push_back(row);
      pre.source.push_back(slot);
    }
    pre.outer.push_back(static_cast<int>(pre.inner.size()));
  }
  pre.values.assign(pre.inner.size(), 0.0);
  pre.rhs.resize(n);
  prepermuted_ = std::move(pre);
  cholmod_sparse lower = prepermuted_view();
  const int nmethods = common_.nmethods, ordering = common_.method[0].ordering;
  const int postorder = common_.postorder, supernodal = common_.supernodal;
  common_.nmethods = 1;
  common_.method[0].ordering = CHOLMOD_NATURAL;
  common_.postorder = false;
  common_.supernodal = CHOLMOD_SUPERNODAL;
  cholmod_factor* natural = cholmod_analyze(&lower, &common_);
  // Only the settings: the statistics (fl, lnz) stay the first analysis's.
  common_.nmethods = nmethods;
  common_.method[0].ordering = ordering;
  common_.postorder = postorder;
  common_.supernodal = supernodal;
  if (natural == nullptr || natural->ordering != CHOLMOD_NATURAL || !natural->is_super ||
      natural->xsize != factor_->xsize || natural->nsuper != factor_->nsuper) {
    cholmod_free_factor(&natural, &common_);
    return false;
  }
  cholmod_free_factor(&factor_, &common_);
  factor_ = natural;
  prepermuted_.active = true;
  return true;
}

void CholmodSolver::gather_prepermuted(const SparseMatrix& A) {
  const double* values = A.valuePtr();
  for (size_t k = 0; k < prepermuted_.source.size(); ++k) {
    prepermuted_.values[k] = values[prepermuted_.source[k]];
  }
}

cholmod_sparse CholmodSolver::prepermuted_view() {
  // Lower (stype -1): the natural ordering's form that needs no transpose.
  return view(n_, prepermuted_.inner.size(), prepermuted_.outer.data(), prepermuted_.inner.data(),
              prepermuted_.values.data(), -1);
}

void CholmodSolver::check_pattern(const SparseMatrix& A, const char* who) const {
  if (n_ < 0)
    throw std::logic_error(std::string("CholmodSolver::") + who + " called before analyze");
  if (A.rows() != n_ || A.cols() != n_ || !A.isCompressed() ||
      A.nonZeros() != static_cast<Eigen::Index>(inner_.size()) ||
      !std::equal(outer_.begin(), outer_.end(), A.outerIndexPtr()) ||
      !std::equal(inner_.begin(), inner_.end(), A.innerIndexPtr())) {
    throw std::invalid_argument(std::string("CholmodSolver::") + who +
                                ": the matrix's pattern differs from the analyzed one");
  }
}

bool CholmodSolver::factorize_preconditioner(const SparseMatrix& A, bool if_definite) {
  // In double: a factor that is not a supernodal LL^T, a solver that went
  // back to double, and values that are not finite (which the double path
  // reports as a failed factorization).
  if (float_factorization_declined_ ||
      !(mode_ == Mode::kLLT && prepermuted_.active && factor_ != nullptr && factor_->is_super) ||
      !all_finite(A)) {
    return if_definite ? factorize_if_definite(A) : factorize(A);
  }
  check_pattern(A, "factorize_preconditioner");
  apply_blas_threads();
  const auto start = Clock::now();
  if (!float_cholesky_.analyzed()) float_cholesky_.analyze(*factor_);
  gather_prepermuted(A);
  single_.values.resize(factor_->xsize);
  const bool factored =
      float_cholesky_.factorize(prepermuted_.outer.data(), prepermuted_.inner.data(),
                                prepermuted_.values.data(), single_.values.data());
  if (!factored) {
    // Not definite in float. An exact Hessian (if_definite) is taken as
    // indefinite: its caller has a definite matrix to factor instead.
    // Otherwise double decides (and falls back where that fails too).
    counters_.factorization_seconds += seconds_since(start);
    if (!if_definite) return factorize(A);
    ++counters_.factorizations;
    factored_ = false;
    return false;
  }
  ++counters_.factorizations;
  ++counters_.single_precision_factorizations;
  factored_ = true;
  double_current_ = false;
  single_.state = Single::State::kUnchecked;
  counters_.factorization_seconds += seconds_since(start);
  return true;
}

bool CholmodSolver::factor_double_now() {
  const auto start = Clock::now();
  cholmod_sparse header = prepermuted_view();
  cholmod_factorize(&header, factor_, &common_);
  if (common_.status < CHOLMOD_OK) {
    throw std::runtime_error(cholmod_error("cholmod_factorize", common_.status));
  }
  counters_.factorization_seconds += seconds_since(start);
  double_current_ = common_.status != CHOLMOD_NOT_POSDEF && factor_->minor >= factor_->n &&
                    pivot_ratio_acceptable(cholmod_rcond(factor_, &common_), n_);
  return double_current_;
}

bool CholmodSolver::factorize(const SparseMatrix& A) {
  check_pattern(A, "factorize");
  apply_blas_threads();  // this thread may not be the constructor's
  const auto start = Clock::now();
  const double analysis_seconds_before = counters_.analysis_seconds;
  ++counters_.factorizations;
  factored_ = all_finite(A) && factorize_with_fallback(A);
  double_current_ = factored_;
  // A fallback's re-analysis is already in analysis_seconds.
  counters_.factorization_seconds +=
      seconds_since(start) - (counters_.analysis_seconds - analysis_seconds_before);
  return factored_;
}

bool CholmodSolver::factorize_if_definite(const SparseMatrix& A) {
  if (!has_cholesky()) return false;
  struct Restore {
    bool& allowed;
    ~Restore() { allowed = true; }
  } restore{fallback_allowed_};
  fallback_allowed_ = false;
  return factorize(A);
}

bool CholmodSolver::factorize_with_fallback(const SparseMatrix& A) {
  if (mode_ == Mode::kUmfpack) return umfpack_->factorize(A);

  cholmod_sparse header;
  if (prepermuted_.active) {
    gather_prepermuted(A);
    header = prepermuted_view();
  } else {
    // A permuted supernodal factorization reads the upper triangle with one
    // permuted transpose of A, the lower with two (the second a copy);
    // simplicial ones the reverse (cholmod_factorize). Each allocates and
    // frees its copy: on cloth_stiff.yaml the transposes took 6.7% of the
    // run's time with the lower triangle.
    header = wrap(A, factor_->is_super ? 1 : -1);
  }
  cholmod_factorize(&header, factor_, &common_);
  single_.state = Single::State::kStale;
  if (common_.status < CHOLMOD_OK) {
    throw std::runtime_error(cholmod_error("cholmod_factorize", common_.status));
  }
  // minor < n is where the factorization stopped; the status says so too.
  const bool pivot_failed = common_.status == CHOLMOD_NOT_POSDEF || factor_->minor < factor_->n;
  // Messages are built only on the way to a fallback: a factorization that
  // succeeds allocates nothing of ours.
  auto at_factorization = [&] {
    return " at factorization " + std::to_string(counters_.factorizations);
  };
  auto pivot_position = [&] {
    return "pivot " + std::to_string(factor_->minor + 1) + " of " + std::to_string(n_);
  };

  if (mode_ == Mode::kLLT) {
    if (!pivot_failed) return pivot_ratio_acceptable(cholmod_rcond(factor_, &common_), n_);
    if (!fallback_allowed_) return false;
    switch_mode(Mode::kLDLT,
                "matrix not positive definite (" + pivot_position() + ")" + at_factorization());
    const auto start = Clock::now();
    analyze_with_cholmod(A);
    ++counters_.analyses;
    counters_.analysis_seconds += seconds_since(start);
    return factorize_with_fallback(A);
  }

  // Simplicial LDL^T does not pivot, so a zero or tiny pivot may come from the
  // elimination order rather than from A; UMFPACK's pivoting may still succeed.
  const double rcond = pivot_failed ? 0.0 : cholmod_rcond(factor_, &common_);
  if (!pivot_failed && pivot_ratio_acceptable(rcond, n_)) return true;
  switch_mode(Mode::kUmfpack,
              (pivot_failed ? "CHOLMOD LDL^T met a zero pivot (" + pivot_position() + ")"
                            : "CHOLMOD LDL^T pivot ratio " + format_ratio(rcond) +
                                  " is at most n * epsilon") +
                  at_factorization());
  free_factor_and_workspace();
  umfpack_ = std::make_unique<UmfpackSolver>();
  const auto start = Clock::now();
  umfpack_->analyze(A);
  ++counters_.analyses;
  counters_.analysis_seconds += seconds_since(start);
  return umfpack_->factorize(A);
}

void CholmodSolver::switch_mode(Mode next, const std::string& why) {
  auto describe = [this](Mode mode) {
    switch (mode) {
      case Mode::kLLT:
        return llt_supernodal_ ? "CHOLMOD supernodal LL^T" : "CHOLMOD simplicial LL^T";
      case Mode::kLDLT:
        return "CHOLMOD LDL^T";
      case Mode::kUmfpack:
        return "UMFPACK";
    }
    return "?";
  };
  const std::string sentence = why + ": switched from " + describe(mode_) + " to " + describe(next);
  mode_ = next;
  // Said once per switch: the solver never switches back.
  std::fprintf(stderr, "stiffsim: %s\n", sentence.c_str());
  fallback_note_ = fallback_note_.empty() ? sentence : fallback_note_ + "; then " + sentence;
}

void CholmodSolver::solve(const Eigen::VectorXd& b, Eigen::VectorXd* x) {
  if (!factored_) {
    throw std::logic_error("CholmodSolver::solve called without a successful factorize()");
  }
  if (b.size() != n_) {
    throw std::invalid_argument("CholmodSolver::solve: right-hand side has size " +
                                std::to_string(b.size()) + ", expected " + std::to_string(n_));
  }
  // After a float factorization: the double factor of the same values.
  // (Float found them definite, with the same pivot-ratio bound; double's
  // finer rounding fails only a matrix at the edge of definiteness.)
  if (!double_current_ && !factor_double_now()) {
    throw std::runtime_error(
        "CholmodSolver::solve: the matrix factored in single precision is not definite in "
        "double");
  }
  const auto start = Clock::now();
  if (mode_ == Mode::kUmfpack) {
    umfpack_->solve(b, x);
  } else {
    cholmod_dense rhs{};
    rhs.nrow = static_cast<size_t>(n_);
    rhs.ncol = 1;
    rhs.nzmax = static_cast<size_t>(n_);
    rhs.d = static_cast<size_t>(n_);
    const double* rhs_values = b.data();
    if (prepermuted_.active) {
      for (int k = 0; k < n_; ++k) prepermuted_.rhs[k] = b[prepermuted_.perm[k]];
      rhs_values = prepermuted_.rhs.data();
    }
    rhs.x = const_cast<double*>(rhs_values);  // read only
    rhs.z = nullptr;
    rhs.xtype = CHOLMOD_REAL;
    rhs.dtype = CHOLMOD_DOUBLE;
    // A simplicial solve asks for a 4 x n Y (up to 4 right-hand sides at a
    // time) but leaves it shaped 1 x n, the columns it used, so the next call
    // would free and reallocate it; its storage still holds 4 x n.
    if (!factor_->is_super && solve_workspace_y_ != nullptr &&
        solve_workspace_y_->nzmax >= 4 * solve_workspace_y_->ncol) {
      solve_workspace_y_->nrow = solve_workspace_y_->d = 4;
    }
    if (!cholmod_solve2(CHOLMOD_A, factor_, &rhs, nullptr, &solution_, nullptr, &solve_workspace_y_,
                        &solve_workspace_e_, &common_)) {
      throw std::runtime_error(cholmod_error("cholmod_solve2", common_.status));
    }
    if (x->size() != n_) x->resize(n_);
    const double* solution = static_cast<const double*>(solution_->x);
    if (prepermuted_.active) {
      for (int k = 0; k < n_; ++k) (*x)[prepermuted_.perm[k]] = solution[k];
    } else {
      std::copy(solution, solution + n_, x->data());
    }
  }
  ++counters_.solves;
  counters_.solve_seconds += seconds_since(start);
}

void CholmodSolver::solve_preconditioner(const Eigen::VectorXd& b, Eigen::VectorXd* x) {
  // In double: anything but a supernodal LL^T whose factored matrix is kept
  // (P A P^T, formed at the analysis, which the check needs), a
  // factorization the check declined, and a zero or non-finite b.
  const double scale = b.size() == n_ ? b.lpNorm<Eigen::Infinity>() : 0.0;
  if (!factored_ || mode_ != Mode::kLLT || !factor_->is_super || !prepermuted_.active ||
      single_.state == Single::State::kDouble || scale == 0.0 || !std::isfinite(scale)) {
    solve(b, x);
    return;
  }
  const auto start = Clock::now();
  const bool float_factored = single_.state == Single::State::kUnchecked;
  const bool check = single_.state == Single::State::kStale || float_factored;
  if (single_.state == Single::State::kStale) {
    const double* values = static_cast<const double*>(factor_->x);
    single_.values.resize(factor_->xsize);
    for (size_t k = 0; k < factor_->xsize; ++k) single_.values[k] = static_cast<float>(values[k]);
  }
  if (check) {
    invert_single_diagonals();
    counters_.single_precision_setup_seconds += seconds_since(start);
  }
  const int* perm = prepermuted_.perm.data();
  auto& y = single_.y;
  if (y.size() != n_) y.resize(n_);
  // Float subnormals (below 1.2e-38: the tails of a stiff sheet's factor
  // and of the products with it) cost a microcode assist per operation:
  // without flushing them, these solves took 0.19 ms within a run of the
  // 20x20 stiff sheet against 0.07 ms on a vector of ones, and the run lost
  // more than single precision saves. The right-hand side is scaled to a
  // largest entry of 1 so that flushing loses only what is below float's
  // range relative to it.
  const FlushSubnormals flush;
  for (int k = 0; k < n_; ++k) y[k] = static_cast<float>(b[perm[k]] / scale);
  const int* super = static_cast<const int*>(factor_->super);
  const int* pi = static_cast<const int*>(factor_->pi);
  const int* px = static_cast<const int*>(factor_->px);
  const int* rows = static_cast<const int*>(factor_->s);
  const int nsuper = static_cast<int>(factor_->nsuper);
  auto& t = single_.gathered;
  if (t.size() < static_cast<Eigen::Index>(factor_->maxesize)) t.resize(factor_->maxesize);
  // CHOLMOD's supernodal layout: supernode s holds columns super[s] to
  // super[s + 1] - 1 of L as one dense column-major block of nrow rows at
  // px[s], its diagonal block first; the rows below are listed at
  // s[pi[s] + ncol ...]. The two sweeps are CHOLMOD's own (dense triangle,
  // then a product scattered to or gathered from the rows below), in float.
  // Each block operation runs eight lanes wide where the CPU has AVX2 with
  // FMA, and four in Eigen's (the build's baseline SSE2) elsewhere
  // (float_kernels.h): BM_SolvePreconditioner/100 took 2.8-3.2 ms against
  // 4.0-4.3 ms, /32 0.15 ms against 0.19-0.21 ms (two alternated rounds);
  // the 100x100 sheet at 1/60 to 0.5 s 0.88x the time (3 starts),
  // cloth.yaml at 1/60 for 2 s 0.83x (10).
  const FloatSweepKernels& kernels = *float_kernels_;
  const float* values = single_.values.data();
  float* yp = y.data();
  float* tp = t.data();
  // The entries [from, to) of the float factor, requested ahead of the
  // sweep (kPrefetchAhead): each supernode requests as many entries as its
  // own block holds, kPrefetchAhead beyond it in the sweep's direction.
  // Into L2, not L1: requests into L1 held the fill buffers the sweep's own
  // loads need. BM_SolvePreconditioner/100, medians of six alternated
  // rounds: 6.0 ms without, 5.1 ms into L1, 4.6 ms into L2, 4.5 ms into
  // L3 (a plain forward and backward pass over its 26 MB took 1.3-1.5
  // ms). In the 100x100 sheet's run at 1/60 to 0.5 s: 2.5-2.7 ms per
  // solve against 3.6-4.0 ms, and 0.82x the run time (4 alternated runs).
  const long factor_size = static_cast<long>(single_.values.size());
  const bool prefetching = factor_size * static_cast<long>(sizeof(float)) > kPrefetchFromBytes;
  auto prefetch = [values, factor_size, prefetching](long from, long to) {
    if (!prefetching) return;
    constexpr long kLine = 64 / sizeof(float);
    for (long k = std::max(from, 0L); k < std::min(to, factor_size); k += kLine) {
      __builtin_prefetch(values + k, 0, 2);  // into L2: see kPrefetchAhead
    }
  };
  // L y = P b, supernode by supernode: the diagonal block's triangle, then
  // the rows below it.
  for (int s = 0; s < nsuper; ++s) {
    const int k1 = super[s], ncol = super[s + 1] - k1;
    const int nrow = pi[s + 1] - pi[s], nbelow = nrow - ncol;
    const float* L = values + px[s];
    prefetch(px[s] + kPrefetchAhead, px[s + 1] + kPrefetchAhead);
    kernels.lower_solve(ncol, nrow, L, yp + k1);
    if (nbelow > 0) {
      kernels.product(nbelow, ncol, nrow, L + ncol, yp + k1, tp);
      const int* below = rows + pi[s] + ncol;
      for (int i = 0; i < nbelow; ++i) yp[below[i]] -= tp[i];
    }
  }
  // L^T z = y, in reverse.
  for (int s = nsuper - 1; s >= 0; --s) {
    const int k1 = super[s], ncol = super[s + 1] - k1;
    const int nrow = pi[s + 1] - pi[s], nbelow = nrow - ncol;
    const float* L = values + px[s];
    prefetch(px[s] - kPrefetchAhead, px[s + 1] - kPrefetchAhead);
    if (nbelow > 0) {
      const int* below = rows + pi[s] + ncol;
      for (int i = 0; i < nbelow; ++i) tp[i] = yp[below[i]];
      kernels.transpose_product_subtract(nbelow, ncol, nrow, L + ncol, tp, yp + k1);
    }
    kernels.lower_transpose_solve(ncol, nrow, L, yp + k1);
  }
  double residual = 0.0;
  if (check) {
    const auto check_start = Clock::now();
    residual = single_precision_residual(b, perm, scale);
    counters_.single_precision_setup_seconds += seconds_since(check_start);
  }
  if (residual > kSinglePrecisionResidual) {
    // W's condition times float's epsilon is not small: GMRES would need
    // products for the rounding alone. This factorization solves in double.
    // A factor made in float can miss where the float copy of a double one
    // does not (its rounding enters every elimination step, and the soft
    // directions of a stiff matrix are differences of its stiff ones): where
    // one does, this solver factors in double from then on.
    single_.state = Single::State::kDouble;
    ++counters_.single_precision_declined;
    if (float_factored) float_factorization_declined_ = true;
    counters_.solve_seconds += seconds_since(start);
    solve(b, x);
    return;
  }
  single_.state = Single::State::kSingle;  // checked
  if (x->size() != n_) x->resize(n_);
  for (int k = 0; k < n_; ++k) (*x)[perm[k]] = scale * y[k];
  ++counters_.solves;
  ++counters_.single_precision_solves;
  if (prefetching) ++counters_.prefetched_solves;
  counters_.solve_seconds += seconds_since(start);
}

void CholmodSolver::invert_single_diagonals() {
  const int* super = static_cast<const int*>(factor_->super);
  const int* pi = static_cast<const int*>(factor_->pi);
  const int* px = static_cast<const int*>(factor_->px);
  for (size_t s = 0; s < factor_->nsuper; ++s) {
    const int ncol = super[s + 1] - super[s], nrow = pi[s + 1] - pi[s];
    float* block = single_.values.data() + px[s];
    for (int j = 0; j < ncol; ++j) {
      float& d = block[static_cast<long>(j) * nrow + j];
      d = 1.0f / d;
    }
  }
}

double CholmodSolver::single_precision_residual(const Eigen::VectorXd& b, const int* perm,
                                                double scale) {
  // |P b - (P A P^T) z| / |P b| for the float solve's z (single_.y), with
  // the lower triangle of P A P^T kept for the factorization.
  Eigen::VectorXd& r = single_.residual;
  r.resize(n_);
  for (int k = 0; k < n_; ++k) r[k] = b[perm[k]] / scale;
  const double norm_b = r.norm();  // > 0: b's largest entry is 1 here
  const Eigen::VectorXf& z = single_.y;
  for (int j = 0; j < n_; ++j) {
    for (int s = prepermuted_.outer[j]; s < prepermuted_.outer[j + 1]; ++s) {
      const int i = prepermuted_.inner[s];
      const double a = prepermuted_.values[s];
      r[i] -= a * z[j];
      if (i != j) r[j] -= a * z[i];
    }
  }
  return r.norm() / norm_b;
}

std::string CholmodSolver::method() const {
  switch (mode_) {
    case Mode::kLLT:
      if (n_ < 0) return "cholmod-llt";  // simplicial or supernodal: analyze() decides
      return llt_supernodal_ ? "cholmod-supernodal-llt" : "cholmod-simplicial-llt";
    case Mode::kLDLT:
      return "cholmod-ldlt";
    case Mode::kUmfpack:
      return "umfpack";
  }
  return "cholmod";
}

long CholmodSolver::factor_nonzeros() const {
  if (!factored_) return 0;
  if (mode_ == Mode::kUmfpack) return umfpack_->factor_nonzeros();
  if (factor_->is_super) return static_cast<long>(factor_->xsize);
  const int* column_counts = static_cast<const int*>(factor_->nz);
  long total = 0;
  for (size_t j = 0; j < factor_->n; ++j) total += column_counts[j];
  return total;
}

}  // namespace stiffsim
