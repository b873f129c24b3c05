#include "stiffsim/linalg/float_kernels.h"

#include <Eigen/Dense>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define STIFFSIM_AVX2 __attribute__((target("avx2,fma")))
#endif

namespace stiffsim {
namespace {

namespace eigen {

using Block = Eigen::Map<const Eigen::MatrixXf, 0, Eigen::OuterStride<>>;
using Vector = Eigen::Map<Eigen::VectorXf>;
using ConstVector = Eigen::Map<const Eigen::VectorXf>;

// Column by column: the diagonal holds reciprocals, which Eigen's
// triangular solves do not take.
void lower_solve(int n, int ld, const float* L, float* y) {
  for (int j = 0; j < n; ++j) {
    const float* column = L + static_cast<long>(j) * ld;
    y[j] *= column[j];
    Vector(y + j + 1, n - j - 1) -= y[j] * ConstVector(column + j + 1, n - j - 1);
  }
}
void lower_transpose_solve(int n, int ld, const float* L, float* y) {
  for (int j = n - 1; j >= 0; --j) {
    const float* column = L + static_cast<long>(j) * ld;
    y[j] = (y[j] - ConstVector(column + j + 1, n - j - 1).dot(ConstVector(y + j + 1, n - j - 1))) *
           column[j];
  }
}
void product(int m, int n, int ld, const float* A, const float* x, float* y) {
  Vector(y, m).noalias() = Block(A, m, n, Eigen::OuterStride<>(ld)) * ConstVector(x, n);
}
void transpose_product_subtract(int m, int n, int ld, const float* A, const float* x, float* y) {
  Vector(y, n).noalias() -=
      Block(A, m, n, Eigen::OuterStride<>(ld)).transpose() * ConstVector(x, m);
}

}  // namespace eigen

#if defined(__x86_64__) && defined(__GNUC__)
namespace avx2 {

STIFFSIM_AVX2 float horizontal_sum(__m256 v) {
  const __m128 halves = _mm_add_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps(v, 1));
  const __m128 pairs = _mm_add_ps(halves, _mm_movehl_ps(halves, halves));
  return _mm_cvtss_f32(_mm_add_ss(pairs, _mm_shuffle_ps(pairs, pairs, 1)));
}

// y[0..n) += a x[0..n)
STIFFSIM_AVX2 void axpy(int n, float a, const float* x, float* y) {
  const __m256 av = _mm256_set1_ps(a);
  int i = 0;
  for (; i + 8 <= n; i += 8) {
    _mm256_storeu_ps(y + i, _mm256_fmadd_ps(av, _mm256_loadu_ps(x + i), _mm256_loadu_ps(y + i)));
  }
  for (; i < n; ++i) y[i] += a * x[i];
}

// sum over [0, n) of x[i] y[i]
STIFFSIM_AVX2 float dot(int n, const float* x, const float* y) {
  __m256 acc = _mm256_setzero_ps();
  int i = 0;
  for (; i + 8 <= n; i += 8) {
    acc = _mm256_fmadd_ps(_mm256_loadu_ps(x + i), _mm256_loadu_ps(y + i), acc);
  }
  float sum = horizontal_sum(acc);
  for (; i < n; ++i) sum += x[i] * y[i];
  return sum;
}

// The four columns of a block from A on (leading dimension ld).
struct FourColumns {
  const float *c0, *c1, *c2, *c3;
};
FourColumns four_columns(const float* A, int ld) { return {A, A + ld, A + 2 * ld, A + 3 * ld}; }

// y[0..m) += A w for the m x 4 block A (the four columns from A on,
// leading dimension ld): four FMAs per load and store of y.
STIFFSIM_AVX2 void add_four_columns(int m, int ld, const float* A, const float* w, float* y) {
  const auto [a0, a1, a2, a3] = four_columns(A, ld);
  const __m256 w0 = _mm256_set1_ps(w[0]), w1 = _mm256_set1_ps(w[1]);
  const __m256 w2 = _mm256_set1_ps(w[2]), w3 = _mm256_set1_ps(w[3]);
  int i = 0;
  for (; i + 8 <= m; i += 8) {
    __m256 v = _mm256_loadu_ps(y + i);
    v = _mm256_fmadd_ps(w0, _mm256_loadu_ps(a0 + i), v);
    v = _mm256_fmadd_ps(w1, _mm256_loadu_ps(a1 + i), v);
    v = _mm256_fmadd_ps(w2, _mm256_loadu_ps(a2 + i), v);
    v = _mm256_fmadd_ps(w3, _mm256_loadu_ps(a3 + i), v);
    _mm256_storeu_ps(y + i, v);
  }
  for (; i < m; ++i) y[i] += w[0] * a0[i] + w[1] * a1[i] + w[2] * a2[i] + w[3] * a3[i];
}

STIFFSIM_AVX2 void product(int m, int n, int ld, const float* A, const float* x, float* y) {
  for (int i = 0; i < m; ++i) y[i] = 0.0f;
  int j = 0;
  for (; j + 4 <= n; j += 4) add_four_columns(m, ld, A + static_cast<long>(j) * ld, x + j, y);
  for (; j < n; ++j) axpy(m, x[j], A + static_cast<long>(j) * ld, y);
}

STIFFSIM_AVX2 void transpose_product_subtract(int m, int n, int ld, const float* A, const float* x,
                                              float* y) {
  // Four columns at a time, sharing each load of x.
  int j = 0;
  for (; j + 4 <= n; j += 4) {
    const auto [a0, a1, a2, a3] = four_columns(A + static_cast<long>(j) * ld, ld);
    __m256 s0 = _mm256_setzero_ps(), s1 = _mm256_setzero_ps();
    __m256 s2 = _mm256_setzero_ps(), s3 = _mm256_setzero_ps();
    int i = 0;
    for (; i + 8 <= m; i += 8) {
      const __m256 xv = _mm256_loadu_ps(x + i);
      s0 = _mm256_fmadd_ps(_mm256_loadu_ps(a0 + i), xv, s0);
      s1 = _mm256_fmadd_ps(_mm256_loadu_ps(a1 + i), xv, s1);
      s2 = _mm256_fmadd_ps(_mm256_loadu_ps(a2 + i), xv, s2);
      s3 = _mm256_fmadd_ps(_mm256_loadu_ps(a3 + i), xv, s3);
    }
    float t0 = horizontal_sum(s0), t1 = horizontal_sum(s1);
    float t2 = horizontal_sum(s2), t3 = horizontal_sum(s3);
    for (; i < m; ++i) {
      t0 += a0[i] * x[i];
      t1 += a1[i] * x[i];
      t2 += a2[i] * x[i];
      t3 += a3[i] * x[i];
    }
    y[j] -= t0;
    y[j + 1] -= t1;
    y[j + 2] -= t2;
    y[j + 3] -= t3;
  }
  for (; j < n; ++j) y[j] -= dot(m, A + static_cast<long>(j) * ld, x);
}

// The triangles go four columns at a time: a 4 x 4 triangle solved in
// scalars, then one pass over the rest of the four columns. Column by
// column they were a chain of short vector operations, each waiting on the
// last, and took 27% of a solve's samples on the 100x100 sheet. The
// diagonal holds reciprocals: the 4 x 4 triangles' chains of dependent
// divisions held most of these two kernels' samples.
STIFFSIM_AVX2 void lower_solve(int n, int ld, const float* L, float* y) {
  int j = 0;
  for (; j + 4 <= n; j += 4) {
    const auto [c0, c1, c2, c3] = four_columns(L + static_cast<long>(j) * ld, ld);
    y[j] *= c0[j];
    y[j + 1] = (y[j + 1] - c0[j + 1] * y[j]) * c1[j + 1];
    y[j + 2] = (y[j + 2] - c0[j + 2] * y[j] - c1[j + 2] * y[j + 1]) * c2[j + 2];
    y[j + 3] =
        (y[j + 3] - c0[j + 3] * y[j] - c1[j + 3] * y[j + 1] - c2[j + 3] * y[j + 2]) * c3[j + 3];
    const float w[4] = {-y[j], -y[j + 1], -y[j + 2], -y[j + 3]};
    add_four_columns(n - j - 4, ld, c0 + j + 4, w, y + j + 4);
  }
  for (; j < n; ++j) {
    const float* column = L + static_cast<long>(j) * ld;
    y[j] *= column[j];
    axpy(n - j - 1, -y[j], column + j + 1, y + j + 1);
  }
}

STIFFSIM_AVX2 void lower_transpose_solve(int n, int ld, const float* L, float* y) {
  // The last n % 4 columns first (they need only the entries after them),
  // then four at a time towards the first.
  const int blocked = n - n % 4;
  for (int j = n - 1; j >= blocked; --j) {
    const float* column = L + static_cast<long>(j) * ld;
    y[j] = (y[j] - dot(n - j - 1, column + j + 1, y + j + 1)) * column[j];
  }
  for (int j = blocked - 4; j >= 0; j -= 4) {
    const auto [c0, c1, c2, c3] = four_columns(L + static_cast<long>(j) * ld, ld);
    transpose_product_subtract(n - j - 4, 4, ld, c0 + j + 4, y + j + 4, y + j);
    y[j + 3] *= c3[j + 3];
    y[j + 2] = (y[j + 2] - c2[j + 3] * y[j + 3]) * c2[j + 2];
    y[j + 1] = (y[j + 1] - c1[j + 2] * y[j + 2] - c1[j + 3] * y[j + 3]) * c1[j + 1];
    y[j] = (y[j] - c0[j + 1] * y[j + 1] - c0[j + 2] * y[j + 2] - c0[j + 3] * y[j + 3]) * c0[j];
  }
}

}  // namespace avx2

#endif

}  // namespace

const FloatSweepKernels& eigen_float_sweep_kernels() {
  static const FloatSweepKernels kernels{eigen::lower_solve, eigen::lower_transpose_solve,
                                         eigen::product, eigen::transpose_product_subtract};
  return kernels;
}

const FloatSweepKernels* avx2_float_sweep_kernels() {
#if defined(__x86_64__) && defined(__GNUC__)
  static const FloatSweepKernels kernels{avx2::lower_solve, avx2::lower_transpose_solve,
                                         avx2::product, avx2::transpose_product_subtract};
  // libgcc's checks include the OS's support for the AVX state (XGETBV).
  __builtin_cpu_init();
  if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) return &kernels;
#endif
  return nullptr;
}

const FloatSweepKernels& float_sweep_kernels() {
  static const FloatSweepKernels& chosen = []() -> const FloatSweepKernels& {
    const FloatSweepKernels* avx2 = avx2_float_sweep_kernels();
    return avx2 != nullptr ? *avx2 : eigen_float_sweep_kernels();
  }();
  return chosen;
}

}  // namespace stiffsim
