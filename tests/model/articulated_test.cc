// Claims about the articulated-body dynamics (exact and compliant
// formulations), each checked against an independent quantity: the kinetic
// energy's Hessian, the potential's gradient, finite differences of F,
// conservation laws and a closed-form period.

#include "stiffsim/model/articulated.h"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <cmath>
#include <random>

#include "stiffsim/error.h"
#include "stiffsim/integrators/runge_kutta45.h"
#include "stiffsim/model/compliant.h"
#include "stiffsim/model/quaternion.h"
#include "stiffsim/model/urdf.h"
#include "articulated_fixtures.h"

namespace stiffsim {
namespace {

Eigen::VectorXd random_positions(const ArticulatedSystem& sys, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::VectorXd q(sys.dimensions().nq);
  for (int i = 0; i < q.size(); ++i) q[i] = u(rng);
  sys.project_positions(q);
  return q;
}

Eigen::VectorXd random_velocities(const ArticulatedSystem& sys, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-2.0, 2.0);
  Eigen::VectorXd v(sys.dimensions().nv);
  for (int i = 0; i < v.size(); ++i) v[i] = u(rng);
  return v;
}

Eigen::MatrixXd dense_mass(const ArticulatedSystem& sys, const Eigen::VectorXd& q) {
  SparseMatrix M = sys.mass_matrix_pattern();
  sys.mass_matrix(q, &M);
  return Eigen::MatrixXd(M);
}

Eigen::VectorXd forces_at(const ArticulatedSystem& sys, const Eigen::VectorXd& q,
                          const Eigen::VectorXd& v) {
  Eigen::VectorXd F(sys.dimensions().nv);
  sys.forces(0.0, q, v, Eigen::VectorXd(), F);
  return F;
}

double potential(const ArticulatedSystem& sys, const Eigen::VectorXd& q) {
  State s;
  s.x.resize(sys.dimensions().nx());
  s.x << q, Eigen::VectorXd::Zero(sys.dimensions().nv);
  return sys.energy(s);
}

// --- The mass matrix -------------------------------------------------------

void expect_mass_is_kinetic_hessian(const ArticulatedSystem& sys, unsigned seed) {
  const Eigen::VectorXd q = random_positions(sys, seed);
  const Eigen::MatrixXd M = dense_mass(sys, q);
  const int n = sys.dimensions().nv;
  // KE is quadratic in v: M_ij = KE(e_i + e_j) - KE(e_i) - KE(e_j) exactly
  // (to rounding), for i != j; M_ii = 2 KE(e_i).
  const double scale = M.cwiseAbs().maxCoeff();
  for (int i = 0; i < n; ++i) {
    const Eigen::VectorXd ei = Eigen::VectorXd::Unit(n, i);
    EXPECT_NEAR(M(i, i), 2.0 * sys.kinetic_energy(q, ei), 1e-12 * scale) << i;
    for (int j = 0; j < i; ++j) {
      const Eigen::VectorXd ej = Eigen::VectorXd::Unit(n, j);
      const double hij = sys.kinetic_energy(q, ei + ej) - sys.kinetic_energy(q, ei) -
                         sys.kinetic_energy(q, ej);
      EXPECT_NEAR(M(i, j), hij, 1e-12 * scale) << i << "," << j;
      EXPECT_EQ(M(i, j), M(j, i));
    }
  }
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(M);
  EXPECT_GT(eig.eigenvalues().minCoeff(), 0.0);
}

TEST(Articulated, MassMatrixIsTheKineticEnergyHessianOnABranchedTree) {
  const ArticulatedSystem sys(branched_tree(), {});
  for (unsigned seed : {1u, 2u, 3u}) expect_mass_is_kinetic_hessian(sys, seed);
}

TEST(Articulated, MassMatrixIsTheKineticEnergyHessianWithAFloatingBase) {
  const ArticulatedSystem sys(branched_tree(/*floating_base=*/true), {});
  for (unsigned seed : {4u, 5u}) expect_mass_is_kinetic_hessian(sys, seed);
}

TEST(Articulated, MassPatternIsTheBranchSparsity) {
  // Bodies on different branches share no entry of M.
  const ArticulatedSystem sys(branched_tree(), {});
  const RigidTree& tree = sys.tree();
  auto on_path = [&](int i, int j) {
    for (int k = i; k >= 0; k = tree.bodies[k].parent)
      if (k == j) return true;
    return false;
  };
  const SparseMatrix& P = sys.mass_matrix_pattern();
  const int nb = static_cast<int>(tree.bodies.size());
  int unrelated_pairs = 0;
  for (int i = 0; i < nb; ++i) {
    for (int j = 0; j < nb; ++j) {
      const bool related = on_path(i, j) || on_path(j, i);
      unrelated_pairs += !related;
      const int r = sys.body_v_offset(i), c = sys.body_v_offset(j);
      bool stored = false;
      for (SparseMatrix::InnerIterator it(P, c); it; ++it) stored |= it.row() == r;
      EXPECT_EQ(related, stored) << tree.bodies[i].link << " " << tree.bodies[j].link;
    }
  }
  EXPECT_GT(unrelated_pairs, 0);
}

// --- Forces ----------------------------------------------------------------

void expect_gravity_is_potential_gradient(const ArticulatedSystem& sys, unsigned seed) {
  const Eigen::VectorXd q = random_positions(sys, seed);
  const Eigen::VectorXd F = forces_at(sys, q, Eigen::VectorXd::Zero(sys.dimensions().nv));
  // F = -N(q)^T dV/dq: the generalized force of the velocities.
  const int nq = sys.dimensions().nq;
  Eigen::VectorXd grad(nq);
  const double eps = 1e-6;
  for (int j = 0; j < nq; ++j) {
    Eigen::VectorXd qp = q, qm = q;
    qp[j] += eps;
    qm[j] -= eps;
    grad[j] = (potential(sys, qp) - potential(sys, qm)) / (2.0 * eps);
  }
  SparseMatrix N = sys.velocity_map_pattern();
  sys.velocity_map(q, &N);
  const Eigen::VectorXd expected = -(Eigen::MatrixXd(N).transpose() * grad);
  // Central differences of a smooth potential of size ~1: error ~ eps^2 plus
  // rounding ~ 1e-16 / eps = 1e-10.
  EXPECT_LT((F - expected).cwiseAbs().maxCoeff(), 1e-7 * (1.0 + expected.cwiseAbs().maxCoeff()))
      << "F = " << F.transpose() << "\nexpected " << expected.transpose();
}

TEST(Articulated, GravityAndSpringsAreThePotentialGradient) {
  ArticulatedOptions o;
  o.joint_forces = springs_for(branched_tree(), 3.0, 0.2);
  const ArticulatedSystem sys(branched_tree(), o);
  for (unsigned seed : {7u, 8u}) expect_gravity_is_potential_gradient(sys, seed);
  const ArticulatedSystem floating(branched_tree(true), {});
  expect_gravity_is_potential_gradient(floating, 9u);
}

void expect_jacobians_match_differences(const ArticulatedSystem& sys, unsigned seed) {
  const Eigen::VectorXd q = random_positions(sys, seed);
  const Eigen::VectorXd v = random_velocities(sys, seed + 100);
  ForceJacobians J = sys.jacobian_pattern();
  sys.force_jacobians(0.0, q, v, Eigen::VectorXd(), JacobianRequest{}, &J);
  const Eigen::MatrixXd K(J.dF_dq), D(J.dF_dv);
  const int nq = sys.dimensions().nq, nv = sys.dimensions().nv;
  const double eps = 1e-6;
  double worst = 0.0, scale = 1.0;
  for (int j = 0; j < nq + nv; ++j) {
    Eigen::VectorXd qp = q, qm = q, vp = v, vm = v;
    if (j < nq) {
      qp[j] += eps, qm[j] -= eps;
    } else {
      vp[j - nq] += eps, vm[j - nq] -= eps;
    }
    const Eigen::VectorXd col = (forces_at(sys, qp, vp) - forces_at(sys, qm, vm)) / (2.0 * eps);
    const Eigen::VectorXd mine = j < nq ? Eigen::VectorXd(K.col(j)) : Eigen::VectorXd(D.col(j - nq));
    worst = std::max(worst, (col - mine).cwiseAbs().maxCoeff());
    scale = std::max(scale, col.cwiseAbs().maxCoeff());
  }
  EXPECT_LT(worst, 1e-6 * scale);
}

TEST(Articulated, ExactJacobiansMatchCentralDifferences) {
  ArticulatedOptions o;
  o.joint_forces = springs_for(branched_tree(), 3.0, 0.2);
  expect_jacobians_match_differences(ArticulatedSystem(branched_tree(), o), 11u);
  expect_jacobians_match_differences(ArticulatedSystem(branched_tree(true), {}), 12u);
}

TEST(Articulated, CompliantJacobiansMatchCentralDifferencesAndAreBlockTridiagonal) {
  BushingParameters b{1e3, 1.0, 1e2, 0.1};
  ArticulatedOptions o;
  o.joint_forces = springs_for(serial_chain(6), 2.0, 0.05);
  auto sys = make_compliant(serial_chain(6), o, b);
  expect_jacobians_match_differences(*sys, 13u);
  // A chain's K and D couple each body with its neighbours only: at most
  // three 6 x 13 blocks per body row.
  const SparseMatrix& K = sys->jacobian_pattern().dF_dq;
  EXPECT_LE(K.nonZeros(), 6 * 3 * 7 * 6);
  EXPECT_LE(sys->jacobian_passes(), 3);
}

// The shipped tree.urdf: heavy links welded by fixed joints, inertial frames
// rotated by rpy with products of inertia, revolute joints about different
// axes and a prismatic slide, loaded through urdfdom.
RigidTree shipped_tree(bool floating_base) {
  return load_urdf(std::string(STIFFSIM_SOURCE_DIR) + "/models/tree.urdf",
                   UrdfOptions{"tree", floating_base}, nullptr);
}

TEST(Articulated, ShippedTreeMassMatrixAndGravityMatchEnergyDerivatives) {
  {
    const bool floating = false;
    ArticulatedOptions o;
    o.joint_forces = springs_for(shipped_tree(floating), 2.0, 0.1);
    const ArticulatedSystem sys(shipped_tree(floating), o);
    for (unsigned seed : {21u, 22u}) {
      expect_mass_is_kinetic_hessian(sys, seed);
      expect_gravity_is_potential_gradient(sys, seed);
      expect_jacobians_match_differences(sys, seed);
    }
  }
}

TEST(Articulated, SingularMassMatrixIsAnInputError) {
  // tree.urdf's root link is massless: on a floating base its rotation about
  // the torso's yaw axis moves nothing that torso_yaw does not.
  try {
    const ArticulatedSystem sys(shipped_tree(true), {});
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("component 'tree': the mass matrix is singular"), std::string::npos)
        << e.what();
  }
}

