#pragma once
// OpenBLAS's kernels for the CPU. OpenBLAS as Debian builds it
// (DYNAMIC_ARCH) picks its kernels when it loads, by the CPU's model. A
// release older than the CPU does not know the model and falls back to its
// generic x86-64 kernels, Prescott's (SSE3, two doubles per instruction):
// Debian 12's OpenBLAS 0.3.21 does so on Intel's family 6 model 207 (a Xeon
// with AVX-512), where CHOLMOD's supernodal factorization spends its time in
// dgemm (BM_Factorize/100: 184 ms with Prescott's kernels, 139 ms with
// SkylakeX's). choose_blas_kernels() then picks by the instruction sets the
// CPU and the OS support instead: SkylakeX's for AVX-512 (F, DQ, BW, VL),
// Haswell's for AVX2 with FMA, Sandybridge's for AVX. It sets
// OPENBLAS_CORETYPE, which OpenBLAS's own initialization reads, runs that
// initialization again and restores the environment. Nothing changes where
// OpenBLAS knew the CPU, where the user set OPENBLAS_CORETYPE, or where the
// BLAS is not OpenBLAS.

#include <string>

namespace stiffsim {

// Once per process, before the first BLAS call: the sparse solvers call it
// through apply_blas_threads() and set_blas_threads(). Not while another
// thread of the process is inside the BLAS (the kernels change under it).
void choose_blas_kernels();

// The kernels in use, for the stats: "OpenBLAS Haswell" (OpenBLAS's own
// choice), "OpenBLAS SkylakeX, chosen for AVX-512 (OpenBLAS's own choice:
// Prescott, ...)" (replaced), or "" before the call or where the BLAS is not
// OpenBLAS.
std::string blas_kernels_note();

// OpenBLAS's name for the kernels in use now ("SkylakeX", "Prescott"), or ""
// where the BLAS is not OpenBLAS.
std::string blas_kernels_in_use();

}  // namespace stiffsim
