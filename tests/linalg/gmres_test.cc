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

// A preconditioner that is a fixed function of its argument but not linear
// in it (the exact inverse rounded to single precision, as a float copy of
// a factor gives): GMRES keeps P^-1 v for each basis vector, so the
// residual it reports is still that of its answer, and the solve converges
// near the exact preconditioner's one product.
TEST(Gmres, ReportsTheTrueResidualUnderASinglePrecisionPreconditioner) {
  const int n = 30;
  const Diagonal A{Eigen::VectorXd::LinSpaced(n, 1.0, 1e4)};
  const Eigen::VectorXd b = Eigen::VectorXd::LinSpaced(n, -1.0, 2.0);
  auto single_inverse = [&](const Eigen::VectorXd& r, Eigen::VectorXd* z) {
    *z = (r.cast<float>().array() / A.d.cast<float>().array()).cast<double>().matrix();
  };
  GmresWorkspace ws;
  Eigen::VectorXd x;
  const GmresResult result = gmres(A, single_inverse, b, Eigen::VectorXd(), 1e-12, n, &ws, &x);
  EXPECT_TRUE(result.converged);
  EXPECT_LE(result.iterations, 3);
  Eigen::VectorXd Ax;
  A(x, &Ax);
  const double relative = (b - Ax).norm() / b.norm();
  EXPECT_LE(relative, 1e-12 * (1 + 1e-3));
  EXPECT_NEAR(result.relative_residual, relative, 1e-14);
  // One product alone leaves the float's rounding, not the tolerance.
  const GmresResult one = gmres(A, single_inverse, b, Eigen::VectorXd(), 1e-12, 1, &ws, &x);
  EXPECT_FALSE(one.converged);
  EXPECT_GT(one.relative_residual, 1e-10);
  EXPECT_LT(one.relative_residual, 1e-6);
}

}  // namespace
}  // namespace stiffsim