TEST(Articulated, InertialTermOfTheJacobianMatchesDifferencesOfFMinusMa) {
  // JacobianRequest::acceleration: K is then d(F - M(q) a)/dq.
  const ArticulatedSystem sys(shipped_tree(false), {});
  const Eigen::VectorXd q = random_positions(sys, 31u), v = random_velocities(sys, 32u);
  const Eigen::VectorXd a = random_velocities(sys, 33u);
  JacobianRequest request;
  request.acceleration = a.data();
  ForceJacobians J = sys.jacobian_pattern();
  sys.force_jacobians(0.0, q, v, Eigen::VectorXd(), request, &J);
  const Eigen::MatrixXd K(J.dF_dq);
  auto residual = [&](const Eigen::VectorXd& qq) {
    return Eigen::VectorXd(forces_at(sys, qq, v) - dense_mass(sys, qq) * a);
  };
  const double eps = 1e-6;
  double worst = 0.0, scale = 1.0;
  for (int j = 0; j < q.size(); ++j) {
    Eigen::VectorXd qp = q, qm = q;
    qp[j] += eps, qm[j] -= eps;
    const Eigen::VectorXd col = (residual(qp) - residual(qm)) / (2.0 * eps);
    worst = std::max(worst, (col - K.col(j)).cwiseAbs().maxCoeff());
    scale = std::max(scale, col.cwiseAbs().maxCoeff());
  }
  EXPECT_LT(worst, 1e-6 * scale);
  // Without the term K differs: the check above could fail.
  ForceJacobians plain = sys.jacobian_pattern();
  sys.force_jacobians(0.0, q, v, Eigen::VectorXd(), JacobianRequest{}, &plain);
  EXPECT_GT((Eigen::MatrixXd(plain.dF_dq) - K).cwiseAbs().maxCoeff(), 1e-3 * scale);
}

