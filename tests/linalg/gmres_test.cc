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

// Where give_up asks for it and switch_preconditioner() replaces the
// preconditioner (here the identity by the exact inverse), the solve goes
// on with the products made, and the new preconditioner's first input is
// the current residual S (b - A x): checked against the residual of the
// same solve abandoned at that point (the same Krylov space, the same x),
// on a row-scaled system as on an unscaled one. With the exact inverse one
// more product then ends the solve.
TEST(Gmres, SwitchedPreconditionerSolvesTheCurrentResidual) {
  const int n = 30;
  const Diagonal A{Eigen::VectorXd::LinSpaced(n, 1.0, n)};
  const Eigen::VectorXd b = Eigen::VectorXd::LinSpaced(n, 1.0, 2.0);
  const Eigen::VectorXd scaled = Eigen::VectorXd::LinSpaced(n, 0.5, 3.0);
  for (const Eigen::VectorXd& scale : {Eigen::VectorXd(), scaled}) {
    auto give_up = [](int iterations, double) { return iterations == 4; };
    GmresWorkspace ws;
    Eigen::VectorXd x;
    gmres(A, identity, b, scale, 1e-10, n, &ws, &x, give_up);
    Eigen::VectorXd residual;
    A(x, &residual);
    residual = b - residual;
    if (scale.size() == n) residual = residual.cwiseProduct(scale);
    residual.normalize();

    bool exact = false;
    Eigen::VectorXd first_input;
    auto precondition = [&](const Eigen::VectorXd& r, Eigen::VectorXd* z) {
      if (!exact) {
        *z = r;
        return;
      }
      if (first_input.size() == 0) first_input = r;
      // S A z = r: z = A^-1 S^-1 r.
      *z = scale.size() == n ? r.cwiseQuotient(scale) : r;
      *z = z->cwiseQuotient(A.d);
    };
    int switches = 0;
    auto switch_preconditioner = [&] {
      ++switches;
      exact = true;
      return true;
    };
    const GmresResult result =
        gmres(A, precondition, b, scale, 1e-10, n, &ws, &x, give_up, switch_preconditioner);
    EXPECT_EQ(switches, 1);
    EXPECT_EQ(result.switched_at, 4);
    EXPECT_FALSE(result.abandoned);
    EXPECT_TRUE(result.converged);
    EXPECT_EQ(result.iterations, 5);
    ASSERT_EQ(first_input.size(), n);
    EXPECT_NEAR(std::abs(first_input.normalized().dot(residual)), 1.0, 1e-10);
    Eigen::VectorXd Ax;
    A(x, &Ax);
    EXPECT_LE((b - Ax).norm(), 1e-9 * b.norm());
  }
}

// A switch that fails (the new factorization could not be made) abandons
// the solve as give_up alone does.
TEST(Gmres, FailedSwitchAbandonsTheSolve) {
  const int n = 30;
  const Diagonal A{Eigen::VectorXd::LinSpaced(n, 1.0, n)};
  const Eigen::VectorXd b = Eigen::VectorXd::Ones(n);
  GmresWorkspace ws;
  Eigen::VectorXd x;
  const GmresResult result = gmres(
      A, identity, b, Eigen::VectorXd(), 1e-10, n, &ws, &x,
      [](int iterations, double) { return iterations == 3; }, [] { return false; });
  EXPECT_TRUE(result.abandoned);
  EXPECT_EQ(result.switched_at, -1);
  EXPECT_EQ(result.iterations, 3);
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
