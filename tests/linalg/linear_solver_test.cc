#include "stiffsim/linalg/linear_solver.h"

#include <gtest/gtest.h>

#include <Eigen/SparseCholesky>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <memory>
#include <random>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "stiffsim/linalg/cholmod_solver.h"
#include "stiffsim/linalg/dense_solvers.h"
#include "stiffsim/linalg/float_cholesky.h"
#include "stiffsim/linalg/umfpack_solver.h"

#if defined(__SSE2__)
#include <xmmintrin.h>
#endif

// Counting allocations: glibc lets an executable interpose malloc and reach
// the real allocator through __libc_malloc, which catches allocations made by
// Eigen, CHOLMOD and UMFPACK alike (operator new ends in malloc too).
// Not under AddressSanitizer, whose own malloc a replacement would shadow.
#if defined(__GLIBC__) && !defined(__SANITIZE_ADDRESS__)
#define STIFFSIM_COUNT_ALLOCATIONS 1
namespace {
std::atomic<bool> counting_allocations{false};
std::atomic<long> allocation_count{0};
}  // namespace
extern "C" {
void* __libc_malloc(size_t size);
void* __libc_calloc(size_t count, size_t size);
void* __libc_realloc(void* pointer, size_t size);
void* malloc(size_t size) {
  if (counting_allocations.load(std::memory_order_relaxed)) ++allocation_count;
  return __libc_malloc(size);
}
void* calloc(size_t count, size_t size) {
  if (counting_allocations.load(std::memory_order_relaxed)) ++allocation_count;
  return __libc_calloc(count, size);
}
void* realloc(void* pointer, size_t size) {
  if (counting_allocations.load(std::memory_order_relaxed)) ++allocation_count;
  return __libc_realloc(pointer, size);
}
}
#endif

