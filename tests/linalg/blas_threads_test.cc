#include "stiffsim/linalg/blas_threads.h"

#include <dlfcn.h>
#include <gtest/gtest.h>
#include <strings.h>
#include <sys/resource.h>

#include <Eigen/SparseCore>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

#include "stiffsim/linalg/blas_kernels.h"
#include "stiffsim/linalg/cholmod_solver.h"
#include "stiffsim/linalg/umfpack_solver.h"

// libgomp, loaded through CHOLMOD; weak so that the test still links (and
// skips) without it. GOMP_parallel is what GCC compiles
// `#pragma omp parallel num_threads(n)` into, as in CHOLMOD's own regions.
extern "C" int omp_get_max_active_levels() __attribute__((weak));
extern "C" int omp_get_max_threads() __attribute__((weak));
extern "C" int omp_get_num_threads() __attribute__((weak));
extern "C" void GOMP_parallel(void (*)(void*), void*, unsigned, unsigned) __attribute__((weak));
// OpenBLAS's thread count, weak so that the test still links (and skips)
// with another BLAS.
extern "C" int openblas_get_num_threads() __attribute__((weak));

namespace stiffsim {
namespace {

bool have_libgomp() {
  return omp_get_max_active_levels != nullptr && omp_get_max_threads != nullptr &&
         omp_get_num_threads != nullptr && GOMP_parallel != nullptr;
}

// OMP_THREAD_LIMIT=1 alone would also give one thread (the old workaround).
bool thread_limit_set() { return std::getenv("OMP_THREAD_LIMIT") != nullptr; }

// The team size of a region that asks for 4 threads, as CHOLMOD's do
// (CHOLMOD_OMP_NUM_THREADS is 4 in Debian's SuiteSparse 5).
int team_size_of_region_asking_for_four() {
  int team = 0;
  GOMP_parallel(
      [](void* data) {
        // Every member writes the same value.
        *static_cast<int*>(data) = omp_get_num_threads();
      },
      &team, 4, 0);
  return team;
}

// The matrix of a 32x32 cloth's springs (stretch, shear, bend) with three
// dofs per node, plus the unit mass: SPD, and supernodal in CHOLMOD.
Eigen::SparseMatrix<double> cloth_like_matrix() {
  constexpr int m = 32;
  std::vector<Eigen::Triplet<double>> entries;
  auto couple = [&](int a, int b, double k) {
    for (int d = 0; d < 3; ++d) {
      entries.emplace_back(3 * a + d, 3 * a + d, k);
      entries.emplace_back(3 * b + d, 3 * b + d, k);
      entries.emplace_back(3 * a + d, 3 * b + d, -k);
      entries.emplace_back(3 * b + d, 3 * a + d, -k);
    }
  };
  for (int y = 0; y < m; ++y) {
    for (int x = 0; x < m; ++x) {
      const int n = y * m + x;
      for (int d = 0; d < 3; ++d) entries.emplace_back(3 * n + d, 3 * n + d, 1.0);
      if (x + 1 < m) couple(n, n + 1, 700.0);
      if (y + 1 < m) couple(n, n + m, 700.0);
      if (x + 1 < m && y + 1 < m) couple(n, n + m + 1, 70.0);
      if (x > 0 && y + 1 < m) couple(n, n + m - 1, 70.0);
      if (x + 2 < m) couple(n, n + 2, 7.0);
      if (y + 2 < m) couple(n, n + 2 * m, 7.0);
    }
  }
  Eigen::SparseMatrix<double> A(3 * m * m, 3 * m * m);
  A.setFromTriplets(entries.begin(), entries.end());
  return A;
}

// Factors A with `threads` and returns A^-1 b for b = (1, 2, 3, ...).
Eigen::VectorXd solve_with(const Eigen::SparseMatrix<double>& A, int threads) {
  set_blas_threads(threads);
  CholmodSolver solver;
  solver.analyze(A);
  EXPECT_EQ(solver.method(), "cholmod-supernodal-llt");
  EXPECT_TRUE(solver.factorize(A));
  const Eigen::VectorXd b = Eigen::VectorXd::LinSpaced(A.rows(), 1.0, A.rows());
  Eigen::VectorXd x(A.rows());
  solver.solve(b, &x);
  return x;
}

// Run in a fresh process (the threadsafe death-test style re-executes the
// binary), so that no earlier test has set the count.
TEST(BlasThreadsTest, FirstSparseSolverAppliesOneThreadWhenNothingWasSet) {
  if (!have_libgomp()) GTEST_SKIP() << "no libgomp loaded";
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_EXIT(
      {
        int failures = 0;
        auto check = [&failures](bool ok, const char* what) {
          if (ok) return;
          std::fprintf(stderr, "failed: %s\n", what);
          ++failures;
        };
        check(current_blas_threads() == 0, "nothing set before the first solver");
        check(thread_limit_set() || team_size_of_region_asking_for_four() > 1,
              "OpenMP starts multi-threaded");
        { CholmodSolver solver; }
        check(current_blas_threads() == 1, "the first solver applies one thread");
        check(!blas_threads_set_explicitly(), "the default is not an explicit call");
        check(omp_get_max_active_levels() == 0, "no active parallel level");
        check(team_size_of_region_asking_for_four() == 1, "a 4-thread region runs on one");
        std::exit(failures);
      },
      testing::ExitedWithCode(0), "");
}

TEST(BlasThreadsTest, OneThreadAllowsNoActiveLevelAndMoreRestoresOne) {
  if (!have_libgomp()) GTEST_SKIP() << "no libgomp loaded";
  set_blas_threads(1);
  EXPECT_EQ(current_blas_threads(), 1);
  EXPECT_TRUE(blas_threads_set_explicitly());
  EXPECT_EQ(omp_get_max_active_levels(), 0);
  EXPECT_EQ(omp_get_max_threads(), 1);
  EXPECT_EQ(team_size_of_region_asking_for_four(), 1);

  set_blas_threads(2);
  EXPECT_GE(omp_get_max_active_levels(), 1);
  EXPECT_EQ(omp_get_max_threads(), 2);
  // The region's own clause decides again (up to OMP_THREAD_LIMIT).
  if (!thread_limit_set()) {
    EXPECT_GT(team_size_of_region_asking_for_four(), 1);
  }
  set_blas_threads(1);
}

double process_cpu_seconds() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_utime.tv_sec + 1e-6 * usage.ru_utime.tv_usec + usage.ru_stime.tv_sec +
         1e-6 * usage.ru_stime.tv_usec;
}

// One thread leaves no BLAS thread running: OpenBLAS's server threads,
// which spin for about 0.1 s after each job before they sleep, are shut
// down. After a threaded product on two threads, the process then uses
// almost no CPU while it sleeps 0.3 s (with the pool kept at one thread:
// 0.1-0.15 s measured here).
TEST(BlasThreadsTest, OneThreadLeavesNoBlasThreadSpinning) {
  if (openblas_get_num_threads == nullptr) GTEST_SKIP() << "the BLAS is not OpenBLAS";
  if (std::thread::hardware_concurrency() < 2) GTEST_SKIP() << "one core: no BLAS threads";
  // The BLAS behind CHOLMOD, which the test does not link itself.
  using Dgemm = void (*)(const char*, const char*, const int*, const int*, const int*,
                         const double*, const double*, const int*, const double*, const int*,
                         const double*, double*, const int*);
  const auto dgemm_ = reinterpret_cast<Dgemm>(dlsym(RTLD_DEFAULT, "dgemm_"));
  ASSERT_NE(dgemm_, nullptr);
  set_blas_threads(2);
  const int n = 400;
  std::vector<double> a(n * n, 1.0), c(n * n, 0.0);
  const double one = 1.0, zero = 0.0;
  dgemm_("N", "N", &n, &n, &n, &one, a.data(), &n, a.data(), &n, &zero, c.data(), &n);
  EXPECT_EQ(c[0], n);
  set_blas_threads(1);
  EXPECT_EQ(openblas_get_num_threads(), 1);
  const double before = process_cpu_seconds();
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_LT(process_cpu_seconds() - before, 0.03);
  // Products on one thread still work without the pool.
  dgemm_("N", "N", &n, &n, &n, &one, a.data(), &n, a.data(), &n, &zero, c.data(), &n);
  EXPECT_EQ(c[n * n - 1], n);
}

TEST(BlasThreadsTest, AnExplicitCountWinsOverTheDefault) {
  if (!have_libgomp()) GTEST_SKIP() << "no libgomp loaded";
  set_blas_threads(2);
  { UmfpackSolver solver; }
  { CholmodSolver solver; }
  EXPECT_EQ(current_blas_threads(), 2);
  EXPECT_EQ(omp_get_max_threads(), 2);
  EXPECT_GE(omp_get_max_active_levels(), 1);
  set_blas_threads(1);
}

// CHOLMOD's supernodal factorization opens an OpenMP region for nearly
// every supernode; with one thread they run as direct calls
// (GOMP_parallel in blas_threads.cc), with two through libgomp, and the
// factor is the same. A region this test opens itself goes to libgomp
// either way (its team: OneThreadAllowsNoActiveLevelAndMoreRestoresOne).
TEST(BlasThreadsTest, CholmodsRegionsRunInlineOnOneThread) {
  if (!have_libgomp()) GTEST_SKIP() << "no libgomp loaded";
  const Eigen::SparseMatrix<double> A = cloth_like_matrix();
  const long before = openmp_regions_run_inline();
  const Eigen::VectorXd inline_x = solve_with(A, 1);
  const long after_one = openmp_regions_run_inline();
  // Measured: 2,674 regions in the analysis and one factorization.
  EXPECT_GT(after_one - before, 100);
  const Eigen::VectorXd team_x = solve_with(A, 2);
  EXPECT_EQ(openmp_regions_run_inline(), after_one);
  set_blas_threads(1);
  team_size_of_region_asking_for_four();
  EXPECT_EQ(openmp_regions_run_inline(), after_one);
  EXPECT_LT((inline_x - team_x).norm(), 1e-12 * team_x.norm());
}

// OpenMP's settings belong to each thread: a thread started after
// set_blas_threads(1) begins with the runtime's defaults, and a solver built
// there carries the process-wide count into it.
TEST(BlasThreadsTest, ASolverInAnotherThreadFollowsTheProcessWideCount) {
  if (!have_libgomp()) GTEST_SKIP() << "no libgomp loaded";
  set_blas_threads(1);
  int levels_before = -1, levels_after = -1, team_after = -1;
  std::thread worker([&] {
    levels_before = omp_get_max_active_levels();
    CholmodSolver solver;
    levels_after = omp_get_max_active_levels();
    team_after = team_size_of_region_asking_for_four();
  });
  worker.join();
  EXPECT_GE(levels_before, 1) << "a new thread starts from the runtime's defaults";
  EXPECT_EQ(levels_after, 0);
  EXPECT_EQ(team_after, 1);
}

// OpenBLAS's kernels (linalg/blas_kernels.h): on a CPU with AVX2, the first
// sparse solver of a process leaves OpenBLAS on kernels of at least that
// width, never its SSE3 fallback for a CPU it does not know (Prescott), and
// a factorization on them solves as before; a user's OPENBLAS_CORETYPE is
// kept. Each test runs in a fresh process (the threadsafe death-test style
// re-executes the binary with this environment), where OpenBLAS chose its
// kernels as it loaded.
bool have_openblas() {
  CholmodSolver solver;  // the first solver makes the choice
  return !blas_kernels_in_use().empty();
}

bool cpu_has_avx2() {
#if defined(__x86_64__)
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
#else
  return false;
#endif
}

TEST(BlasKernelsTest, FirstSolverLeavesKernelsAsWideAsTheCpuAndSolves) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  unsetenv("OPENBLAS_CORETYPE");
  EXPECT_EXIT(
      {
        int failures = 0;
        auto check = [&failures](bool ok, const std::string& what) {
          if (ok) return;
          std::fprintf(stderr, "failed: %s\n", what.c_str());
          ++failures;
        };
        if (!have_openblas()) std::exit(0);
        const std::string kernels = blas_kernels_in_use();
        const std::string note = blas_kernels_note();
        check(note.rfind("OpenBLAS " + kernels, 0) == 0, "the note names the kernels: " + note);
        if (cpu_has_avx2()) {
          check(strcasecmp(kernels.c_str(), "Prescott") != 0, "not the SSE3 fallback: " + note);
        }
        check(std::getenv("OPENBLAS_CORETYPE") == nullptr, "the environment is restored");
        const Eigen::SparseMatrix<double> A = cloth_like_matrix();
        CholmodSolver solver;
        solver.analyze(A);
        check(solver.method() == "cholmod-supernodal-llt", "supernodal: " + solver.method());
        check(solver.factorize(A), "factorized");
        const Eigen::VectorXd b = Eigen::VectorXd::LinSpaced(A.rows(), -1.0, 2.0);
        Eigen::VectorXd x(A.rows());
        solver.solve(b, &x);
        check((A * x - b).norm() <= 1e-12 * b.norm(), "solved to round-off");
        std::exit(failures);
      },
      testing::ExitedWithCode(0), "");
}

TEST(BlasKernelsTest, UsersCoretypeIsKept) {
  if (!cpu_has_avx2()) GTEST_SKIP() << "Haswell's kernels need AVX2";
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  setenv("OPENBLAS_CORETYPE", "Haswell", 1);
  EXPECT_EXIT(
      {
        if (!have_openblas()) std::exit(0);
        const bool kept = blas_kernels_in_use() == "Haswell" &&
                          blas_kernels_note() == "OpenBLAS Haswell" &&
                          std::getenv("OPENBLAS_CORETYPE") != nullptr;
        if (!kept) std::fprintf(stderr, "failed: %s\n", blas_kernels_note().c_str());
        std::exit(kept ? 0 : 1);
      },
      testing::ExitedWithCode(0), "");
  unsetenv("OPENBLAS_CORETYPE");
}

}  // namespace
}  // namespace stiffsim
