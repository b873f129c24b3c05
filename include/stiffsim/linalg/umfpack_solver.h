#pragma once
// Sparse LU (UMFPACK, unsymmetric-pattern multifrontal) for unsymmetric
// iteration matrices, and the last resort of CholmodSolver when even LDL^T
// fails. Symbolic analysis once per pattern (the symmetric strategy where the
// diagonal is zero-free, as every Newton matrix's is), numeric factorization
// per values, solves into preallocated workspace.

#include <umfpack.h>

#include <string>
#include <vector>

#include "stiffsim/linalg/linear_solver.h"

namespace stiffsim {

class UmfpackSolver final : public LinearSolver {
 public:
  UmfpackSolver();
  ~UmfpackSolver() override;
  UmfpackSolver(const UmfpackSolver&) = delete;
  UmfpackSolver& operator=(const UmfpackSolver&) = delete;

  // Throws std::invalid_argument for a non-square pattern and
  // std::runtime_error if UMFPACK's symbolic analysis fails.
  void analyze(const SparseMatrix& pattern) override;
  // Throws std::invalid_argument if A's pattern differs from the analyzed one.
  bool factorize(const SparseMatrix& A) override;
  void solve(const Eigen::VectorXd& b, Eigen::VectorXd* x) override;
  std::string method() const override { return "umfpack"; }
  // lnz + unz from umfpack_di_get_lunz: both count the diagonal, so the n
  // diagonal entries are counted twice (UMFPACK's own convention).
  long factor_nonzeros() const override { return factor_nonzeros_; }

 private:
  void free_numeric();
  void free_symbolic();

  // A private copy of the analyzed pattern, refilled with the values of every
  // factorize(): iterative refinement in solve() needs A, and the caller may
  // already be assembling the next matrix into its own storage.
  SparseMatrix matrix_;
  int n_ = -1;  // -1 until analyze()
  void* symbolic_ = nullptr;
  void* numeric_ = nullptr;
  bool factored_ = false;
  long factor_nonzeros_ = 0;
  double control_[UMFPACK_CONTROL];
  double info_[UMFPACK_INFO];
  // umfpack_di_wsolve workspace: n ints and 5n doubles with refinement.
  std::vector<int> int_workspace_;
  std::vector<double> double_workspace_;
};

}  // namespace stiffsim