namespace stiffsim {
namespace {

// Residuals are relative to |b|; every system below has a condition number
// below ~1e3, so 1e-10 leaves several digits of margin over double rounding.
constexpr double kResidualTolerance = 1e-10;

// 5-point Laplacian on an m x m grid (Dirichlet), eigenvalues in (0, 8), plus
// `shift` on the diagonal (a vector so that values can be random), plus an
// optional skew part `convection` on the x-neighbours (unsymmetric values,
// symmetric pattern).
SparseMatrix grid_matrix(int m, const Eigen::VectorXd& shift, double convection = 0.0) {
  const int n = m * m;
  std::vector<Eigen::Triplet<double>> triplets;
  for (int y = 0; y < m; ++y) {
    for (int x = 0; x < m; ++x) {
      const int k = y * m + x;
      triplets.emplace_back(k, k, 4.0 + shift[k]);
      if (x > 0) triplets.emplace_back(k, k - 1, -1.0 - convection);
      if (x + 1 < m) triplets.emplace_back(k, k + 1, -1.0 + convection);
      if (y > 0) triplets.emplace_back(k, k - m, -1.0);
      if (y + 1 < m) triplets.emplace_back(k, k + m, -1.0);
    }
  }
  SparseMatrix A(n, n);
  A.setFromTriplets(triplets.begin(), triplets.end());
  A.makeCompressed();
  return A;
}

Eigen::VectorXd random_vector(int n, unsigned seed, double low = -1.0, double high = 1.0) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uniform(low, high);
  Eigen::VectorXd v(n);
  for (int i = 0; i < n; ++i) v[i] = uniform(rng);
  return v;
}

SparseMatrix random_spd(int m, unsigned seed) {
  return grid_matrix(m, random_vector(m * m, seed, 0.5, 1.5));
}

// Symmetric, nonsingular, one negative eigenvalue: the shift sits halfway
// between the two smallest Laplacian eigenvalues, 4 - 2cos(i pi/(m+1)) -
// 2cos(j pi/(m+1)) for (i, j) = (1, 1) and (1, 2).
SparseMatrix symmetric_indefinite(int m) {
  const double h = M_PI / (m + 1);
  const double lambda11 = 4.0 - 4.0 * std::cos(h);
  const double lambda12 = 4.0 - 2.0 * std::cos(h) - 2.0 * std::cos(2.0 * h);
  return grid_matrix(m, Eigen::VectorXd::Constant(m * m, -0.5 * (lambda11 + lambda12)));
}

// The matrix with row and column `k` zeroed but kept in the pattern.
SparseMatrix with_zero_row_and_column(SparseMatrix A, int k) {
  for (int j = 0; j < A.outerSize(); ++j) {
    for (SparseMatrix::InnerIterator it(A, j); it; ++it) {
      if (it.row() == k || it.col() == k) it.valueRef() = 0.0;
    }
  }
  return A;
}

double relative_residual(const SparseMatrix& A, const Eigen::VectorXd& x,
                         const Eigen::VectorXd& b) {
  return (A * x - b).norm() / b.norm();
}

// CHOLMOD names its LL^T variant once analyze() has seen the pattern.
std::string expected_method(LinearSolverKind kind, bool analyzed) {
  switch (kind) {
    case LinearSolverKind::kDenseLU:
      return "dense-lu";
    case LinearSolverKind::kDenseLDLT:
      return "dense-ldlt";
    case LinearSolverKind::kCholmod:
      // The 40 x 40 grid Laplacian of these tests: flops/nnz(L) = 17 after
      // ordering, below CHOLMOD's switch of 40.
      return analyzed ? "cholmod-simplicial-llt" : "cholmod-llt";
    case LinearSolverKind::kUmfpack:
      return "umfpack";
    case LinearSolverKind::kAuto:
      break;
  }
  return "";
}

// Every explicit kind on symmetric positive definite systems. Dense solvers get
// a 24 x 24 grid (n = 576) to stay fast; sparse ones a 40 x 40 grid (n = 1600).
class EverySolverTest : public testing::TestWithParam<LinearSolverKind> {
 protected:
  int grid() const {
    const LinearSolverKind kind = GetParam();
    return kind == LinearSolverKind::kDenseLU || kind == LinearSolverKind::kDenseLDLT ? 24 : 40;
  }
  std::unique_ptr<LinearSolver> make(const SparseMatrix& pattern) const {
    LinearSolverChoice choice = make_linear_solver(GetParam(), pattern, /*symmetric=*/true);
    EXPECT_EQ(choice.solver->method(), expected_method(GetParam(), false));
    choice.solver->analyze(pattern);
    return std::move(choice.solver);
  }
};

TEST_P(EverySolverTest, SolvesRandomSpdSystem) {
  const SparseMatrix A = random_spd(grid(), 1);
  const Eigen::VectorXd b = random_vector(A.rows(), 2);
  auto solver = make(A);
  ASSERT_TRUE(solver->factorize(A));
  Eigen::VectorXd x(A.rows());
  solver->solve(b, &x);
  EXPECT_LT(relative_residual(A, x, b), kResidualTolerance);
  EXPECT_GT(solver->factor_nonzeros(), A.rows());
  EXPECT_TRUE(solver->fallback_note().empty());
  EXPECT_EQ(solver->method(), expected_method(GetParam(), true));
}

TEST_P(EverySolverTest, RefactorsNewValuesOnTheSamePatternWithoutReanalysis) {
  const SparseMatrix A1 = random_spd(grid(), 3);
  const SparseMatrix A2 = random_spd(grid(), 4);
  ASSERT_FALSE(A1.isApprox(A2));
  const Eigen::VectorXd b = random_vector(A1.rows(), 5);
  auto solver = make(A1);
  Eigen::VectorXd x1(A1.rows()), x2(A1.rows());
  ASSERT_TRUE(solver->factorize(A1));
  solver->solve(b, &x1);
  ASSERT_TRUE(solver->factorize(A2));
  solver->solve(b, &x2);
  EXPECT_LT(relative_residual(A1, x1, b), kResidualTolerance);
  EXPECT_LT(relative_residual(A2, x2, b), kResidualTolerance);
  // Fails if the second solve still used the first factor.
  EXPECT_GT(relative_residual(A1, x2, b), 1e-6);
  EXPECT_EQ(solver->counters().analyses, 1);
  EXPECT_EQ(solver->counters().factorizations, 2);
  EXPECT_EQ(solver->counters().solves, 2);
  EXPECT_GT(solver->counters().factorization_seconds, 0.0);
}

TEST_P(EverySolverTest, SingularMatrixFailsToFactorize) {
  const SparseMatrix A = with_zero_row_and_column(random_spd(grid(), 6), 17);
  auto solver = make(A);
  EXPECT_FALSE(solver->factorize(A));
  Eigen::VectorXd x(A.rows());
  EXPECT_THROW(solver->solve(random_vector(A.rows(), 7), &x), std::logic_error);
}

// A graph Laplacian (no diagonal shift, Neumann rows summing to zero) is
// singular, but rounding leaves a tiny pivot rather than an exact zero.
TEST_P(EverySolverTest, RoundingHiddenSingularityFailsToFactorize) {
  SparseMatrix A = random_spd(grid(), 8);
  for (int j = 0; j < A.outerSize(); ++j) {
    double off_diagonal_sum = 0.0;
    for (SparseMatrix::InnerIterator it(A, j); it; ++it) {
      if (it.row() != j) off_diagonal_sum += it.value();
    }
    A.coeffRef(j, j) = -off_diagonal_sum;
  }
  auto solver = make(A);
  EXPECT_FALSE(solver->factorize(A));
}

TEST_P(EverySolverTest, NonFiniteValueFailsWithoutChangingMethodAndRecovers) {
  const SparseMatrix A = random_spd(grid(), 9);
  SparseMatrix poisoned = A;
  poisoned.valuePtr()[poisoned.nonZeros() / 2] = std::numeric_limits<double>::quiet_NaN();
  auto solver = make(A);
  EXPECT_FALSE(solver->factorize(poisoned));
  poisoned.valuePtr()[poisoned.nonZeros() / 2] = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(solver->factorize(poisoned));
  EXPECT_EQ(solver->method(), expected_method(GetParam(), true))
      << "NaN must not trigger a fallback";
  EXPECT_TRUE(solver->fallback_note().empty());

  ASSERT_TRUE(solver->factorize(A));
  const Eigen::VectorXd b = random_vector(A.rows(), 10);
  Eigen::VectorXd x(A.rows());
  solver->solve(b, &x);
  EXPECT_LT(relative_residual(A, x, b), kResidualTolerance);
}

TEST_P(EverySolverTest, SolveDoesNotAllocateInSteadyState) {
#ifndef STIFFSIM_COUNT_ALLOCATIONS
  GTEST_SKIP() << "allocation counting needs glibc";
#else
  const SparseMatrix A = random_spd(grid(), 11);
  const Eigen::VectorXd b1 = random_vector(A.rows(), 12);
  const Eigen::VectorXd b2 = random_vector(A.rows(), 13);
  auto solver = make(A);
  ASSERT_TRUE(solver->factorize(A));
  Eigen::VectorXd x(A.rows());
  solver->solve(b1, &x);  // the first solve may size workspaces
  // The instrument itself must see an ordinary Eigen allocation.
  allocation_count = 0;
  counting_allocations = true;
  const Eigen::VectorXd copy = b1;
  counting_allocations = false;
  ASSERT_GT(allocation_count.load(), 0);
  ASSERT_EQ(copy, b1);
  allocation_count = 0;
  counting_allocations = true;
  solver->solve(b2, &x);
  solver->solve(b1, &x);
  counting_allocations = false;
  EXPECT_EQ(allocation_count.load(), 0);
  EXPECT_LT(relative_residual(A, x, b1), kResidualTolerance);
#endif
}

TEST_P(EverySolverTest, RejectsMatrixWithAnotherPatternOrSize) {
  const SparseMatrix A = random_spd(grid(), 14);
  auto solver = make(A);
  const SparseMatrix smaller = random_spd(grid() - 1, 14);
  EXPECT_THROW(solver->factorize(smaller), std::invalid_argument);
}

INSTANTIATE_TEST_SUITE_P(LinearSolvers, EverySolverTest,
                         testing::Values(LinearSolverKind::kDenseLU, LinearSolverKind::kDenseLDLT,
                                         LinearSolverKind::kCholmod, LinearSolverKind::kUmfpack),
                         [](const testing::TestParamInfo<LinearSolverKind>& info) {
                           std::string name = to_string(info.param);
                           name.erase(std::remove(name.begin(), name.end(), '-'), name.end());
                           return name;
                         });

// Solvers that accept unsymmetric matrices.
class UnsymmetricSolverTest : public testing::TestWithParam<LinearSolverKind> {};

TEST_P(UnsymmetricSolverTest, SolvesUnsymmetricSystem) {
  const int m = GetParam() == LinearSolverKind::kDenseLU ? 24 : 40;
  const SparseMatrix A = grid_matrix(m, random_vector(m * m, 20, 0.5, 1.5), /*convection=*/0.6);
  ASSERT_FALSE(A.isApprox(SparseMatrix(A.transpose())));
  const Eigen::VectorXd b = random_vector(A.rows(), 21);
  LinearSolverChoice choice = make_linear_solver(GetParam(), A, /*symmetric=*/false);
  choice.solver->analyze(A);
  ASSERT_TRUE(choice.solver->factorize(A));
  Eigen::VectorXd x(A.rows());
  choice.solver->solve(b, &x);
  EXPECT_LT(relative_residual(A, x, b), kResidualTolerance);
  // Fails if only one triangle (or the symmetric part) had been used.
  EXPECT_GT(relative_residual(SparseMatrix(A.transpose()), x, b), 1e-3);
}

INSTANTIATE_TEST_SUITE_P(LinearSolvers, UnsymmetricSolverTest,
                         testing::Values(LinearSolverKind::kDenseLU, LinearSolverKind::kUmfpack),
                         [](const testing::TestParamInfo<LinearSolverKind>& info) {
                           std::string name = to_string(info.param);
                           name.erase(std::remove(name.begin(), name.end(), '-'), name.end());
                           return name;
                         });

TEST(CholmodSolverTest, IndefiniteMatrixFallsBackToLdltOnceAndStillSolves) {
  const SparseMatrix A = symmetric_indefinite(30);
  const Eigen::VectorXd b = random_vector(A.rows(), 30);
  CholmodSolver solver;
  solver.analyze(A);
  const std::string llt = solver.method() == "cholmod-supernodal-llt" ? "CHOLMOD supernodal LL^T"
                                                                      : "CHOLMOD simplicial LL^T";
  testing::internal::CaptureStderr();
  ASSERT_TRUE(solver.factorize(A));
  const std::string first_log = testing::internal::GetCapturedStderr();
  EXPECT_EQ(solver.method(), "cholmod-ldlt");
  EXPECT_NE(solver.fallback_note().find("not positive definite"), std::string::npos)
      << solver.fallback_note();
  EXPECT_NE(solver.fallback_note().find("at factorization 1:"), std::string::npos)
      << solver.fallback_note();
  EXPECT_NE(solver.fallback_note().find("switched from " + llt + " to CHOLMOD LDL^T"),
            std::string::npos)
      << solver.fallback_note();
  EXPECT_EQ(first_log, "stiffsim: " + solver.fallback_note() + "\n");

  Eigen::VectorXd x(A.rows());
  solver.solve(b, &x);
  EXPECT_LT(relative_residual(A, x, b), kResidualTolerance);
  EXPECT_GT(solver.factor_nonzeros(), A.rows());

  // The switch is permanent and said once: a second indefinite matrix (and a
  // definite one) are factored by LDL^T without a word.
  const SparseMatrix spd = random_spd(30, 31);
  testing::internal::CaptureStderr();
  ASSERT_TRUE(solver.factorize(A));
  ASSERT_TRUE(solver.factorize(spd));
  EXPECT_EQ(testing::internal::GetCapturedStderr(), "");
  EXPECT_EQ(solver.method(), "cholmod-ldlt");
  solver.solve(b, &x);
  EXPECT_LT(relative_residual(spd, x, b), kResidualTolerance);
  // One analysis for the pattern, one redone for LDL^T.
  EXPECT_EQ(solver.counters().analyses, 2);
  EXPECT_EQ(solver.counters().factorizations, 3);
}

// [[0, L], [L, 0]], with the diagonal's zeros explicit in the pattern or
// absent from it.
SparseMatrix swapped_blocks(const SparseMatrix& L, bool explicit_zero_diagonal) {
  const int half = static_cast<int>(L.rows()), n = 2 * half;
  std::vector<Eigen::Triplet<double>> triplets;
  for (int j = 0; j < L.outerSize(); ++j) {
    for (SparseMatrix::InnerIterator it(L, j); it; ++it) {
      triplets.emplace_back(it.row(), half + it.col(), it.value());
      triplets.emplace_back(half + it.row(), it.col(), it.value());
    }
  }
  if (explicit_zero_diagonal) {
    for (int k = 0; k < n; ++k) triplets.emplace_back(k, k, 0.0);
  }
  SparseMatrix A(n, n);
  A.setFromTriplets(triplets.begin(), triplets.end());
  A.makeCompressed();
  return A;
}

// [[0, L], [L, 0]] with L a shifted Laplacian: nonsingular, but every diagonal
// entry is zero, so LDL^T without pivoting meets a zero pivot whatever the
// ordering, and only UMFPACK's pivoting gets through.
TEST(CholmodSolverTest, ZeroDiagonalFallsBackToUmfpack) {
  const SparseMatrix A = swapped_blocks(random_spd(15, 40), true);
  const int n = static_cast<int>(A.rows());

  CholmodSolver solver;
  solver.analyze(A);
  testing::internal::CaptureStderr();
  ASSERT_TRUE(solver.factorize(A));
  const std::string log = testing::internal::GetCapturedStderr();
  EXPECT_EQ(solver.method(), "umfpack");
  EXPECT_NE(solver.fallback_note().find("to CHOLMOD LDL^T"), std::string::npos);
  EXPECT_NE(solver.fallback_note().find("switched from CHOLMOD LDL^T to UMFPACK"),
            std::string::npos)
      << solver.fallback_note();
  EXPECT_NE(log.find("stiffsim: "), std::string::npos);
  const Eigen::VectorXd b = random_vector(n, 41);
  Eigen::VectorXd x(n);
  solver.solve(b, &x);
  EXPECT_LT(relative_residual(A, x, b), kResidualTolerance);
  EXPECT_GT(solver.factor_nonzeros(), n);
}

// The shape of a particle system's iteration matrix: a diagonal mass plus,
// for each spring between nodes a and b, the 3 x 3 block K = k (d d^T + 0.1 I)
// (d a random unit direction) assembled as [K -K; -K K]. Symmetric positive
// definite; condition number below ~1e3 for the stiffness used here.
SparseMatrix spring_network(int nodes, const std::vector<std::pair<int, int>>& springs,
                            unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal;
  std::vector<Eigen::Triplet<double>> triplets;
  for (int i = 0; i < 3 * nodes; ++i) triplets.emplace_back(i, i, 1.0);
  for (const auto& [a, b] : springs) {
    Eigen::Vector3d d(normal(rng), normal(rng), normal(rng));
    d.normalize();
    const Eigen::Matrix3d K = 10.0 * (d * d.transpose() + 0.1 * Eigen::Matrix3d::Identity());
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) {
        triplets.emplace_back(3 * a + r, 3 * a + c, K(r, c));
        triplets.emplace_back(3 * b + r, 3 * b + c, K(r, c));
        triplets.emplace_back(3 * a + r, 3 * b + c, -K(r, c));
        triplets.emplace_back(3 * b + r, 3 * a + c, -K(r, c));
      }
    }
  }
  SparseMatrix A(3 * nodes, 3 * nodes);
  A.setFromTriplets(triplets.begin(), triplets.end());
  A.makeCompressed();
  return A;
}

