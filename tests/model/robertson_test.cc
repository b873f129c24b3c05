// Claims about the Robertson kinetics system: its analytic Jacobian is the
// derivative of its right-hand side, and it conserves y1 + y2 + y3.

#include "stiffsim/model/robertson.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "stiffsim/error.h"

namespace stiffsim {
namespace {

Eigen::Vector3d rhs(const RobertsonSystem& sys, const Eigen::Vector3d& y) {
  const Eigen::VectorXd empty(0);
  Eigen::VectorXd zdot(3);
  sys.misc_derivatives(0.0, empty, empty, y, zdot);
  return zdot;
}

// States along a typical trajectory (start, the fast transient, the slow
// phase, late) plus an off-trajectory one where every term is large.
std::vector<Eigen::Vector3d> sample_states() {
  return {Eigen::Vector3d(1.0, 0.0, 0.0), Eigen::Vector3d(0.99, 3.6e-5, 0.01),
          Eigen::Vector3d(0.966, 3.07e-5, 0.0336), Eigen::Vector3d(0.1, 1e-6, 0.9),
          Eigen::Vector3d(0.3, 0.2, 0.5)};
}

TEST(Robertson, DescribesItself) {
  const RobertsonSystem sys;
  EXPECT_EQ(sys.name(), "robertson");
  EXPECT_EQ(sys.dimensions(), (Dimensions{0, 0, 3}));
  EXPECT_EQ(sys.misc_names(), (std::vector<std::string>{"y1", "y2", "y3"}));
  const State s = sys.initial_state();
  EXPECT_EQ(s.t, 0.0);
  EXPECT_EQ(s.x, Eigen::Vector3d(1, 0, 0));
  const Capabilities c = sys.capabilities();
  EXPECT_TRUE(c.identity_velocity_map && c.constant_mass_matrix && c.diagonal_mass_matrix &&
              c.analytic_jacobians);
  EXPECT_FALSE(c.symmetric_jacobians || c.passive || c.has_energy || c.has_quaternions);
  EXPECT_EQ(sys.mass_matrix_pattern().rows(), 0);
  EXPECT_EQ(sys.mass_matrix_pattern().cols(), 0);
  const ForceJacobians& P = sys.jacobian_pattern();
  EXPECT_EQ(P.dfz_dz.rows(), 3);
  EXPECT_EQ(P.dfz_dz.cols(), 3);
  EXPECT_EQ(P.dfz_dz.nonZeros(), 9);
  for (const SparseMatrix* m : {&P.dF_dq, &P.dF_dv, &P.dF_dz, &P.dfz_dq, &P.dfz_dv}) {
    EXPECT_EQ(m->nonZeros(), 0);
  }
  EXPECT_EQ(P.dF_dz.rows(), 0);
  EXPECT_EQ(P.dF_dz.cols(), 3);
  EXPECT_EQ(P.dfz_dq.rows(), 3);
  EXPECT_EQ(P.dfz_dq.cols(), 0);
}

TEST(Robertson, RejectsBadRates) {
  EXPECT_THROW(RobertsonSystem(-0.04), InputError);
  EXPECT_THROW(RobertsonSystem(0.04, NAN), InputError);
  EXPECT_THROW(RobertsonSystem(0.04, 3e7, INFINITY), InputError);
}

TEST(Robertson, RightHandSideIsTheClassicKineticsAndSumsToZero) {
  const RobertsonSystem sys;
  for (const Eigen::Vector3d& y : sample_states()) {
    const Eigen::Vector3d f = rhs(sys, y);
    const double r1 = 0.04 * y[0], r2 = 3e7 * y[1] * y[1], r3 = 1e4 * y[1] * y[2];
    EXPECT_DOUBLE_EQ(f[0], -r1 + r3);
    EXPECT_DOUBLE_EQ(f[2], r2);
    // Mass conservation: the sum cancels up to the round-off of its largest
    // term.
    EXPECT_LE(std::abs(f.sum()), 4e-16 * f.cwiseAbs().maxCoeff()) << y.transpose();
  }
}

TEST(Robertson, JacobianMatchesCentralDifferences) {
  const RobertsonSystem sys;
  const Eigen::VectorXd empty(0);
  for (const Eigen::Vector3d& y : sample_states()) {
    ForceJacobians J = sys.jacobian_pattern();
    sys.force_jacobians(0.0, empty, empty, y, JacobianRequest{}, &J);
    const Eigen::Matrix3d analytic = Eigen::MatrixXd(J.dfz_dz);
    Eigen::Matrix3d fd;
    for (int j = 0; j < 3; ++j) {
      // f is quadratic, so central differences are exact up to round-off:
      // the error is eps |f| / d, with d = 1e-6 (scaled to y_j) well below
      // the 1e-7 relative tolerance.
      const double d = 1e-6 * std::max(1.0, std::abs(y[j]));
      Eigen::Vector3d yp = y, ym = y;
      yp[j] += d;
      ym[j] -= d;
      fd.col(j) = (rhs(sys, yp) - rhs(sys, ym)) / (2 * d);
    }
    const double scale = analytic.cwiseAbs().maxCoeff();
    EXPECT_LE((analytic - fd).cwiseAbs().maxCoeff(), 1e-7 * scale)
        << "y = " << y.transpose() << "\nanalytic\n"
        << analytic << "\nfd\n"
        << fd;
    // The columns of a conservative kinetics Jacobian sum to zero too.
    EXPECT_LE(analytic.colwise().sum().cwiseAbs().maxCoeff(), 1e-15 * scale);
  }
}

}  // namespace
}  // namespace stiffsim
