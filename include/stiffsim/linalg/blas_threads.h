#pragma once
// The number of threads of the BLAS and the OpenMP regions under CHOLMOD.
// OpenBLAS spins its worker threads between calls; for the many small
// supernodal updates of a cloth or rope factorization and the per-iteration
// triangular solves that costs more than it gains on a small machine, so
// stiffsim defaults to one thread.
//
// CHOLMOD (SuiteSparse 5.x) also runs OpenMP regions with
// num_threads(CHOLMOD_OMP_NUM_THREADS), a count fixed when CHOLMOD was built
// (4 on Debian 12), which omp_set_num_threads does not reach. One thread is
// therefore forced by allowing no active parallel level
// (omp_set_max_active_levels(0)): every region then runs on the calling
// thread. With more than one thread, at least one active level is allowed
// again, so CHOLMOD's own loops run with its built-in count, capped by
// OMP_THREAD_LIMIT; only the OpenMP regions that ask for no count follow the
// number given here.
//
// A region that runs on one thread still costs libgomp a team: allocated,
// cleared and ended by a system call. CHOLMOD's supernodal factorization
// opens one for nearly every supernode (2,674 for a 32x32 cloth's matrix),
// so where the calling thread has one thread its regions run as direct
// calls instead (GOMP_parallel, defined in blas_threads.cc and found before
// libgomp's; openmp_regions_run_inline() counts them).
//
// OpenBLAS's count is process-wide, but OpenMP's settings belong to each
// thread: the sparse solvers call apply_blas_threads() in the thread that
// constructs, analyzes or factorizes, which carries the process-wide count
// into that thread.

namespace stiffsim {

// Uses `threads` (>= 1) from now on, in every thread that runs a sparse
// solver; an explicit call always wins over the default. Returns false if
// the loaded BLAS cannot be told (not OpenBLAS); OpenMP is set regardless.
bool set_blas_threads(int threads);

// The first time in the process, unless set_blas_threads was called, applies
// the default of one thread; then makes the calling thread's OpenMP settings
// follow the process-wide count. CholmodSolver and UmfpackSolver call it, so
// every entry point (CLI, tests, benchmarks, reports, bindings) gets one
// thread without asking. Cheap after its first call in a thread.
void apply_blas_threads();

// The process-wide count in effect: the last set_blas_threads argument, 1
// once the default was applied, 0 before either.
int current_blas_threads();
// True once set_blas_threads was called (not only the default applied).
bool blas_threads_set_explicitly();

// CHOLMOD's OpenMP regions that ran as direct calls in threads given one
// thread, since the process started. libgomp runs a one-thread region as a
// team (allocated, cleared and ended by a system call); blas_threads.cc
// defines GOMP_parallel, found before libgomp's, to skip that for CHOLMOD.
long openmp_regions_run_inline();

}  // namespace stiffsim