// A rope: stretch springs to the next node, bend springs to the one after.
SparseMatrix rope_matrix(int nodes, unsigned seed) {
  std::vector<std::pair<int, int>> springs;
  for (int i = 0; i + 1 < nodes; ++i) springs.emplace_back(i, i + 1);
  for (int i = 0; i + 2 < nodes; ++i) springs.emplace_back(i, i + 2);
  return spring_network(nodes, springs, seed);
}

// A cloth: stretch, shear and bend springs (two apart) on an m x m grid.
SparseMatrix cloth_matrix(int m, unsigned seed) {
  std::vector<std::pair<int, int>> springs;
  auto node = [m](int x, int y) { return y * m + x; };
  for (int y = 0; y < m; ++y) {
    for (int x = 0; x < m; ++x) {
      if (x + 1 < m) springs.emplace_back(node(x, y), node(x + 1, y));
      if (y + 1 < m) springs.emplace_back(node(x, y), node(x, y + 1));
      if (x + 1 < m && y + 1 < m) springs.emplace_back(node(x, y), node(x + 1, y + 1));
      if (x > 0 && y + 1 < m) springs.emplace_back(node(x, y), node(x - 1, y + 1));
      if (x + 2 < m) springs.emplace_back(node(x, y), node(x + 2, y));
      if (y + 2 < m) springs.emplace_back(node(x, y), node(x, y + 2));
    }
  }
  return spring_network(m * m, springs, seed);
}

