#include "stiffsim/linalg/blas_threads.h"

#include <algorithm>
#include <atomic>
#include <mutex>

// Weak: resolved only when the BLAS behind libblas.so.3 is OpenBLAS, so the
// reference BLAS still links and runs.
extern "C" void openblas_set_num_threads(int) __attribute__((weak));
// Weak as well: resolved when an OpenMP runtime is loaded (libgomp, through
// CHOLMOD), so stiffsim still links and runs without one.
extern "C" void omp_set_num_threads(int) __attribute__((weak));
extern "C" void omp_set_max_active_levels(int) __attribute__((weak));
extern "C" int omp_get_max_active_levels() __attribute__((weak));

namespace stiffsim {
namespace {

constexpr int kDefaultThreads = 1;

std::mutex process_mutex;             // orders the process-wide writes below
std::atomic<int> process_threads{0};  // 0: neither set nor defaulted yet
std::atomic<bool> set_explicitly{false};
// The count this thread's OpenMP settings were last given; 0 for none.
thread_local int thread_openmp_threads = 0;

bool apply_openblas(int threads) {
  if (openblas_set_num_threads == nullptr) return false;
  openblas_set_num_threads(threads);
  return true;
}

void apply_openmp(int threads) {
  thread_openmp_threads = threads;
  if (omp_set_max_active_levels != nullptr) {
    // libgomp runs a region on one thread when the current active level
    // reaches max-active-levels, whatever its num_threads clause says.
    const int levels = omp_get_max_active_levels != nullptr ? omp_get_max_active_levels() : 0;
    omp_set_max_active_levels(threads == 1 ? 0 : std::max(levels, 1));
  }
  if (omp_set_num_threads != nullptr) omp_set_num_threads(threads);
}

}  // namespace

bool set_blas_threads(int threads) {
  threads = std::max(threads, 1);
  bool told;
  {
    const std::lock_guard<std::mutex> lock(process_mutex);
    told = apply_openblas(threads);
    set_explicitly = true;
    process_threads = threads;
  }
  apply_openmp(threads);
  return told;
}

void apply_blas_threads() {
  int threads = process_threads.load();
  if (threads == 0) {
    const std::lock_guard<std::mutex> lock(process_mutex);
    if (process_threads.load() == 0) {
      apply_openblas(kDefaultThreads);
      process_threads = kDefaultThreads;
    }
    threads = process_threads.load();
  }
  if (thread_openmp_threads != threads) apply_openmp(threads);
}

int current_blas_threads() { return process_threads.load(); }

bool blas_threads_set_explicitly() { return set_explicitly.load(); }

}  // namespace stiffsim
