#pragma once

// A supernodal Cholesky factorization L L^T = A in single precision, on
// the symbolic analysis CHOLMOD made for A (its supernodes, their row
// lists and the layout of their dense blocks). The factor is laid out as
// CHOLMOD lays out a supernodal factor's values, so the float sweeps of
// CholmodSolver::solve_preconditioner apply it as they apply a float copy
// of CHOLMOD's double factor.
//
// Why: a preconditioner's factor needs no more than float's precision
// (the float sweeps already apply one), and single-precision BLAS does
// twice the flops per cycle of double. The numeric phase is CHOLMOD's
// left-looking supernodal algorithm (t_cholmod_super_numeric): each
// supernode gathers the updates of the supernodes below it that touch its
// columns (SYRK and GEMM), then factors its diagonal block (POTRF) and
// solves the rows below (TRSM). (Small updates summed in place instead of
// by BLAS were no faster: BM_FactorizePreconditioner/32 1.88-2.06 ms
// either way.)

#include <cholmod.h>

#include <vector>

namespace stiffsim {

class FloatCholesky {
 public:
  // Keeps a copy of the symbolic structure of a supernodal factor (is_super;
  // analyzed in the natural ordering, so that A's rows are L's) and
  // allocates the workspaces, once. Throws std::invalid_argument for a
  // simplicial factor.
  void analyze(const cholmod_factor& symbolic);
  bool analyzed() const { return n_ >= 0; }
  // Factors A, given by its lower triangle in column form (rows sorted,
  // each column's rows at or below its diagonal), of the analyzed pattern,
  // into L (L->xsize entries, CHOLMOD's supernodal layout). False where a
  // pivot is not positive and finite, or the ratio of the smallest to the
  // largest squared pivot is at most n times double's epsilon (the
  // LinearSolver's "numerically singular"); L is then garbage.
  bool factorize(const int* outer, const int* inner, const double* values, float* L);

 private:
  int n_ = -1, nsuper_ = 0;
  std::vector<int> super_, pi_, px_, rows_;
  std::vector<int> super_of_;  // column -> its supernode
  // Workspace of the numeric phase: each row's place in the current
  // supernode, the lists of supernodes waiting to update each supernode
  // (head, next), and where each waiting supernode's next rows start.
  std::vector<int> map_, head_, next_, position_;
  std::vector<float> update_;
};

}  // namespace stiffsim