TEST(CholmodSolverTest, BandedRopePatternPicksSimplicialLltAndSolves) {
  const SparseMatrix A = rope_matrix(3334, 60);  // 10,002 DOFs
  CholmodSolver solver;
  solver.analyze(A);
  EXPECT_EQ(solver.method(), "cholmod-simplicial-llt");
  EXPECT_NE(solver.factorization_note().find("cholmod-simplicial-llt: flops/nnz(L) = "),
            std::string::npos)
      << solver.factorization_note();
  EXPECT_NE(solver.factorization_note().find(" < 40"), std::string::npos)
      << solver.factorization_note();
  ASSERT_TRUE(solver.factorize(A));
  EXPECT_TRUE(solver.fallback_note().empty());
  const Eigen::VectorXd b = random_vector(A.rows(), 61);
  Eigen::VectorXd x(A.rows());
  solver.solve(b, &x);
  EXPECT_LT(relative_residual(A, x, b), kResidualTolerance);
  // Against Eigen's own simplicial Cholesky, to the same rounding margin.
  const Eigen::SimplicialLLT<SparseMatrix> reference(A);
  ASSERT_EQ(reference.info(), Eigen::Success);
  const Eigen::VectorXd expected = reference.solve(b);
  EXPECT_LT((x - expected).norm() / expected.norm(), kResidualTolerance);
  // A band of 6 below the diagonal stays a band after ordering: no fill to
  // speak of, and no explicit zeros of supernodal padding.
  EXPECT_LT(solver.factor_nonzeros(), 8 * A.rows());
}

TEST(CholmodSolverTest, ClothGridPatternPicksSupernodalLltAndSolves) {
  const SparseMatrix A = cloth_matrix(100, 62);  // 30,000 DOFs
  CholmodSolver solver;
  solver.analyze(A);
  EXPECT_EQ(solver.method(), "cholmod-supernodal-llt");
  EXPECT_NE(solver.factorization_note().find("cholmod-supernodal-llt: flops/nnz(L) = "),
            std::string::npos)
      << solver.factorization_note();
  EXPECT_NE(solver.factorization_note().find(" >= 40"), std::string::npos)
      << solver.factorization_note();
  ASSERT_TRUE(solver.factorize(A));
  const Eigen::VectorXd b = random_vector(A.rows(), 63);
  Eigen::VectorXd x(A.rows());
  solver.solve(b, &x);
  EXPECT_LT(relative_residual(A, x, b), kResidualTolerance);
  // Its float factor (about 26 MB: the 100x100 sheet's pattern) is
  // prefetched ahead of the sweeps (CholmodSolver::kPrefetchFromBytes); the
  // solve is the double one to float rounding, as for a small factor
  // (SupernodalPreconditionerSolvesInSinglePrecision).
  Eigen::VectorXd x_single(A.rows());
  solver.solve_preconditioner(b, &x_single);
  EXPECT_EQ(solver.counters().single_precision_solves, 1);
  EXPECT_EQ(solver.counters().prefetched_solves, 1);
  EXPECT_LT(relative_residual(A, x_single, b), 1e-5);
  EXPECT_LT((x_single - x).norm() / x.norm(), 1e-4);
}

// CHOLMOD's view of a lower triangle held by Eigen, for calling CHOLMOD
// directly.
cholmod_sparse lower_view(const SparseMatrix& lower) {
  cholmod_sparse a{};
  a.nrow = a.ncol = static_cast<std::size_t>(lower.rows());
  a.nzmax = static_cast<std::size_t>(lower.nonZeros());
  a.p = const_cast<int*>(lower.outerIndexPtr());
  a.i = const_cast<int*>(lower.innerIndexPtr());
  a.x = const_cast<double*>(lower.valuePtr());
  a.stype = -1;
  a.itype = CHOLMOD_INT;
  a.xtype = CHOLMOD_REAL;
  a.dtype = CHOLMOD_DOUBLE;
  a.sorted = a.packed = 1;
  return a;
}

// CHOLMOD's supernodal factorization counts and times its BLAS calls.
// cholmod_solver.cc defines SuiteSparse_time, which the library's timers
// then call instead of reading the clock: the calls are counted, and no
// time passes in them. (Without the definition the 2,700-unknown sheet's
// calls summed to 0.9-2.3 ms each kind.)
TEST(CholmodSolverTest, SuiteSparseTimersAreNotRead) {
  const SparseMatrix A = cloth_matrix(30, 34);
  const SparseMatrix lower = A.triangularView<Eigen::Lower>();
  cholmod_common common;
  cholmod_start(&common);
  common.supernodal = CHOLMOD_SUPERNODAL;
  cholmod_sparse a = lower_view(lower);
  cholmod_factor* factor = cholmod_analyze(&a, &common);
  ASSERT_NE(factor, nullptr);
  ASSERT_TRUE(cholmod_factorize(&a, factor, &common));
  EXPECT_EQ(common.status, CHOLMOD_OK);
  EXPECT_TRUE(factor->is_super);
  EXPECT_GT(common.cholmod_cpu_syrk_calls + common.cholmod_cpu_gemm_calls, 0u);
  EXPECT_EQ(common.cholmod_cpu_syrk_time, 0.0);
  EXPECT_EQ(common.cholmod_cpu_gemm_time, 0.0);
  EXPECT_EQ(common.cholmod_cpu_potrf_time, 0.0);
  EXPECT_EQ(common.cholmod_cpu_trsm_time, 0.0);
  cholmod_free_factor(&factor, &common);
  cholmod_finish(&common);
}

