#include "stiffsim/linalg/dense_solvers.h"

#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace stiffsim {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// Pivots are judged by the ratio of the smallest to the largest magnitude:
// at or below n * epsilon (the usual rank tolerance) the matrix cannot be told
// apart from a singular one, because rounding in the elimination leaves pivots
// of that size (not exact zeros) when A is singular. The same test is used by
// every solver, so that "numerically singular" means one thing.
// A template, not a Ref, because diagonals are strided and a Ref would copy.
template <typename Derived>
bool pivots_nonsingular(const Eigen::MatrixBase<Derived>& pivots) {
  if (pivots.size() == 0) return true;
  const double smallest = pivots.cwiseAbs().minCoeff();
  const double largest = pivots.cwiseAbs().maxCoeff();
  const double tolerance =
      static_cast<double>(pivots.size()) * std::numeric_limits<double>::epsilon();
  // Written so that NaN and Inf pivots fail the test.
  return std::isfinite(largest) && smallest > tolerance * largest;
}

Eigen::Index checked_size(const SparseMatrix& pattern, const char* who) {
  if (pattern.rows() != pattern.cols()) {
    throw std::invalid_argument(std::string(who) + "::analyze: matrix is " +
                                std::to_string(pattern.rows()) + " x " +
                                std::to_string(pattern.cols()) + ", not square");
  }
  return pattern.rows();
}

void check_factorize_size(Eigen::Index n, const SparseMatrix& A, const char* who) {
  if (n < 0) throw std::logic_error(std::string(who) + "::factorize called before analyze");
  if (A.rows() != n || A.cols() != n) {
    throw std::invalid_argument(std::string(who) + "::factorize: matrix is " +
                                std::to_string(A.rows()) + " x " + std::to_string(A.cols()) +
                                ", analyzed for " + std::to_string(n) + " x " + std::to_string(n));
  }
}

// Copies A into the preallocated dense matrix; false if a value is not finite
// (the factorization would spread it everywhere and report nothing).
bool copy_to_dense(const SparseMatrix& A, Eigen::MatrixXd* dense) {
  dense->setZero();
  for (int j = 0; j < A.outerSize(); ++j) {
    for (SparseMatrix::InnerIterator it(A, j); it; ++it) {
      if (!std::isfinite(it.value())) return false;
      (*dense)(it.row(), it.col()) = it.value();
    }
  }
  return true;
}

void check_solve(bool factored, Eigen::Index n, const Eigen::VectorXd& b, const char* who) {
  if (!factored) {
    throw std::logic_error(std::string(who) + "::solve called without a successful factorize()");
  }
  if (b.size() != n) {
    throw std::invalid_argument(std::string(who) + "::solve: right-hand side has size " +
                                std::to_string(b.size()) + ", expected " + std::to_string(n));
  }
}

}  // namespace

void DenseLUSolver::analyze(const SparseMatrix& pattern) {
  const auto start = Clock::now();
  n_ = checked_size(pattern, "DenseLUSolver");
  dense_.setZero(n_, n_);
  // The sized constructor preallocates the LU, permutation and transposition
  // storage, so that compute() on an n x n matrix does not allocate them.
  lu_ = Eigen::PartialPivLU<Eigen::MatrixXd>(n_);
  factored_ = false;
  ++counters_.analyses;
  counters_.analysis_seconds += seconds_since(start);
}

bool DenseLUSolver::factorize(const SparseMatrix& A) {
  check_factorize_size(n_, A, "DenseLUSolver");
  const auto start = Clock::now();
  ++counters_.factorizations;
  factored_ = copy_to_dense(A, &dense_);
  if (factored_) {
    lu_.compute(dense_);
    factored_ = pivots_nonsingular(lu_.matrixLU().diagonal());
  }
  counters_.factorization_seconds += seconds_since(start);
  return factored_;
}

void DenseLUSolver::solve(const Eigen::VectorXd& b, Eigen::VectorXd* x) {
  check_solve(factored_, n_, b, "DenseLUSolver");
  const auto start = Clock::now();
  // A Solve expression is evaluated straight into *x (no temporary).
  *x = lu_.solve(b);
  ++counters_.solves;
  counters_.solve_seconds += seconds_since(start);
}

long DenseLUSolver::factor_nonzeros() const { return factored_ ? static_cast<long>(n_) * n_ : 0; }

void DenseLDLTSolver::analyze(const SparseMatrix& pattern) {
  const auto start = Clock::now();
  n_ = checked_size(pattern, "DenseLDLTSolver");
  dense_.setZero(n_, n_);
  // Factoring the zero matrix sizes LDLT's storage for later compute() calls;
  // assigning LDLT(n) instead would copy its uninitialized info() flag.
  ldlt_.compute(dense_);
  factored_ = false;
  ++counters_.analyses;
  counters_.analysis_seconds += seconds_since(start);
}

bool DenseLDLTSolver::factorize(const SparseMatrix& A) {
  check_factorize_size(n_, A, "DenseLDLTSolver");
  const auto start = Clock::now();
  ++counters_.factorizations;
  factored_ = copy_to_dense(A, &dense_);
  if (factored_) {
    ldlt_.compute(dense_);
    // Eigen reports success for a zero pivot whose column is zero too, and
    // its solve() then quietly returns a pseudo-inverse solution: test D.
    factored_ = ldlt_.info() == Eigen::Success && pivots_nonsingular(ldlt_.vectorD());
  }
  counters_.factorization_seconds += seconds_since(start);
  return factored_;
}

void DenseLDLTSolver::solve(const Eigen::VectorXd& b, Eigen::VectorXd* x) {
  check_solve(factored_, n_, b, "DenseLDLTSolver");
  const auto start = Clock::now();
  *x = ldlt_.solve(b);
  ++counters_.solves;
  counters_.solve_seconds += seconds_since(start);
}

long DenseLDLTSolver::factor_nonzeros() const {
  return factored_ ? static_cast<long>(n_) * (n_ + 1) / 2 : 0;
}

}  // namespace stiffsim
