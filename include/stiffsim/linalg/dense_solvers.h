#pragma once
// Dense factorizations for small or dense iteration matrices, where the
// bookkeeping of a sparse factorization costs more than the flops it saves.
// Both copy the sparse values into a dense matrix sized once in analyze(), so
// factorize() and solve() allocate nothing for n <= 200; above that, Eigen's
// blocked LU still allocates its matrix-product packing buffers.

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/LU>
#include <string>

#include "stiffsim/linalg/linear_solver.h"

namespace stiffsim {

// LU with partial pivoting (Eigen::PartialPivLU); any nonsingular matrix.
class DenseLUSolver final : public LinearSolver {
 public:
  void analyze(const SparseMatrix& pattern) override;
  bool factorize(const SparseMatrix& A) override;
  void solve(const Eigen::VectorXd& b, Eigen::VectorXd* x) override;
  std::string method() const override { return "dense-lu"; }
  // n * n: L and U share one dense n x n array.
  long factor_nonzeros() const override;

 private:
  Eigen::Index n_ = -1;  // -1 until analyze()
  Eigen::MatrixXd dense_;
  Eigen::PartialPivLU<Eigen::MatrixXd> lu_;
  bool factored_ = false;
};

// LDL^T with symmetric pivoting (Eigen::LDLT); symmetric matrices, positive
// or negative semidefinite in theory, in practice also the mildly indefinite
// iteration matrices of stiff systems. Reads only the lower triangle.
class DenseLDLTSolver final : public LinearSolver {
 public:
  void analyze(const SparseMatrix& pattern) override;
  bool factorize(const SparseMatrix& A) override;
  void solve(const Eigen::VectorXd& b, Eigen::VectorXd* x) override;
  std::string method() const override { return "dense-ldlt"; }
  // n * (n + 1) / 2: the unit lower triangle L with D on its diagonal.
  long factor_nonzeros() const override;

 private:
  Eigen::Index n_ = -1;  // -1 until analyze()
  Eigen::MatrixXd dense_;
  Eigen::LDLT<Eigen::MatrixXd, Eigen::Lower> ldlt_;
  bool factored_ = false;
};

}  // namespace stiffsim