// FloatCholesky on CHOLMOD's supernodal analysis (natural ordering, as
// CholmodSolver analyzes its permuted matrix) against CHOLMOD's double
// factor of the same matrix: entry by entry, within float's rounding of
// an elimination (the factor's largest entry times a few hundred float
// epsilons), and false for an indefinite matrix.
TEST(FloatCholeskyTest, MatchesCholmodsDoubleFactor) {
  for (int m : {12, 30}) {
    SCOPED_TRACE(m);
    const SparseMatrix A = cloth_matrix(m, 35);
    const SparseMatrix lower = A.triangularView<Eigen::Lower>();
    cholmod_common common;
    cholmod_start(&common);
    common.supernodal = CHOLMOD_SUPERNODAL;
    common.nmethods = 1;
    common.method[0].ordering = CHOLMOD_NATURAL;
    common.postorder = false;
    cholmod_sparse a = lower_view(lower);
    cholmod_factor* factor = cholmod_analyze(&a, &common);
    ASSERT_NE(factor, nullptr);
    ASSERT_TRUE(factor->is_super);
    FloatCholesky single;
    single.analyze(*factor);
    std::vector<float> L(factor->xsize);
    ASSERT_TRUE(
        single.factorize(lower.outerIndexPtr(), lower.innerIndexPtr(), lower.valuePtr(), L.data()));
    ASSERT_TRUE(cholmod_factorize(&a, factor, &common));
    ASSERT_EQ(common.status, CHOLMOD_OK);
    const double* reference = static_cast<const double*>(factor->x);
    double largest = 0.0, difference = 0.0;
    for (std::size_t k = 0; k < factor->xsize; ++k) {
      largest = std::max(largest, std::abs(reference[k]));
      difference = std::max(difference, std::abs(reference[k] - L[k]));
    }
    EXPECT_GT(largest, 1.0);
    EXPECT_LT(difference, 300 * std::numeric_limits<float>::epsilon() * largest);
    // e_k^T A e_k < 0 on the same pattern: not definite.
    SparseMatrix indefinite = lower;
    const int k = static_cast<int>(lower.rows()) / 2;
    indefinite.coeffRef(k, k) = -indefinite.coeff(k, k);
    EXPECT_FALSE(single.factorize(indefinite.outerIndexPtr(), indefinite.innerIndexPtr(),
                                  indefinite.valuePtr(), L.data()));
    cholmod_free_factor(&factor, &common);
    cholmod_finish(&common);
  }
}

// factorize_if_definite() tries the LL^T alone: an indefinite matrix fails
// it without a fallback or a word, and the solver keeps its LL^T for the
// definite matrix a caller then factors instead (an integrator's exact
// Hessian, then its clamped form). factorize() still falls back, after
// which there is no LL^T to try. A grid (simplicial) and a cloth
// (supernodal).
TEST(CholmodSolverTest, FactorizeIfDefiniteFailsOnIndefiniteWithoutFallingBack) {
  std::vector<std::string> methods;
  for (const SparseMatrix& spd : {random_spd(30, 31), cloth_matrix(30, 32)}) {
    CholmodSolver solver;
    solver.analyze(spd);
    const std::string method = solver.method();
    methods.push_back(method);
    SCOPED_TRACE(method);
    ASSERT_TRUE(solver.has_cholesky());
    // e_k^T A e_k < 0: indefinite, on the same pattern.
    SparseMatrix indefinite = spd;
    const int k = static_cast<int>(spd.rows()) / 2;
    indefinite.coeffRef(k, k) = -indefinite.coeff(k, k);
    const Eigen::VectorXd b = random_vector(static_cast<int>(spd.rows()), 33);
    Eigen::VectorXd x(spd.rows());
    testing::internal::CaptureStderr();
    EXPECT_FALSE(solver.factorize_if_definite(indefinite));
    EXPECT_EQ(testing::internal::GetCapturedStderr(), "");
    EXPECT_EQ(solver.method(), method);
    EXPECT_TRUE(solver.fallback_note().empty());
    EXPECT_TRUE(solver.has_cholesky());
    EXPECT_THROW(solver.solve(b, &x), std::logic_error);  // nothing factored
    ASSERT_TRUE(solver.factorize_if_definite(spd));
    solver.solve(b, &x);
    EXPECT_LT(relative_residual(spd, x, b), kResidualTolerance);
    testing::internal::CaptureStderr();
    ASSERT_TRUE(solver.factorize(indefinite));
    testing::internal::GetCapturedStderr();
    EXPECT_EQ(solver.method(), "cholmod-ldlt");
    EXPECT_FALSE(solver.has_cholesky());
    EXPECT_FALSE(solver.factorize_if_definite(spd));  // not attempted
    EXPECT_EQ(solver.counters().factorizations, 3);
  }
  EXPECT_EQ(methods,
            (std::vector<std::string>{"cholmod-simplicial-llt", "cholmod-supernodal-llt"}));
}

// A supernodal factor is computed from P A P^T, whose pattern the analysis
// formed with the slot of A each entry comes from: every factorization
// takes A's current values, and solves permute in and out. Two matrices of
// one pattern in turn, then a negative definite one, which falls back to
// LDL^T (analyzed again, simplicial, from A itself).
TEST(CholmodSolverTest, SupernodalFactorsThePermutedMatrixFormedAtTheAnalysis) {
  const SparseMatrix A = cloth_matrix(40, 70);  // 4,800 DOFs
  SparseMatrix B = A;
  for (int k = 0; k < B.nonZeros(); ++k) B.valuePtr()[k] *= 1.0 + 0.1 * std::sin(k);
  B = SparseMatrix(0.5 * (B + SparseMatrix(B.transpose())));
  B.diagonal().array() += 10.0;
  ASSERT_EQ(B.nonZeros(), A.nonZeros());
  const SparseMatrix& C = B;
  CholmodSolver solver;
  solver.analyze(A);
  ASSERT_EQ(solver.method(), "cholmod-supernodal-llt");
  EXPECT_NE(solver.factorization_note().find("P A P^T formed at the analysis"), std::string::npos)
      << solver.factorization_note();
  const Eigen::VectorXd b = random_vector(A.rows(), 71);
  Eigen::VectorXd x(A.rows());
  for (const SparseMatrix* M : {&A, &C, &A}) {
    ASSERT_TRUE(solver.factorize(*M));
    solver.solve(b, &x);
    EXPECT_LT(relative_residual(*M, x, b), kResidualTolerance);
  }
  EXPECT_GT(relative_residual(B, x, b), 1e-6);  // B's solve is not A's
  const SparseMatrix negative = -A;
  testing::internal::CaptureStderr();
  ASSERT_TRUE(solver.factorize(negative));
  testing::internal::GetCapturedStderr();
  EXPECT_EQ(solver.method(), "cholmod-ldlt");
  solver.solve(b, &x);
  EXPECT_LT(relative_residual(negative, x, b), kResidualTolerance);
}

