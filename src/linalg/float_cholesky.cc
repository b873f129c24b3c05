#include "stiffsim/linalg/float_cholesky.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

// Single-precision BLAS and LAPACK (the same library CHOLMOD calls in
// double).
extern "C" {
void ssyrk_(const char* uplo, const char* trans, const int* n, const int* k, const float* alpha,
            const float* a, const int* lda, const float* beta, float* c, const int* ldc);
void sgemm_(const char* transa, const char* transb, const int* m, const int* n, const int* k,
            const float* alpha, const float* a, const int* lda, const float* b, const int* ldb,
            const float* beta, float* c, const int* ldc);
void spotrf_(const char* uplo, const int* n, float* a, const int* lda, int* info);
void strsm_(const char* side, const char* uplo, const char* transa, const char* diag, const int* m,
            const int* n, const float* alpha, const float* a, const int* lda, float* b,
            const int* ldb);
}

namespace stiffsim {

void FloatCholesky::analyze(const cholmod_factor& symbolic) {
  if (!symbolic.is_super) {
    throw std::invalid_argument("FloatCholesky::analyze: the factor is not supernodal");
  }
  n_ = static_cast<int>(symbolic.n);
  nsuper_ = static_cast<int>(symbolic.nsuper);
  const int* super = static_cast<const int*>(symbolic.super);
  const int* pi = static_cast<const int*>(symbolic.pi);
  const int* px = static_cast<const int*>(symbolic.px);
  const int* rows = static_cast<const int*>(symbolic.s);
  super_.assign(super, super + nsuper_ + 1);
  pi_.assign(pi, pi + nsuper_ + 1);
  px_.assign(px, px + nsuper_ + 1);
  rows_.assign(rows, rows + pi_[nsuper_]);
  super_of_.resize(n_);
  for (int s = 0; s < nsuper_; ++s) {
    std::fill(super_of_.begin() + super_[s], super_of_.begin() + super_[s + 1], s);
  }
  map_.assign(n_, 0);
  head_.assign(nsuper_, -1);
  next_.assign(nsuper_, -1);
  position_.assign(nsuper_, 0);
  update_.assign(std::max<std::size_t>(symbolic.maxcsize, 1), 0.0f);
}

bool FloatCholesky::factorize(const int* outer, const int* inner, const double* values, float* L) {
  if (n_ < 0) throw std::logic_error("FloatCholesky::factorize called before analyze");
  std::fill(head_.begin(), head_.end(), -1);
  float* C = update_.data();
  const char lower = 'L', no = 'N', transposed = 'T', right = 'R';
  const float one = 1.0f, zero = 0.0f;
  float smallest = std::numeric_limits<float>::infinity(), largest = 0.0f;
  for (int s = 0; s < nsuper_; ++s) {
    const int k1 = super_[s], k2 = super_[s + 1], ncol = k2 - k1;
    const int first = pi_[s], nrow = pi_[s + 1] - first;
    float* Ls = L + px_[s];
    for (int k = 0; k < nrow; ++k) map_[rows_[first + k]] = k;
    // A's columns, in the zeroed block (supernodes hold explicit zeros).
    std::fill(Ls, Ls + static_cast<long>(nrow) * ncol, 0.0f);
    for (int j = k1; j < k2; ++j) {
      float* column = Ls + static_cast<long>(j - k1) * nrow;
      for (int p = outer[j]; p < outer[j + 1]; ++p) {
        column[map_[inner[p]]] = static_cast<float>(values[p]);
      }
    }
    // The updates of each supernode d below whose rows reach columns k1..k2.
    for (int d = head_[s]; d != -1;) {
      const int d_next = next_[d];
      const int ndcol = super_[d + 1] - super_[d];
      const int d_first = pi_[d], ndrow = pi_[d + 1] - d_first;
      const int start = position_[d];  // d's first row in s's columns
      const int* d_rows = rows_.data() + d_first + start;
      int in_columns = 0;  // d's rows in s's columns
      while (start + in_columns < ndrow && d_rows[in_columns] < k2) ++in_columns;
      const int reach = ndrow - start;  // d's rows from there on
      const float* Ld = L + px_[d] + start;
      // C = Ld(rows from start) Ld(rows in s's columns)^T: its top
      // square's lower triangle by SYRK, the rows below by GEMM.
      ssyrk_(&lower, &no, &in_columns, &ndcol, &one, Ld, &ndrow, &zero, C, &reach);
      const int below = reach - in_columns;
      if (below > 0) {
        sgemm_(&no, &transposed, &below, &in_columns, &ndcol, &one, Ld + in_columns, &ndrow, Ld,
               &ndrow, &zero, C + in_columns, &reach);
      }
      for (int j = 0; j < in_columns; ++j) {
        float* column = Ls + static_cast<long>(d_rows[j] - k1) * nrow;
        const float* c = C + static_cast<long>(j) * reach;
        for (int i = j; i < reach; ++i) column[map_[d_rows[i]]] -= c[i];
      }
      // d waits next for the supernode of its first row past s's columns.
      position_[d] = start + in_columns;
      if (position_[d] < ndrow) {
        const int ancestor = super_of_[rows_[d_first + position_[d]]];
        next_[d] = head_[ancestor];
        head_[ancestor] = d;
      }
      d = d_next;
    }
    int info = 0;
    spotrf_(&lower, &ncol, Ls, &nrow, &info);
    if (info != 0) return false;
    for (int k = 0; k < ncol; ++k) {
      const float pivot = Ls[k + static_cast<long>(k) * nrow];
      if (!std::isfinite(pivot)) return false;
      smallest = std::min(smallest, pivot * pivot);
      largest = std::max(largest, pivot * pivot);
    }
    const int below = nrow - ncol;
    if (below > 0) {
      strsm_(&right, &lower, &transposed, &no, &below, &ncol, &one, Ls, &nrow, Ls + ncol, &nrow);
      position_[s] = ncol;
      const int ancestor = super_of_[rows_[first + ncol]];
      next_[s] = head_[ancestor];
      head_[ancestor] = s;
    }
  }
  // Singular as LinearSolver defines it (as double would find it): float's
  // own n epsilon would call W singular at the condition of a stiff
  // cloth (the float solves' residual check is what judges float).
  return smallest > n_ * std::numeric_limits<double>::epsilon() * largest;
}

}  // namespace stiffsim
