#include "stiffsim/model/spring_batch.h"

#include <algorithm>
#include <cmath>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define STIFFSIM_AVX2 __attribute__((target("avx2,fma")))
#endif

namespace stiffsim {
namespace {

// One spring's force on its node a, f_a (spring_batch.h).
inline void spring_force(const double* xa, const double* xb, const double* va, const double* vb,
                         double rest, double k, double c, double* f) {
  const double d[3] = {xb[0] - xa[0], xb[1] - xa[1], xb[2] - xa[2]};
  const double l = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  const double inverse = l > kCollapsedSpringLength ? 1.0 / l : 0.0;
  const double rate = (vb[0] - va[0]) * d[0] + (vb[1] - va[1]) * d[1] + (vb[2] - va[2]) * d[2];
  const double s = (k * (l - rest) + c * rate * inverse) * inverse;
  for (int r = 0; r < 3; ++r) f[r] = s * d[r];
}

void add_springs(int from, int to, const int* a, const int* b, const double* rest, const double* k,
                 const double* c, const double* q, const double* v, double* F) {
  for (int i = from; i < to; ++i) {
    double f[3];
    spring_force(q + a[i], q + b[i], v + a[i], v + b[i], rest[i], k[i], c[i], f);
    for (int r = 0; r < 3; ++r) {
      F[a[i] + r] += f[r];
      F[b[i] + r] -= f[r];
    }
  }
}

#if defined(__x86_64__) && defined(__GNUC__)
// p[0..3) and a zero (mask three: the first three lanes).
STIFFSIM_AVX2 inline __m256d load3(__m256i three, const double* p) {
  return _mm256_maskload_pd(p, three);
}

// p[0..3) += x[0..3).
STIFFSIM_AVX2 inline void add3(__m256d x, double* p) {
  _mm_storeu_pd(p, _mm_add_pd(_mm_loadu_pd(p), _mm256_castpd256_pd128(x)));
  p[2] += _mm_cvtsd_f64(_mm256_extractf128_pd(x, 1));
}

// t[r] = (x[0][r], x[1][r], x[2][r], x[3][r]) for r < 3.
STIFFSIM_AVX2 inline void transpose(const __m256d* x, __m256d* t) {
  const __m256d lo01 = _mm256_unpacklo_pd(x[0], x[1]), hi01 = _mm256_unpackhi_pd(x[0], x[1]);
  const __m256d lo23 = _mm256_unpacklo_pd(x[2], x[3]), hi23 = _mm256_unpackhi_pd(x[2], x[3]);
  t[0] = _mm256_permute2f128_pd(lo01, lo23, 0x20);
  t[1] = _mm256_permute2f128_pd(hi01, hi23, 0x20);
  t[2] = _mm256_permute2f128_pd(lo01, lo23, 0x31);
}

// Four springs per step: each spring's difference vectors d and v_b - v_a
// loaded whole (three coordinates and a masked fourth), the four turned
// into lanes for one square root and one division, the forces turned back
// and added spring by spring in order (two springs of the four may share a
// node). The force on node a is summed over the springs in a row that
// share it (SpringBatch orders them so) and added to F once.
STIFFSIM_AVX2 void add_springs_avx2(int n, const int* a, const int* b, const double* rest,
                                    const double* k, const double* c, const double* q,
                                    const double* v, double* F) {
  const __m256d collapsed = _mm256_set1_pd(kCollapsedSpringLength);
  const __m256d one = _mm256_set1_pd(1.0);
  const __m256i three = _mm256_set_epi64x(0, -1, -1, -1);
  int current = n > 0 ? a[0] : 0;
  __m256d sum = _mm256_setzero_pd();
  int i = 0;
  for (; i + 4 <= n; i += 4) {
    __m256d d[4], w[4];
    for (int j = 0; j < 4; ++j) {
      d[j] = _mm256_sub_pd(load3(three, q + b[i + j]), load3(three, q + a[i + j]));
      w[j] = _mm256_sub_pd(load3(three, v + b[i + j]), load3(three, v + a[i + j]));
    }
    // Lanes: dd[r] holds coordinate r of the four springs' d, ww likewise.
    __m256d dd[3], ww[3];
    transpose(d, dd);
    transpose(w, ww);
    __m256d l2 = _mm256_mul_pd(dd[0], dd[0]);
    l2 = _mm256_fmadd_pd(dd[1], dd[1], l2);
    l2 = _mm256_fmadd_pd(dd[2], dd[2], l2);
    const __m256d l = _mm256_sqrt_pd(l2);
    // 1 / l where l > kCollapsedSpringLength, 0 elsewhere (and where l is
    // NaN: the force is then NaN, as force() gives).
    const __m256d inverse =
        _mm256_and_pd(_mm256_cmp_pd(l, collapsed, _CMP_GT_OQ), _mm256_div_pd(one, l));
    __m256d rate = _mm256_mul_pd(ww[0], dd[0]);
    rate = _mm256_fmadd_pd(ww[1], dd[1], rate);
    rate = _mm256_fmadd_pd(ww[2], dd[2], rate);
    const __m256d damping = _mm256_mul_pd(_mm256_loadu_pd(c + i), _mm256_mul_pd(rate, inverse));
    const __m256d stretch = _mm256_sub_pd(l, _mm256_loadu_pd(rest + i));
    alignas(32) double s[4];
    _mm256_store_pd(
        s, _mm256_mul_pd(_mm256_fmadd_pd(_mm256_loadu_pd(k + i), stretch, damping), inverse));
    for (int j = 0; j < 4; ++j) {
      const __m256d f = _mm256_mul_pd(_mm256_set1_pd(s[j]), d[j]);
      if (a[i + j] != current) {
        add3(sum, F + current);
        current = a[i + j];
        sum = _mm256_setzero_pd();
      }
      sum = _mm256_add_pd(sum, f);
      add3(_mm256_sub_pd(_mm256_setzero_pd(), f), F + b[i + j]);
    }
  }
  add3(sum, F + current);
  add_springs(i, n, a, b, rest, k, c, q, v, F);
}

bool cpu_has_avx2() {
  // libgcc's checks include the OS's support for the AVX state (XGETBV).
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
}
#endif

}  // namespace

SpringBatch::SpringBatch(const std::vector<SpringElement>& elements,
                         const std::vector<int>& dof_of_node) {
  for (const SpringElement& e : elements) {
    const auto [a, b] = e.nodes();
    if (dof_of_node[a] < 0 || dof_of_node[b] < 0) continue;
    a_.push_back(dof_of_node[std::min(a, b)]);
    b_.push_back(dof_of_node[std::max(a, b)]);
    rest_.push_back(e.spring().rest_length);
    k_.push_back(e.spring().k);
    c_.push_back(e.spring().c);
  }
}

void SpringBatch::add_forces(const double* q, const double* v, double* F) const {
#if defined(__x86_64__) && defined(__GNUC__)
  static const bool avx2 = cpu_has_avx2();
  if (avx2) {
    add_springs_avx2(size(), a_.data(), b_.data(), rest_.data(), k_.data(), c_.data(), q, v, F);
    return;
  }
#endif
  add_forces_portable(q, v, F);
}

void SpringBatch::add_forces_portable(const double* q, const double* v, double* F) const {
  add_springs(0, size(), a_.data(), b_.data(), rest_.data(), k_.data(), c_.data(), q, v, F);
}

}  // namespace stiffsim