// A supernodal factor applied as a preconditioner runs in single
// precision: its solve is the double solve to float rounding, no closer,
// and follows each new factorization. Cholesky in float leaves a backward
// error of a modest multiple of its epsilon (6e-8) times |A|, so the
// relative residual stays near 1e-6; the double solve's is near 1e-15.
// Where the factor is simplicial (a rope), there is no single-precision
// copy: the preconditioner solve is the solve itself.
TEST(CholmodSolverTest, SupernodalPreconditionerSolvesInSinglePrecision) {
  const SparseMatrix A = cloth_matrix(40, 72);  // 4,800 DOFs
  SparseMatrix B = A;
  for (int k = 0; k < B.nonZeros(); ++k) B.valuePtr()[k] *= 1.0 + 0.1 * std::cos(k);
  B = SparseMatrix(0.5 * (B + SparseMatrix(B.transpose())));
  B.diagonal().array() += 10.0;
  CholmodSolver solver;
  solver.analyze(A);
  ASSERT_EQ(solver.method(), "cholmod-supernodal-llt");
  const Eigen::VectorXd b = random_vector(A.rows(), 73);
  Eigen::VectorXd x(A.rows()), x_single(A.rows());
  const SparseMatrix& C = B;
  for (const SparseMatrix* M : {&A, &C, &A}) {
    ASSERT_TRUE(solver.factorize(*M));
    solver.solve(b, &x);
    solver.solve_preconditioner(b, &x_single);
    const double residual = relative_residual(*M, x_single, b);
    EXPECT_LT(residual, 1e-5);
    EXPECT_GT(residual, 1e3 * relative_residual(*M, x, b));  // float, not double
    EXPECT_LT((x_single - x).norm() / x.norm(), 1e-4);
  }
  EXPECT_EQ(solver.counters().solves, 6);
  EXPECT_EQ(solver.counters().single_precision_solves, 3);
  EXPECT_EQ(solver.counters().single_precision_declined, 0);
  EXPECT_EQ(solver.counters().prefetched_solves, 0);  // a float factor below 8 MB

  const SparseMatrix R = rope_matrix(400, 74);
  CholmodSolver simplicial;
  simplicial.analyze(R);
  ASSERT_EQ(simplicial.method(), "cholmod-simplicial-llt");
  ASSERT_TRUE(simplicial.factorize(R));
  const Eigen::VectorXd c = random_vector(R.rows(), 75);
  Eigen::VectorXd y(R.rows()), y_preconditioner(R.rows());
  simplicial.solve(c, &y);
  simplicial.solve_preconditioner(c, &y_preconditioner);
  EXPECT_EQ(y_preconditioner, y);
  EXPECT_EQ(simplicial.counters().single_precision_solves, 0);
}

// The first preconditioner solve after a factorization measures the float
// solve's residual against the factored matrix. Where W's condition times
// float's epsilon is not small (here the stiffness a million times the
// mass term, condition ~1e9), the float answer is far from A^-1 b and that
// factorization's preconditioner solves run in double; the next
// well-conditioned factorization returns to single precision.
TEST(CholmodSolverTest, IllConditionedFactorPreconditionsInDouble) {
  const SparseMatrix A = cloth_matrix(40, 76);
  SparseMatrix identity(A.rows(), A.cols());
  identity.setIdentity();
  SparseMatrix stiff = 1e6 * (A - identity) + identity;  // the same pattern
  stiff.makeCompressed();
  ASSERT_EQ(stiff.nonZeros(), A.nonZeros());
  CholmodSolver solver;
  solver.analyze(A);
  ASSERT_EQ(solver.method(), "cholmod-supernodal-llt");
  const Eigen::VectorXd b = random_vector(A.rows(), 77);
  Eigen::VectorXd x(A.rows()), x_preconditioner(A.rows());

  ASSERT_TRUE(solver.factorize(stiff));
  solver.solve(b, &x);
  for (int k = 0; k < 2; ++k) {
    solver.solve_preconditioner(b, &x_preconditioner);
    EXPECT_LT((x_preconditioner - x).norm(), 1e-12 * x.norm());  // double's answer
  }
  EXPECT_EQ(solver.counters().single_precision_declined, 1);
  EXPECT_EQ(solver.counters().single_precision_solves, 0);

  ASSERT_TRUE(solver.factorize(A));
  solver.solve(b, &x);
  solver.solve_preconditioner(b, &x_preconditioner);
  EXPECT_LT((x_preconditioner - x).norm() / x.norm(), 1e-4);
  EXPECT_GT((x_preconditioner - x).norm() / x.norm(), 1e-12);  // float's
  EXPECT_EQ(solver.counters().single_precision_declined, 1);
  EXPECT_EQ(solver.counters().single_precision_solves, 1);
}

// factorize_preconditioner() factors a supernodal LL^T in single
// precision only (FloatCholesky): its preconditioner solves are float
// ones, checked once against the matrix, and a double solve() factors the
// same values in double first (once). Where the float factor misses
// (stiffness a million times the mass term: in float the soft directions
// are lost to the stiff ones' rounding), that factorization solves in
// double and the solver factors in double from then on, while the float
// copy of a double factor still serves the next well-conditioned matrix.
// An indefinite matrix fails if_definite without a fallback.
TEST(CholmodSolverTest, PreconditionerFactorsInSinglePrecisionUntilFloatMisses) {
  const SparseMatrix A = cloth_matrix(40, 80);
  CholmodSolver solver;
  solver.analyze(A);
  ASSERT_EQ(solver.method(), "cholmod-supernodal-llt");
  const Eigen::VectorXd b = random_vector(A.rows(), 81);
  Eigen::VectorXd x(A.rows()), x_single(A.rows());
  ASSERT_TRUE(solver.factorize_preconditioner(A, false));
  EXPECT_EQ(solver.counters().single_precision_factorizations, 1);
  EXPECT_EQ(solver.counters().factorizations, 1);
  for (int k = 0; k < 2; ++k) {
    solver.solve_preconditioner(b, &x_single);
    const double residual = relative_residual(A, x_single, b);
    EXPECT_LT(residual, 1e-5);
    EXPECT_GT(residual, 1e-10);  // float's
  }
  solver.solve(b, &x);
  EXPECT_LT(relative_residual(A, x, b), kResidualTolerance);  // double's
  EXPECT_LT((x_single - x).norm() / x.norm(), 1e-4);
  EXPECT_EQ(solver.counters().single_precision_solves, 2);

  SparseMatrix identity(A.rows(), A.cols());
  identity.setIdentity();
  SparseMatrix stiff = 1e6 * (A - identity) + identity;  // the same pattern
  stiff.makeCompressed();
  ASSERT_TRUE(solver.factorize_preconditioner(stiff, false));
  EXPECT_EQ(solver.counters().single_precision_factorizations, 2);
  solver.solve_preconditioner(b, &x_single);
  EXPECT_EQ(solver.counters().single_precision_declined, 1);
  solver.solve(b, &x);
  CholmodSolver reference;  // the double factorization of the same matrix
  reference.analyze(A);
  ASSERT_TRUE(reference.factorize(stiff));
  Eigen::VectorXd x_reference(A.rows());
  reference.solve(b, &x_reference);
  EXPECT_LT((x - x_reference).norm(), 1e-12 * x_reference.norm());
  EXPECT_LT((x_single - x_reference).norm(), 1e-12 * x_reference.norm());  // double's answer

  ASSERT_TRUE(solver.factorize_preconditioner(A, false));
  EXPECT_EQ(solver.counters().single_precision_factorizations, 2);  // double now
  solver.solve_preconditioner(b, &x_single);
  EXPECT_LT(relative_residual(A, x_single, b), 1e-5);
  EXPECT_EQ(solver.counters().single_precision_solves, 3);  // the float copy's

  SparseMatrix indefinite = A;
  const int k = static_cast<int>(A.rows()) / 2;
  indefinite.coeffRef(k, k) = -indefinite.coeff(k, k);
  CholmodSolver fresh;
  fresh.analyze(A);
  testing::internal::CaptureStderr();
  EXPECT_FALSE(fresh.factorize_preconditioner(indefinite, true));
  EXPECT_EQ(testing::internal::GetCapturedStderr(), "");
  EXPECT_EQ(fresh.method(), "cholmod-supernodal-llt");
  EXPECT_THROW(fresh.solve(b, &x), std::logic_error);  // nothing factored
  ASSERT_TRUE(fresh.factorize_preconditioner(A, true));
  EXPECT_EQ(fresh.counters().single_precision_factorizations, 1);
}

