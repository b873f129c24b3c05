// Both sets of float kernels of the preconditioner's sweeps (AVX2 where
// the CPU has it, and Eigen's) against the same operations in double, on blocks of every size
// around the kernels' steps (four columns, eight rows) and with a leading dimension beyond the
// rows, as a supernode of CHOLMOD's has. The sweeps as a whole are tested through
// CholmodSolver::solve_preconditioner (linear_solver_test).

#include "stiffsim/linalg/float_kernels.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace stiffsim {
namespace {

struct Block {
  int rows, cols, ld;
  std::vector<float> values;  // column-major, ld >= rows
  double at(int i, int j) const { return values[static_cast<size_t>(j) * ld + i]; }
};

// A random block with a dominant diagonal (where rows == cols, a
// well-conditioned lower triangle), padded below its rows by 3 NaNs: a
// kernel that reads past a column's rows returns NaN.
Block random_block(int rows, int cols, std::mt19937* rng) {
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  Block b{rows, cols, rows + 3, {}};
  b.values.resize(static_cast<size_t>(b.ld) * std::max(cols, 1));
  for (size_t k = 0; k < b.values.size(); ++k) {
    b.values[k] = static_cast<int>(k % b.ld) < rows ? u(*rng) : std::nanf("");
  }
  for (int j = 0; j < std::min(rows, cols); ++j)
    b.values[static_cast<size_t>(j) * b.ld + j] += 4.0f;
  return b;
}

std::vector<float> random_vector(int n, std::mt19937* rng) {
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::vector<float> v(n);
  for (float& x : v) x = u(*rng);
  return v;
}

// |a - b| / |b| in the infinity norm (b in double); infinite where a has
// a NaN.
double relative_error(const std::vector<float>& a, const Eigen::VectorXd& b) {
  double diff = 0.0;
  for (int i = 0; i < b.size(); ++i) {
    if (!std::isfinite(a[i])) return std::numeric_limits<double>::infinity();
    diff = std::max(diff, std::abs(a[i] - b[i]));
  }
  return b.size() == 0 ? 0.0 : diff / std::max(b.lpNorm<Eigen::Infinity>(), 1e-30);
}

Eigen::MatrixXd dense(const Block& b) {
  Eigen::MatrixXd m(b.rows, b.cols);
  for (int j = 0; j < b.cols; ++j) {
    for (int i = 0; i < b.rows; ++i) m(i, j) = b.at(i, j);
  }
  return m;
}

Eigen::VectorXd to_double(const std::vector<float>& v) {
  return Eigen::Map<const Eigen::VectorXf>(v.data(), static_cast<Eigen::Index>(v.size()))
      .cast<double>();
}

// Float's rounding over sums of up to ~40 terms of unit size, with the
// triangles' error growth: the kernels agree with double to a few float
// epsilons (1.2e-7); an indexing error shows as O(1).
constexpr double kFloatTolerance = 2e-5;

// Parameter: the kernel set, "avx2" or "eigen".
class FloatKernels : public ::testing::TestWithParam<const char*> {
 protected:
  void SetUp() override {
    if (std::string(GetParam()) == "eigen") {
      kernels_ = &eigen_float_sweep_kernels();
    } else {
      kernels_ = avx2_float_sweep_kernels();
      if (kernels_ == nullptr) GTEST_SKIP() << "no AVX2 with FMA on this CPU";
    }
  }
  const FloatSweepKernels* kernels_ = nullptr;
  std::mt19937 rng_{20261128};
};

TEST_P(FloatKernels, TrianglesSolveAsInDouble) {
  for (int n = 0; n <= 21; ++n) {
    const Block L = random_block(n, n, &rng_);
    const std::vector<float> b = random_vector(n, &rng_);
    const Eigen::MatrixXd Ld = dense(L);
    // The kernels take the diagonal's reciprocals (float_kernels.h).
    Block reciprocal = L;
    for (int j = 0; j < n; ++j) {
      float& d = reciprocal.values[static_cast<size_t>(j) * L.ld + j];
      d = 1.0f / d;
    }
    std::vector<float> y = b;
    kernels_->lower_solve(n, L.ld, reciprocal.values.data(), y.data());
    const Eigen::VectorXd expected = Ld.triangularView<Eigen::Lower>().solve(to_double(b));
    EXPECT_LT(relative_error(y, expected), kFloatTolerance) << "n = " << n;
    y = b;
    kernels_->lower_transpose_solve(n, L.ld, reciprocal.values.data(), y.data());
    const Eigen::VectorXd expected_t =
        Ld.triangularView<Eigen::Lower>().transpose().solve(to_double(b));
    EXPECT_LT(relative_error(y, expected_t), kFloatTolerance) << "n = " << n;
  }
}

TEST_P(FloatKernels, ProductsAsInDouble) {
  for (int m = 0; m <= 19; ++m) {
    for (int n = 0; n <= 9; ++n) {
      const Block A = random_block(m, n, &rng_);
      const Eigen::MatrixXd Ad = dense(A);
      const std::vector<float> x = random_vector(n, &rng_);
      // m entries overwritten, then 8 that must stay (no store past y's end)
      std::vector<float> y(m + 8, 7.0f);
      kernels_->product(m, n, A.ld, A.values.data(), x.data(), y.data());
      EXPECT_LT(relative_error(y, Ad * to_double(x)), kFloatTolerance) << m << " x " << n;
      EXPECT_EQ(std::count(y.begin() + m, y.end(), 7.0f), 8) << m << " x " << n;
      const std::vector<float> xt = random_vector(m, &rng_);
      const std::vector<float> y0 = random_vector(n, &rng_);
      std::vector<float> yt = y0;
      kernels_->transpose_product_subtract(m, n, A.ld, A.values.data(), xt.data(), yt.data());
      const Eigen::VectorXd expected = to_double(y0) - Ad.transpose() * to_double(xt);
      EXPECT_LT(relative_error(yt, expected), kFloatTolerance) << m << " x " << n;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Sets, FloatKernels, ::testing::Values("avx2", "eigen"));

}  // namespace
}  // namespace stiffsim
