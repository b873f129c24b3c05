#pragma once

// Single-precision kernels for the triangular sweeps of the float
// preconditioner solve (CholmodSolver::solve_preconditioner): the four
// operations on a supernode's block, column-major with leading dimension
// ld, as CHOLMOD stores it. Two sets: AVX2 with FMA, eight lanes wide,
// where the CPU and the OS support them, and Eigen's elsewhere, four lanes
// wide in the build's baseline SSE2. The sweeps call whichever
// float_sweep_kernels() chose once, with no branch of their own.

namespace stiffsim {

struct FloatSweepKernels {
  // y = L^-1 y for the n x n lower triangle of L, whose diagonal holds the
  // reciprocals 1 / L_jj (a multiplication instead of a division in each
  // step's chain; CholmodSolver writes them).
  void (*lower_solve)(int n, int ld, const float* L, float* y);
  // y = L^-T y for the n x n lower triangle of L, reciprocal diagonal as
  // above.
  void (*lower_transpose_solve)(int n, int ld, const float* L, float* y);
  // y = A x for the m x n block A.
  void (*product)(int m, int n, int ld, const float* A, const float* x, float* y);
  // y -= A^T x for the m x n block A (y has n entries, x has m).
  void (*transpose_product_subtract)(int m, int n, int ld, const float* A, const float* x,
                                     float* y);
};

// The AVX2 set where this CPU may run it, Eigen's otherwise.
const FloatSweepKernels& float_sweep_kernels();
// Eigen's set, on every CPU.
const FloatSweepKernels& eigen_float_sweep_kernels();
// The AVX2 set, or nullptr where the CPU or the OS lacks AVX2 with FMA (and
// off x86-64).
const FloatSweepKernels* avx2_float_sweep_kernels();

}  // namespace stiffsim