// Right-hand sides far outside float's range (a Newton residual near its
// root can be 1e-40 and below) are scaled before the float solve, so the
// answer keeps float's relative precision; the float solve flushes
// subnormals and leaves the caller's floating-point control as it was.
TEST(CholmodSolverTest, PreconditionerSolveKeepsTinyAndHugeRightHandSides) {
  const SparseMatrix A = cloth_matrix(40, 78);
  CholmodSolver solver;
  solver.analyze(A);
  ASSERT_TRUE(solver.factorize(A));
  const Eigen::VectorXd b = random_vector(A.rows(), 79);
  Eigen::VectorXd x(A.rows()), x_single(A.rows());
  solver.solve(b, &x);
#if defined(__SSE2__)
  const unsigned int control = _mm_getcsr();
#endif
  for (const double size : {1e-300, 1e-45, 1.0, 1e60}) {
    solver.solve_preconditioner(size * b, &x_single);
    EXPECT_LT((x_single / size - x).norm() / x.norm(), 1e-4)
        << "right-hand side scaled by " << size;
  }
#if defined(__SSE2__)
  EXPECT_EQ(_mm_getcsr(), control);
#endif
  EXPECT_EQ(solver.counters().single_precision_solves, 4);
  solver.solve_preconditioner(Eigen::VectorXd::Zero(A.rows()), &x_single);
  EXPECT_EQ(x_single, Eigen::VectorXd::Zero(A.rows()));
}

// The LDL^T fallback re-analyzes as simplicial whichever LL^T was chosen; a
// banded indefinite matrix takes it from simplicial LL^T.
TEST(CholmodSolverTest, SimplicialLltFallsBackToLdltOnIndefiniteBandedMatrix) {
  SparseMatrix A = rope_matrix(200, 64);
  for (int i = 0; i < 3; ++i) A.coeffRef(3 * 100 + i, 3 * 100 + i) = -5.0;
  CholmodSolver solver;
  solver.analyze(A);
  ASSERT_EQ(solver.method(), "cholmod-simplicial-llt");
  const std::string note = solver.factorization_note();
  testing::internal::CaptureStderr();
  ASSERT_TRUE(solver.factorize(A));
  testing::internal::GetCapturedStderr();
  EXPECT_EQ(solver.method(), "cholmod-ldlt");
  EXPECT_NE(solver.fallback_note().find("switched from CHOLMOD simplicial LL^T to CHOLMOD LDL^T"),
            std::string::npos)
      << solver.fallback_note();
  EXPECT_EQ(solver.factorization_note(), note) << "the LL^T choice is kept as it was made";
  const Eigen::VectorXd b = random_vector(A.rows(), 65);
  Eigen::VectorXd x(A.rows());
  solver.solve(b, &x);
  EXPECT_LT(relative_residual(A, x, b), 1e-9);
}

// The shape of implicit Euler's Newton matrix in mass-matrix form on a
// cloth, [I, -h I; h K, M + h D] (K the stiffness, D the damping, of one
// pattern), whose Schur complement after the identity block is VIE's
// M + h D + h^2 K. The stiff springs' h K dwarfs M in the v rows
// (h^2 k / m = 700 and h c / m = 20 on models/cloth.yaml at h = 1/60).
// Its diagonal is zero-free, but only half of its pattern is symmetric (the
// q rows hold two entries, the v rows many), and UMFPACK's own choice, the
// unsymmetric strategy, gave twice the entries of the symmetric one here
// (795,078 against 395,616 for a 24x24 sheet).
SparseMatrix implicit_euler_matrix(const SparseMatrix& K, double h, double m, double c,
                                   SparseMatrix* schur) {
  const int n = static_cast<int>(K.rows());
  std::vector<Eigen::Triplet<double>> triplets;
  for (int k = 0; k < n; ++k) {
    triplets.emplace_back(k, k, 1.0);
    triplets.emplace_back(k, n + k, -h);
    triplets.emplace_back(n + k, n + k, m);
  }
  for (int j = 0; j < K.outerSize(); ++j) {
    for (SparseMatrix::InnerIterator it(K, j); it; ++it) {
      triplets.emplace_back(n + it.row(), it.col(), h * it.value());
      triplets.emplace_back(n + it.row(), n + it.col(), h * c * it.value());
    }
  }
  SparseMatrix A(2 * n, 2 * n);
  A.setFromTriplets(triplets.begin(), triplets.end());
  A.makeCompressed();
  SparseMatrix identity(n, n);
  identity.setIdentity();
  *schur = m * identity + (h * c + h * h) * K;
  schur->makeCompressed();
  return A;
}

TEST(UmfpackSolverTest, ZeroFreeDiagonalTakesTheSymmetricStrategyAndItsFill) {
  const SparseMatrix K = cloth_matrix(24, 71);  // 1,728 DOFs
  const double h = 1.0 / 60.0, k = K.coeffs().cwiseAbs().maxCoeff();
  const double m = h * h * k / 700.0, c = 20.0 * m / h;
  SparseMatrix S;
  const SparseMatrix A = implicit_euler_matrix(K, h, m, c, &S);
  UmfpackSolver solver;
  solver.analyze(A);
  EXPECT_NE(solver.factorization_note().find("symmetric strategy"), std::string::npos)
      << solver.factorization_note();
  ASSERT_TRUE(solver.factorize(A));
  const Eigen::VectorXd b = random_vector(A.rows(), 72);
  Eigen::VectorXd x(A.rows());
  solver.solve(b, &x);
  EXPECT_LT(relative_residual(A, x, b), kResidualTolerance);
  // L and U of S's block are each about S's Cholesky factor; UMFPACK counts
  // the diagonal in both, and the identity block adds a few entries per row.
  CholmodSolver cholesky;
  cholesky.analyze(S);
  ASSERT_TRUE(cholesky.factorize(S));
  const long reference = 2 * cholesky.factor_nonzeros() + 3 * A.rows();
  EXPECT_LT(solver.factor_nonzeros(), 1.3 * reference)
      << "L U " << solver.factor_nonzeros() << ", Cholesky of the Schur complement "
      << cholesky.factor_nonzeros();
}

