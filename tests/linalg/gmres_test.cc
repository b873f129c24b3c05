// GMRES (linalg/gmres.h) on small systems with known answers: it converges
// to the requested relative tolerance, and a give_up callback ends a solve
// early with the result marked abandoned and the partial answer the best
// one in the Krylov space so far.

#include "stiffsim/linalg/gmres.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>

namespace stiffsim {
namespace {

// A diagonal operator with eigenvalues 1..n: unpreconditioned GMRES needs
// up to n products (one per distinct eigenvalue), so it cannot finish early
// by itself.
struct Diagonal {
  Eigen::VectorXd d;
  void operator()(const Eigen::VectorXd& p, Eigen::VectorXd* Ap) const { *Ap = d.cwiseProduct(p); }
};

void identity(const Eigen::VectorXd& r, Eigen::VectorXd* z) { *z = r; }

TEST(Gmres, ConvergesToItsTolerance) {
  const int n = 30;
  const Diagonal A{Eigen::VectorXd::LinSpaced(n, 1.0, n)};
  const Eigen::VectorXd b = Eigen::VectorXd::Ones(n);
  GmresWorkspace ws;
  Eigen::VectorXd x;
  const GmresResult result = gmres(A, identity, b, Eigen::VectorXd(), 1e-10, n, &ws, &x);
  EXPECT_TRUE(result.converged);
  EXPECT_FALSE(result.abandoned);
  Eigen::VectorXd Ax;
  A(x, &Ax);
  EXPECT_LE((b - Ax).norm(), 1e-10 * b.norm() * (1 + 1e-6));
  EXPECT_NEAR(result.relative_residual, (b - Ax).norm() / b.norm(), 1e-12);
}

TEST(Gmres, GiveUpEndsTheSolveEarly) {
  const int n = 30;
  const Diagonal A{Eigen::VectorXd::LinSpaced(n, 1.0, n)};
  const Eigen::VectorXd b = Eigen::VectorXd::Ones(n);
  GmresWorkspace ws;
  Eigen::VectorXd x;
  int asked = 0;
  auto give_up = [&](int iterations, double relative_residual) {
    ++asked;
    EXPECT_EQ(iterations, asked);
    EXPECT_GT(relative_residual, 1e-10);
    return iterations == 4;
  };
  const GmresResult result = gmres(A, identity, b, Eigen::VectorXd(), 1e-10, n, &ws, &x, give_up);
  EXPECT_TRUE(result.abandoned);
  EXPECT_FALSE(result.converged);
  EXPECT_EQ(result.iterations, 4);
  EXPECT_EQ(asked, 4);
  // The partial answer minimizes the residual over the four-dimensional
  // Krylov space: its residual is the one reported, below |b| and above
  // the tolerance.
  Eigen::VectorXd Ax;
  A(x, &Ax);
  const double relative = (b - Ax).norm() / b.norm();
  EXPECT_NEAR(result.relative_residual, relative, 1e-12);
  EXPECT_LT(relative, 1.0);
  EXPECT_GT(relative, 1e-3);
  // A later, larger solve in the same workspace and then a smaller one
  // reuse its storage (it only grows).
  const double* storage = ws.basis.data();
  gmres(A, identity, b, Eigen::VectorXd(), 1e-10, n / 2, &ws, &x);
  EXPECT_EQ(ws.basis.data(), storage);
}

}  // namespace
}  // namespace stiffsim
