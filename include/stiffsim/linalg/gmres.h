#pragma once
// Right-preconditioned GMRES for the unsymmetric Newton systems of the
// Krylov path (DESIGN.md section 2): A dx = b with A applied, never
// factored, preconditioned by an older factorization.
//
// Our own rather than Eigen's (unsupported) GMRES: that one allocates its
// Krylov basis on every call and takes its preconditioner through a class
// whose solve() returns a new vector; the step allocates nothing. One cycle,
// no restart: a Newton solve that needs more products than the basis holds
// is better served by a fresh factorization (the cost model's business).
// It keeps P^-1 v for every basis vector and builds x from those (flexible
// GMRES), so A Z = V H holds as computed and the residual it reports is
// x's whatever P^-1 did: the preconditioner need not be exactly linear (a
// single-precision solve, LinearSolver::solve_preconditioner).

#include <Eigen/Core>
#include <cmath>
#include <vector>

namespace stiffsim {

struct GmresWorkspace {
  Eigen::MatrixXd basis;           // n x (m + 1): the Arnoldi vectors
  Eigen::MatrixXd preconditioned;  // n x m: P^-1 times each, so x costs no extra solve
  Eigen::MatrixXd hessenberg;      // (m + 1) x m, triangularized in place by Givens rotations
  Eigen::VectorXd cosines, sines, rhs, coefficients, w, z;
  // The current residual, and its coordinates in the basis, where the
  // preconditioner changes (see gmres).
  Eigen::VectorXd residual, residual_coefficients;
  // Grows only: a solve given a smaller budget of products than the last
  // (a stale preconditioner's, see ImplicitIntegrator) allocates nothing.
  void resize(Eigen::Index n, int m) {
    if (basis.rows() == n && basis.cols() >= m + 1) return;
    basis.resize(n, m + 1);
    preconditioned.resize(n, m);
    hessenberg.resize(m + 1, m);
    for (Eigen::VectorXd* v : {&cosines, &sines, &coefficients}) v->resize(m);
    rhs.resize(m + 1);
    residual_coefficients.resize(m + 1);
    w.resize(n);
    z.resize(n);
    residual.resize(n);
  }
};

struct GmresResult {
  int iterations = 0;              // products with A (and preconditioner solves)
  bool converged = false;          // |S (b - A x)| <= tolerance |S b| reached
  double relative_residual = 1.0;  // |S (b - A x)| / |S b| at exit
  bool abandoned = false;          // ended by give_up before max_iterations
  int switched_at = -1;            // products before the preconditioner changed (see gmres)
};

// Solves A x = b from x = 0, minimizing |S (b - A x)|_2 over the Krylov
// space of S A P^-1 (S a diagonal row scaling, `scale`, or the identity when
// empty), until it is at most relative_tolerance |S b| or max_iterations
// products are spent. apply(p, &Ap) computes A p; precondition(r, &z)
// computes z = P^-1 r. Since the scaled residual norm never grows, x is a
// descent direction for 1/2 |S r(x)|^2 at any point whose residual is -b
// and whose Jacobian is A, whenever it reduced that norm at all.
// give_up(iterations, relative_residual), asked after every product that
// left the solve short of its tolerance, may end it early (the result then
// says abandoned), unless switch_preconditioner() (asked then, once) says
// it replaced the preconditioner: the solve then goes on with its basis
// and products kept, the next direction the new preconditioner's solve of
// the current residual (then of the Arnoldi vectors as before). A restart
// would have thrown the products away and begun again from b.
template <class Apply, class Precondition, class GiveUp, class Switch>
GmresResult gmres(const Apply& apply, const Precondition& precondition, const Eigen::VectorXd& b,
                  const Eigen::VectorXd& scale, double relative_tolerance, int max_iterations,
                  GmresWorkspace* ws, Eigen::VectorXd* x, const GiveUp& give_up,
                  const Switch& switch_preconditioner) {
  GmresResult result;
  const Eigen::Index n = b.size();
  x->setZero(n);
  ws->resize(n, max_iterations);
  const bool scaled = scale.size() == n;
  auto& V = ws->basis;
  auto& H = ws->hessenberg;
  if (scaled) {
    V.col(0) = scale.cwiseProduct(b);
  } else {
    V.col(0) = b;
  }
  const double beta = V.col(0).norm();
  if (beta == 0.0 || !std::isfinite(beta)) {
    result.converged = beta == 0.0;
    result.relative_residual = beta == 0.0 ? 0.0 : beta;
    return result;
  }
  V.col(0) /= beta;
  ws->rhs.setZero();
  ws->rhs[0] = beta;
  int k = 0;  // columns of the basis in use beyond the first
  bool residual_next = false;
  while (k < max_iterations) {
    // w = S A P^-1 v_k, orthogonalized against the basis (modified
    // Gram-Schmidt, once more where it lost most of its length).
    if (residual_next) {
      ws->w = ws->residual;
      residual_next = false;
    } else {
      ws->w = V.col(k);
    }
    precondition(ws->w, &ws->z);
    ws->preconditioned.col(k) = ws->z;
    apply(ws->z, &ws->w);
    if (scaled) ws->w.array() *= scale.array();
    ++result.iterations;
    const double before = ws->w.norm();
    for (int i = 0; i <= k; ++i) {
      H(i, k) = V.col(i).dot(ws->w);
      ws->w.noalias() -= H(i, k) * V.col(i);
    }
    double after = ws->w.norm();
    if (after < 0.1 * before) {
      for (int i = 0; i <= k; ++i) {
        const double correction = V.col(i).dot(ws->w);
        H(i, k) += correction;
        ws->w.noalias() -= correction * V.col(i);
      }
      after = ws->w.norm();
    }
    H(k + 1, k) = after;
    // Apply the earlier rotations to the new column, then one that zeroes
    // its subdiagonal entry; rhs[k + 1] is then the residual norm.
    for (int i = 0; i < k; ++i) {
      const double a = H(i, k), c = H(i + 1, k);
      H(i, k) = ws->cosines[i] * a + ws->sines[i] * c;
      H(i + 1, k) = -ws->sines[i] * a + ws->cosines[i] * c;
    }
    const double a = H(k, k), c = H(k + 1, k);
    const double r = std::hypot(a, c);
    ws->cosines[k] = r == 0.0 ? 1.0 : a / r;
    ws->sines[k] = r == 0.0 ? 0.0 : c / r;
    H(k, k) = r;
    H(k + 1, k) = 0.0;
    ws->rhs[k + 1] = -ws->sines[k] * ws->rhs[k];
    ws->rhs[k] = ws->cosines[k] * ws->rhs[k];
    ++k;
    result.relative_residual = std::abs(ws->rhs[k]) / beta;
    if (!std::isfinite(result.relative_residual)) return result;
    if (result.relative_residual <= relative_tolerance) {
      result.converged = true;
      break;
    }
    if (after == 0.0) break;  // the Krylov space is invariant: x is exact
    bool switched = false;
    if (k < max_iterations && result.switched_at < 0 &&
        give_up(result.iterations, result.relative_residual)) {
      if (!switch_preconditioner()) {
        result.abandoned = true;
        break;
      }
      result.switched_at = result.iterations;
      switched = true;
    }
    V.col(k) = ws->w / after;
    if (switched) {
      // The scaled residual S (b - A x) = V_0..k Q^T (0, ..., 0, rhs[k]),
      // Q the product of the rotations (Q H = R): that vector rotated
      // back through them, the last first.
      auto& q = ws->residual_coefficients;
      q.head(k + 1).setZero();
      q[k] = ws->rhs[k];
      for (int i = k - 1; i >= 0; --i) {
        q[i] = -ws->sines[i] * q[i + 1];
        q[i + 1] *= ws->cosines[i];
      }
      ws->residual.noalias() = V.leftCols(k + 1) * q.head(k + 1);
      ws->residual /= ws->residual.norm();
      residual_next = true;
    }
  }
  // y = H^-1 rhs (upper triangular k x k), x = P^-1 V y = Z y.
  for (int i = k - 1; i >= 0; --i) {
    double sum = ws->rhs[i];
    for (int j = i + 1; j < k; ++j) sum -= H(i, j) * ws->coefficients[j];
    ws->coefficients[i] = H(i, i) != 0.0 ? sum / H(i, i) : 0.0;
  }
  x->noalias() = ws->preconditioned.leftCols(k) * ws->coefficients.head(k);
  if (result.relative_residual <= relative_tolerance) result.converged = true;
  return result;
}

template <class Apply, class Precondition, class GiveUp>
GmresResult gmres(const Apply& apply, const Precondition& precondition, const Eigen::VectorXd& b,
                  const Eigen::VectorXd& scale, double relative_tolerance, int max_iterations,
                  GmresWorkspace* ws, Eigen::VectorXd* x, const GiveUp& give_up) {
  return gmres(apply, precondition, b, scale, relative_tolerance, max_iterations, ws, x, give_up,
               [] { return false; });
}
template <class Apply, class Precondition>
GmresResult gmres(const Apply& apply, const Precondition& precondition, const Eigen::VectorXd& b,
                  const Eigen::VectorXd& scale, double relative_tolerance, int max_iterations,
                  GmresWorkspace* ws, Eigen::VectorXd* x) {
  return gmres(apply, precondition, b, scale, relative_tolerance, max_iterations, ws, x,
               [](int, double) { return false; });
}

}  // namespace stiffsim
