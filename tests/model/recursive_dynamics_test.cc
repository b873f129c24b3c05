// The O(n) recursive algorithms against the assembled matrices: the
// articulated-body solve against a dense solve of M(q) + diag(d), and the
// inverse-dynamics residual against M(q) dv - h F.

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <random>

#include "articulated_fixtures.h"
#include "stiffsim/error.h"
#include "stiffsim/model/articulated.h"
#include "stiffsim/model/articulated_body_solver.h"

namespace stiffsim {
namespace {

// A random state of `system`: joint values in [-1, 1], unit quaternions.
void random_state(const ArticulatedSystem& system, unsigned seed, Eigen::VectorXd* q,
                  Eigen::VectorXd* v) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Dimensions d = system.dimensions();
  *q = Eigen::VectorXd::NullaryExpr(d.nq, [&] { return u(rng); });
  *v = Eigen::VectorXd::NullaryExpr(d.nv, [&] { return u(rng); });
  system.project_positions(*q);
}

Eigen::MatrixXd dense_mass(const ArticulatedSystem& system, const Eigen::VectorXd& q) {
  SparseMatrix M = system.mass_matrix_pattern();
  system.mass_matrix(q, &M);
  return Eigen::MatrixXd(M);
}

std::vector<std::unique_ptr<ArticulatedSystem>> systems_under_test() {
  std::vector<std::unique_ptr<ArticulatedSystem>> out;
  ArticulatedOptions chain;
  chain.joint_forces.resize(12);
  for (int i = 0; i < 12; ++i) chain.joint_forces[i] = JointForce{100.0 * (i + 1), 0.1, 0.3 * i};
  // A drive on a joint that also has a spring: two elements on one pivot.
  chain.drives.push_back(
      JointDrive{3, 500.0, 4.0, ScalarPath::sinusoid(0.1, 0.3, 2.0, 0.0, "drive")});
  out.push_back(std::make_unique<ArticulatedSystem>(serial_chain(12), chain));
  out.push_back(std::make_unique<ArticulatedSystem>(branched_tree(false), ArticulatedOptions{}));
  out.push_back(std::make_unique<ArticulatedSystem>(branched_tree(true), ArticulatedOptions{}));
  return out;
}

TEST(ArticulatedBodySolver, SolvesTheMassMatrixPlusJointTerms) {
  // (M(q) + h D_J + h^2 K_J) x = b to round-off: the pivots are those of an
  // LDL^T factorization, so the error is a few ulps times the condition.
  int index = 0;
  for (const auto& owned : systems_under_test()) {
    const ArticulatedSystem& system = *owned;
    const ArticulatedModel& model = system.model();
    ArticulatedBodySolver solver(model, system.pivot_stiffness(), system.pivot_damping());
    for (unsigned seed = 1; seed <= 3; ++seed) {
      Eigen::VectorXd q, v;
      random_state(system, seed + 10 * index, &q, &v);
      const double h = 1e-2 * seed;
      Eigen::MatrixXd W = dense_mass(system, q);
      // The joint terms from the description itself: the URDF's damping,
      // the scene's springs and dampers, the drives' gains.
      const ArticulatedOptions& o = system.options();
      for (int i = 0; i < model.bodies(); ++i) {
        if (joint_nv(model.tree.bodies[i].type) != 1) continue;
        const int k = model.v_offset[i];
        W(k, k) += h * model.tree.bodies[i].damping;
        if (!o.joint_forces.empty()) {
          W(k, k) += h * o.joint_forces[i].damping + h * h * o.joint_forces[i].stiffness;
        }
      }
      for (const JointDrive& dr : o.drives) {
        const int k = model.v_offset[dr.body];
        W(k, k) += h * dr.kd + h * h * dr.kp;
      }
      ASSERT_TRUE(solver.factor(q, h));
      const Eigen::VectorXd b = Eigen::VectorXd::LinSpaced(model.nv, -1.0, 2.0);
      Eigen::VectorXd x(model.nv);
      solver.solve(b, x);
      const Eigen::VectorXd expected = W.ldlt().solve(b);
      EXPECT_LT((x - expected).norm(), 1e-10 * expected.norm())
          << "system " << index << " seed " << seed;
    }
    ++index;
  }
}

TEST(ArticulatedBodySolver, ReportsASingularMassMatrix) {
  // A massless leaf moves nothing: its pivot is zero.
  RigidTree tree = serial_chain(3);
  tree.bodies[2].inertia = RigidInertia{};
  ArticulatedOptions options;
  EXPECT_THROW(ArticulatedSystem(tree, options), InputError);
  ArticulatedSystem good(serial_chain(3), options);
  ArticulatedBodySolver solver(good.model(), good.pivot_stiffness(), good.pivot_damping());
  EXPECT_TRUE(solver.factor(Eigen::VectorXd::Zero(3), 0.0));
  EXPECT_GT(solver.pivot_ratio(), 1e-6);
}

TEST(InverseDynamicsResidual, EqualsTheMassMatrixForm) {
  // M(q) dv - h F, evaluated without M, against the assembled product.
  int index = 0;
  for (const auto& owned : systems_under_test()) {
    const ArticulatedSystem& system = *owned;
    const Dimensions d = system.dimensions();
    Eigen::VectorXd q, v;
    random_state(system, 7 + index, &q, &v);
    const Eigen::VectorXd dv = Eigen::VectorXd::LinSpaced(d.nv, -0.3, 0.5);
    const double h = 3e-3;
    Eigen::VectorXd F(d.nv), r(d.nv);
    const Eigen::VectorXd z(0);
    system.forces(0.0, q, v, z, F);
    system.momentum_residual(0.0, q, v, z, dv, h, r);
    const Eigen::VectorXd expected = dense_mass(system, q) * dv - h * F;
    EXPECT_LT((r - expected).norm(), 1e-12 * (expected.norm() + h * F.norm()))
        << "system " << index;
    ++index;
  }
}

TEST(ArticulatedSystem, ForceJacobiansAreTheAnalyticDerivatives) {
  // force_jacobians() (analytic RNEA derivatives) against
  // automatic_force_jacobians() (forward-mode AD) through the System
  // interface, with the inertial term of a given acceleration: both exact,
  // so they agree to round-off (1e-10 of the largest entry).
  int index = 0;
  for (const auto& owned : systems_under_test()) {
    const ArticulatedSystem& system = *owned;
    const Dimensions d = system.dimensions();
    Eigen::VectorXd q, v;
    random_state(system, 21 + index, &q, &v);
    const Eigen::VectorXd a = Eigen::VectorXd::LinSpaced(d.nv, 2.0, -1.0);
    const Eigen::VectorXd z(0);
    for (const double* acceleration : {static_cast<const double*>(nullptr), a.data()}) {
      JacobianRequest request;
      request.acceleration = acceleration;
      ForceJacobians analytic = system.jacobian_pattern(), automatic = system.jacobian_pattern();
      system.force_jacobians(0.0, q, v, z, request, &analytic);
      system.automatic_force_jacobians(0.0, q, v, z, request, &automatic);
      for (auto m : {&ForceJacobians::dF_dq, &ForceJacobians::dF_dv}) {
        const Eigen::MatrixXd A(analytic.*m), B(automatic.*m);
        EXPECT_LE((A - B).cwiseAbs().maxCoeff(), 1e-10 * B.cwiseAbs().maxCoeff())
            << "system " << index;
      }
    }
    ++index;
  }
}

}  // namespace
}  // namespace stiffsim