TEST(UmfpackSolverTest, StructuralZerosOnTheDiagonalLeaveTheStrategyToUmfpack) {
  // No diagonal entry at all.
  const SparseMatrix A = swapped_blocks(random_spd(12, 73), false);
  const int n = static_cast<int>(A.rows());
  UmfpackSolver solver;
  solver.analyze(A);
  EXPECT_NE(solver.factorization_note().find("UMFPACK's own strategy"), std::string::npos)
      << solver.factorization_note();
  ASSERT_TRUE(solver.factorize(A));
  const Eigen::VectorXd b = random_vector(n, 74);
  Eigen::VectorXd x(n);
  solver.solve(b, &x);
  EXPECT_LT(relative_residual(A, x, b), kResidualTolerance);
}

TEST(AutoChoiceTest, SmallSystemsGoDense) {
  const SparseMatrix A = random_spd(14, 50);  // n = 196
  LinearSolverChoice symmetric = make_linear_solver(LinearSolverKind::kAuto, A, true);
  EXPECT_EQ(symmetric.solver->method(), "dense-ldlt");
  EXPECT_NE(symmetric.reason.find("n = 196 <= 200"), std::string::npos) << symmetric.reason;
  EXPECT_NE(symmetric.reason.find("dense LDLT"), std::string::npos) << symmetric.reason;
  LinearSolverChoice unsymmetric = make_linear_solver(LinearSolverKind::kAuto, A, false);
  EXPECT_EQ(unsymmetric.solver->method(), "dense-lu");
  EXPECT_NE(unsymmetric.reason.find("unsymmetric"), std::string::npos) << unsymmetric.reason;
}

TEST(AutoChoiceTest, SmallSparseSystemsGoSparseWhenChosenByDensity) {
  // n = 196; 5 n - 4 m = 924 entries, density 924 / 196^2 = 2.41%.
  const SparseMatrix A = random_spd(14, 50);
  LinearSolverChoice symmetric =
      make_linear_solver(LinearSolverKind::kAuto, A, true, SmallSystems::kByDensity);
  EXPECT_EQ(symmetric.solver->method(), "cholmod-llt");
  EXPECT_NE(symmetric.reason.find("n = 196 <= 200 and density 2.41% <= 50%"), std::string::npos)
      << symmetric.reason;
  // Unsymmetric small systems stay dense (UMFPACK's overhead).
  LinearSolverChoice unsymmetric =
      make_linear_solver(LinearSolverKind::kAuto, A, false, SmallSystems::kByDensity);
  EXPECT_EQ(unsymmetric.solver->method(), "dense-lu");
  // Denser than half: dense all the same.
  PatternBuilder builder(60, 60);
  builder.add_block(0, 0, 60, 60);
  const SparseMatrix full_pattern = builder.build();
  LinearSolverChoice full =
      make_linear_solver(LinearSolverKind::kAuto, full_pattern, true, SmallSystems::kByDensity);
  EXPECT_EQ(full.solver->method(), "dense-ldlt");
  EXPECT_NE(full.reason.find("> 50%"), std::string::npos) << full.reason;
}

TEST(AutoChoiceTest, LargeSparseSystemsGoToCholmodOrUmfpack) {
  // n = 1024; 5 n - 4 m = 4992 entries, density 4992 / 1024^2 = 0.476%.
  const SparseMatrix A = random_spd(32, 51);
  LinearSolverChoice symmetric = make_linear_solver(LinearSolverKind::kAuto, A, true);
  EXPECT_EQ(symmetric.solver->method(), "cholmod-llt");
  EXPECT_NE(symmetric.reason.find("n = 1024 > 200"), std::string::npos) << symmetric.reason;
  EXPECT_NE(symmetric.reason.find("density 0.476% <= 10%"), std::string::npos) << symmetric.reason;
  EXPECT_NE(symmetric.reason.find("CHOLMOD"), std::string::npos) << symmetric.reason;
  LinearSolverChoice unsymmetric = make_linear_solver(LinearSolverKind::kAuto, A, false);
  EXPECT_EQ(unsymmetric.solver->method(), "umfpack");
  EXPECT_NE(unsymmetric.reason.find("UMFPACK"), std::string::npos) << unsymmetric.reason;
}

TEST(AutoChoiceTest, DenseLargeSystemsGoDense) {
  PatternBuilder builder(300, 300);
  builder.add_block(0, 0, 100, 300);  // density 1/3
  const SparseMatrix A = builder.build();
  LinearSolverChoice choice = make_linear_solver(LinearSolverKind::kAuto, A, false);
  EXPECT_EQ(choice.solver->method(), "dense-lu");
  EXPECT_NE(choice.reason.find("density 33.3% > 10%"), std::string::npos) << choice.reason;
}

TEST(ExplicitChoiceTest, HonouredAndRejectedForUnsymmetricWhenTheyNeedSymmetry) {
  const SparseMatrix A = random_spd(5, 52);  // small: auto would pick dense
  EXPECT_EQ(make_linear_solver(LinearSolverKind::kUmfpack, A, true).solver->method(), "umfpack");
  EXPECT_EQ(make_linear_solver(LinearSolverKind::kCholmod, A, true).solver->method(),
            "cholmod-llt");
  EXPECT_THROW(make_linear_solver(LinearSolverKind::kCholmod, A, false), std::invalid_argument);
  EXPECT_THROW(make_linear_solver(LinearSolverKind::kDenseLDLT, A, false), std::invalid_argument);
  EXPECT_EQ(make_linear_solver(LinearSolverKind::kDenseLU, A, false).solver->method(), "dense-lu");
}

TEST(LinearSolverKindTest, ParsesEveryNameAndRoundTrips) {
  EXPECT_EQ(parse_linear_solver_kind("dense"), LinearSolverKind::kDenseLU);
  for (LinearSolverKind kind :
       {LinearSolverKind::kAuto, LinearSolverKind::kDenseLU, LinearSolverKind::kDenseLDLT,
        LinearSolverKind::kCholmod, LinearSolverKind::kUmfpack}) {
    EXPECT_EQ(parse_linear_solver_kind(to_string(kind)), kind) << to_string(kind);
  }
  try {
    parse_linear_solver_kind("superlu");
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& error) {
    const std::string message = error.what();
    EXPECT_NE(message.find("superlu"), std::string::npos) << message;
    for (const char* name : {"auto", "dense-lu", "dense-ldlt", "cholmod", "umfpack"}) {
      EXPECT_NE(message.find(name), std::string::npos) << message;
    }
  }
}

}  // namespace
}  // namespace stiffsim
