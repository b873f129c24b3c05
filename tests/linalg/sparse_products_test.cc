#include "stiffsim/linalg/sparse_products.h"

#include <gtest/gtest.h>

#include <random>
#include <stdexcept>
#include <vector>

namespace stiffsim {
namespace {

// A random sparse matrix with columns of 0 to 9 entries, so every
// remainder of the four partial sums (and empty columns) occurs.
SparseMatrix random_matrix(int rows, int cols, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> value(-1.0, 1.0);
  std::uniform_int_distribution<int> row(0, rows - 1), count(0, 9);
  std::vector<Eigen::Triplet<double>> triplets;
  for (int j = 0; j < cols; ++j) {
    const int entries = count(rng);
    for (int k = 0; k < entries; ++k) triplets.emplace_back(row(rng), j, value(rng));
  }
  SparseMatrix A(rows, cols);
  A.setFromTriplets(triplets.begin(), triplets.end());
  A.makeCompressed();
  return A;
}

TEST(SparseProductsTest, TransposeProductEqualsEigensProduct) {
  const SparseMatrix A = random_matrix(57, 43, 1);
  const Eigen::VectorXd x = Eigen::VectorXd::LinSpaced(57, -2.0, 3.0);
  Eigen::VectorXd y;
  transpose_product(A, x, &y);
  const Eigen::VectorXd expected = A.transpose() * x;
  ASSERT_EQ(y.size(), 43);
  // Only the order of the additions differs: a few ulps of the entries'
  // magnitudes (at most 9 terms of size <= 3).
  EXPECT_LE((y - expected).lpNorm<Eigen::Infinity>(), 1e-14);
}

TEST(SparseProductsTest, QuadraticFormEqualsDotOfProduct) {
  const SparseMatrix A = random_matrix(60, 60, 2);
  const Eigen::VectorXd x = Eigen::VectorXd::LinSpaced(60, 1.0, -1.5);
  const double expected = x.dot(A * x);
  EXPECT_NEAR(quadratic_form(A, x), expected, 1e-13 * (1.0 + std::abs(expected)));
  // On a segment of a longer vector, as the integrators pass it.
  Eigen::VectorXd longer(70);
  longer.setZero();
  longer.segment(10, 60) = x;
  EXPECT_NEAR(quadratic_form(A, longer.segment(10, 60)), expected,
              1e-13 * (1.0 + std::abs(expected)));
}

TEST(SparseProductsTest, SymmetricQuadraticFormReadsHalfOfASymmetricMatrix) {
  // A + A^T holds both triangles; some columns have no diagonal entry, some
  // nothing below it.
  const SparseMatrix B = random_matrix(40, 40, 4);
  SparseMatrix A = SparseMatrix(B.transpose()) + B;
  A.makeCompressed();
  const Eigen::VectorXd x = Eigen::VectorXd::LinSpaced(40, -1.0, 2.0);
  const double expected = x.dot(A * x);
  EXPECT_NEAR(symmetric_quadratic_form(A, x), expected, 1e-13 * (1.0 + std::abs(expected)));
  // It reads the lower triangle only: an unsymmetric matrix gives the
  // form of its lower triangle mirrored, not x^T B x.
  const SparseMatrix L = B.triangularView<Eigen::Lower>();
  const SparseMatrix mirrored =
      SparseMatrix(L.transpose()) + SparseMatrix(L) -
      SparseMatrix(B.diagonal().asDiagonal().toDenseMatrix().sparseView());
  EXPECT_NEAR(symmetric_quadratic_form(B, x), x.dot(mirrored * x),
              1e-13 * (1.0 + std::abs(expected)));
}

TEST(SparseProductsTest, RejectsMismatchedSizesAndUncompressedMatrices) {
  SparseMatrix A = random_matrix(10, 8, 3);
  Eigen::VectorXd y;
  EXPECT_THROW(transpose_product(A, Eigen::VectorXd::Ones(9), &y), std::invalid_argument);
  EXPECT_THROW(quadratic_form(A, Eigen::VectorXd::Ones(10)), std::invalid_argument);
  A.uncompress();
  EXPECT_FALSE(A.isCompressed());
  EXPECT_THROW(transpose_product(A, Eigen::VectorXd::Ones(10), &y), std::invalid_argument);
}

}  // namespace
}  // namespace stiffsim