TEST(Articulated, CompliantColumnsNameTheLinks) {
  auto sys = make_compliant(serial_chain(2), {}, BushingParameters{});
  const std::vector<std::string> q = sys->position_names(), v = sys->velocity_names();
  ASSERT_EQ(q.size(), 14u);
  EXPECT_EQ(q[0], "chain/link_1/x");
  EXPECT_EQ(q[6], "chain/link_1/qz");
  EXPECT_EQ(v[5], "chain/link_1/wz");
  EXPECT_EQ(v[6], "chain/link_2/vx");
  const ArticulatedSystem exact(serial_chain(2), {});
  EXPECT_EQ(exact.position_names()[1], "chain/joint_2");
}

TEST(Articulated, CompliantChainStartsWhereTheExactChainIs) {
  // Bushings at rest: no bushing force, so the initial compliant F equals
  // gravity alone, and the joint coordinates read back the exact angles.
  ArticulatedOptions o;
  o.initial_q = Eigen::VectorXd::LinSpaced(5, 0.1, 0.5);
  auto sys = make_compliant(serial_chain(5), o, BushingParameters{1e6, 0.0, 1e4, 0.0});
  const State x0 = sys->initial_state();
  const Eigen::VectorXd q0 = x0.q(sys->dimensions());
  for (int k = 0; k < 5; ++k) EXPECT_NEAR(sys->bushing_coordinate(k, q0), o.initial_q[k], 1e-12);
  const Eigen::VectorXd F = forces_at(*sys, q0, x0.v(sys->dimensions()));
  for (int b = 0; b < 5; ++b) {
    EXPECT_NEAR(F[6 * b + 2], -0.1 * 9.81, 1e-9);
    EXPECT_NEAR(F.segment<2>(6 * b).norm(), 0.0, 1e-9);
  }
}

