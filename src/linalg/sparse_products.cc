#include "stiffsim/linalg/sparse_products.h"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace stiffsim {
namespace {

// The dot product of column j of A with x, in four partial sums.
inline double column_dot(const int* inner, const double* value, int begin, int end,
                         const double* x) {
  double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
  int k = begin;
  for (; k + 4 <= end; k += 4) {
    s0 += value[k] * x[inner[k]];
    s1 += value[k + 1] * x[inner[k + 1]];
    s2 += value[k + 2] * x[inner[k + 2]];
    s3 += value[k + 3] * x[inner[k + 3]];
  }
  for (; k < end; ++k) s0 += value[k] * x[inner[k]];
  return (s0 + s1) + (s2 + s3);
}

// square: the quadratic forms need A square as well.
void check(const SparseMatrix& A, const Eigen::Ref<const Eigen::VectorXd>& x, const char* caller,
           bool square) {
  if (!A.isCompressed() || x.size() != A.rows() || (square && A.cols() != A.rows())) {
    throw std::invalid_argument(std::string(caller) + ": needs a compressed" +
                                (square ? " square" : "") + " matrix and a vector of its rows");
  }
}

}  // namespace

void transpose_product(const SparseMatrix& A, const Eigen::Ref<const Eigen::VectorXd>& x,
                       Eigen::VectorXd* y) {
  check(A, x, "transpose_product", false);
  const int n = static_cast<int>(A.cols());
  if (y->size() != n) y->resize(n);
  const int* outer = A.outerIndexPtr();
  const int* inner = A.innerIndexPtr();
  const double* value = A.valuePtr();
  for (int j = 0; j < n; ++j) (*y)[j] = column_dot(inner, value, outer[j], outer[j + 1], x.data());
}

double quadratic_form(const SparseMatrix& A, const Eigen::Ref<const Eigen::VectorXd>& x) {
  check(A, x, "quadratic_form", true);
  const int n = static_cast<int>(A.cols());
  const int* outer = A.outerIndexPtr();
  const int* inner = A.innerIndexPtr();
  const double* value = A.valuePtr();
  double sum = 0.0;
  for (int j = 0; j < n; ++j)
    sum += x[j] * column_dot(inner, value, outer[j], outer[j + 1], x.data());
  return sum;
}

double symmetric_quadratic_form(const SparseMatrix& A, const Eigen::Ref<const Eigen::VectorXd>& x) {
  check(A, x, "symmetric_quadratic_form", true);
  const int n = static_cast<int>(A.cols());
  const int* outer = A.outerIndexPtr();
  const int* inner = A.innerIndexPtr();
  const double* value = A.valuePtr();
  double diagonal = 0.0, lower = 0.0;
  for (int j = 0; j < n; ++j) {
    // The column's entries on and below the diagonal are its last ones.
    int below =
        static_cast<int>(std::lower_bound(inner + outer[j], inner + outer[j + 1], j) - inner);
    if (below < outer[j + 1] && inner[below] == j) diagonal += value[below++] * x[j] * x[j];
    lower += x[j] * column_dot(inner, value, below, outer[j + 1], x.data());
  }
  return diagonal + 2.0 * lower;
}

}  // namespace stiffsim
