#pragma once
// Products of a compressed column-major sparse matrix read column by column:
// each column gives one dot product with x, summed in independent partial
// sums. Eigen's A^T x sums each column in one chain of dependent additions,
// one entry per addition's latency (four cycles); the refined solves' products
// with W spent 85% of their time in that chain on cloth_stiff.yaml.

#include <Eigen/Core>

#include "stiffsim/linalg/sparse_pattern.h"

namespace stiffsim {

// y = A^T x (for a symmetric A, A x). A must be compressed; y is resized
// to A's columns.
void transpose_product(const SparseMatrix& A, const Eigen::Ref<const Eigen::VectorXd>& x,
                       Eigen::VectorXd* y);

// x^T A x.
double quadratic_form(const SparseMatrix& A, const Eigen::Ref<const Eigen::VectorXd>& x);

// x^T A x for a symmetric A with both triangles stored and each column's
// rows sorted: the diagonal and twice the strict lower triangle, half the
// entries read.
double symmetric_quadratic_form(const SparseMatrix& A, const Eigen::Ref<const Eigen::VectorXd>& x);

}  // namespace stiffsim
