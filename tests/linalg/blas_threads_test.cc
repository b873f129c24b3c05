#include "stiffsim/linalg/blas_threads.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <thread>

#include "stiffsim/linalg/cholmod_solver.h"
#include "stiffsim/linalg/umfpack_solver.h"

// libgomp, loaded through CHOLMOD; weak so that the test still links (and
// skips) without it. GOMP_parallel is what GCC compiles
// `#pragma omp parallel num_threads(n)` into, as in CHOLMOD's own regions.
extern "C" int omp_get_max_active_levels() __attribute__((weak));
extern "C" int omp_get_max_threads() __attribute__((weak));
extern "C" int omp_get_num_threads() __attribute__((weak));
extern "C" void GOMP_parallel(void (*)(void*), void*, unsigned, unsigned) __attribute__((weak));

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

}  // namespace
}  // namespace stiffsim
