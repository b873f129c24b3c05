#include "stiffsim/linalg/blas_threads.h"

// Weak: resolved only when the BLAS behind libblas.so.3 is OpenBLAS, so the
// reference BLAS still links and runs.
extern "C" void openblas_set_num_threads(int) __attribute__((weak));
// CHOLMOD's supernodal numeric factorization also runs OpenMP regions.
extern "C" void omp_set_num_threads(int) __attribute__((weak));

namespace stiffsim {

bool set_blas_threads(int threads) {
  if (omp_set_num_threads != nullptr) omp_set_num_threads(threads);
  if (openblas_set_num_threads == nullptr) return false;
  openblas_set_num_threads(threads);
  return true;
}

}  // namespace stiffsim
