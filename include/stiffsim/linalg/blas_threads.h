#pragma once
// The number of threads the BLAS under CHOLMOD uses. OpenBLAS spins its
// worker threads between calls; for the many small supernodal updates of a
// cloth or rope factorization and the per-iteration triangular solves that
// costs more than it gains on a small machine, so stiffsim defaults to one.

namespace stiffsim {

// Returns false if the loaded BLAS cannot be told (not OpenBLAS).
bool set_blas_threads(int threads);

}  // namespace stiffsim
