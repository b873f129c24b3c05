#pragma once

// Single-precision kernels for the triangular sweeps of the float
// preconditioner solve (CholmodSolver::solve_preconditioner), in AVX2 with
// FMA. The build targets baseline x86-64, where Eigen's float products run
// four lanes wide (SSE); these run eight, chosen at run time where the CPU
// and the OS support them (avx2_float_kernels_available()). Matrices are
// column-major blocks with leading dimension ld, as CHOLMOD stores a
// supernode.

namespace stiffsim {

// Whether the kernels below may run on this CPU (AVX2 and FMA, with the
// OS saving the AVX state). Always false off x86-64.
bool avx2_float_kernels_available();

namespace avx2 {

// y = L^-1 y for the n x n lower triangle of L.
void lower_solve(int n, int ld, const float* L, float* y);
// y = L^-T y for the n x n lower triangle of L.
void lower_transpose_solve(int n, int ld, const float* L, float* y);
// y = A x for the m x n block A.
void product(int m, int n, int ld, const float* A, const float* x, float* y);
// y -= A^T x for the m x n block A (y has n entries, x has m).
void transpose_product_subtract(int m, int n, int ld, const float* A, const float* x, float* y);

}  // namespace avx2
}  // namespace stiffsim