// --- Motion ----------------------------------------------------------------

double run_energy_drift(const ArticulatedSystem& sys, double t_final, double accuracy) {
  IntegratorSettings s;
  s.accuracy = accuracy;
  s.max_step = 0.01;
  RungeKutta45 rk(sys, s);
  State x0 = sys.initial_state();
  const double e0 = sys.energy(x0);
  rk.initialize(x0);
  double worst = 0.0;
  while (rk.state().t < t_final) {
    rk.step_at_most(t_final);
    worst = std::max(worst, std::abs(sys.energy(rk.state()) - e0));
  }
  return worst / std::abs(e0);
}

TEST(Articulated, DoublePendulumConservesEnergyUnderTightRk45) {
  ArticulatedOptions o;
  o.initial_q = Eigen::Vector2d(0.3, 0.3);
  const ArticulatedSystem sys(serial_chain(2), o);
  EXPECT_LT(run_energy_drift(sys, 5.0, 1e-10), 1e-7);
}

TEST(Articulated, BranchedTreeConservesEnergyUnderTightRk45) {
  ArticulatedOptions o;
  o.initial_v = Eigen::VectorXd::Constant(ArticulatedSystem(branched_tree(true), {}).dimensions().nv, 0.5);
  o.joint_forces = springs_for(branched_tree(true), 1.0, 0.0);
  const ArticulatedSystem sys(branched_tree(true), o);
  EXPECT_LT(run_energy_drift(sys, 1.0, 1e-10), 1e-7);
}

TEST(Articulated, PendulumSmallAnglePeriodMatchesClosedForm) {
  // One rod about y: period 2 pi sqrt(I_pivot / (m g d)).
  const double m = 0.1, l = 0.1, d = 0.05;
  ArticulatedOptions o;
  o.initial_q = Eigen::VectorXd::Constant(1, 1e-3);
  const ArticulatedSystem sys(serial_chain(1), o);
  const double i_pivot = m * l * l / 12.0 + m * d * d;
  const double expected = 2.0 * M_PI * std::sqrt(i_pivot / (m * 9.81 * d));
  IntegratorSettings s;
  s.accuracy = 1e-11;
  s.max_step = 1e-3;
  RungeKutta45 rk(sys, s);
  rk.initialize(sys.initial_state());
  // Upward zero crossings of the angle, located by linear interpolation.
  std::vector<double> crossings;
  double t_prev = 0.0, a_prev = 1e-3;
  while (crossings.size() < 4) {
    rk.step_at_most(10.0);
    const double a = rk.state().x[0], t = rk.state().t;
    if (a_prev < 0.0 && a >= 0.0) crossings.push_back(t_prev + (t - t_prev) * (-a_prev) / (a - a_prev));
    t_prev = t;
    a_prev = a;
  }
  const double period = (crossings.back() - crossings.front()) / 3.0;
  EXPECT_NEAR(period / expected, 1.0, 1e-3);
}

}  // namespace
}  // namespace stiffsim
