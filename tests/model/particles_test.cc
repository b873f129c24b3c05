// Particle mass-spring systems and their builders (MODELS.md, "Particle
// mass-spring meshes"): forces, analytic Jacobians against finite
// differences, energy, topology, validation.

#include "stiffsim/model/particles.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <random>
#include <string>

#include "stiffsim/error.h"
#include "stiffsim/model/particle_meshes.h"

// Not under AddressSanitizer, whose own malloc a replacement would shadow.
#if defined(__GLIBC__) && !defined(__SANITIZE_ADDRESS__)
// Counts every heap allocation (operator new and Eigen both end in malloc) while
// g_count_allocations is set, to check that the hot path allocates nothing.
extern "C" void* __libc_malloc(size_t size);
static std::atomic<bool> g_count_allocations{false};
static std::atomic<long> g_allocations{0};
extern "C" void* malloc(size_t size) {
  if (g_count_allocations.load(std::memory_order_relaxed)) ++g_allocations;
  return __libc_malloc(size);
}
#define STIFFSIM_COUNTS_ALLOCATIONS 1
#endif

namespace stiffsim {
namespace {

using Eigen::MatrixXd;
using Eigen::Vector3d;
using Eigen::VectorXd;

VectorXd forces_at(const ParticleSystem& sys, const VectorXd& q, const VectorXd& v) {
  VectorXd F(sys.dimensions().nv);
  sys.forces(0.0, q, v, VectorXd(), F);
  return F;
}

struct Jacobians {
  MatrixXd K, D;
  long approximated;
};

Jacobians jacobians_at(const ParticleSystem& sys, const VectorXd& q, const VectorXd& v,
                       bool definite = false, bool complete = false) {
  ForceJacobians J = sys.jacobian_pattern();
  JacobianRequest request;
  request.definite = definite;
  request.complete = complete;
  sys.force_jacobians(0.0, q, v, VectorXd(), request, &J);
  return {MatrixXd(J.dF_dq), MatrixXd(J.dF_dv), J.approximated_terms};
}

Jacobians automatic_jacobians_at(const ParticleSystem& sys, const VectorXd& q, const VectorXd& v,
                                 bool definite = false) {
  ForceJacobians J = sys.jacobian_pattern();
  J.approximated_terms = -1;
  JacobianRequest request;
  request.definite = definite;
  sys.automatic_force_jacobians(0.0, q, v, VectorXd(), request, &J);
  return {MatrixXd(J.dF_dq), MatrixXd(J.dF_dv), J.approximated_terms};
}

// Central differences, column by column. In q the step is 1e-6 (positions
// are O(1)): truncation O(h^2 |F'''|) and round-off O(eps |F| / h) give a
// relative error ~3e-11 on the test cloth, far below the 1e-6 tolerance. F is
// affine in v, so in v there is no truncation error and a large step only
// shrinks the round-off.
MatrixXd central_difference(const ParticleSystem& sys, const VectorXd& q, const VectorXd& v,
                            bool wrt_velocity) {
  const double h = wrt_velocity ? 1e-2 : 1e-6;
  const int n = sys.dimensions().nv;
  MatrixXd J(n, n);
  for (int j = 0; j < n; ++j) {
    VectorXd qp = q, qm = q, vp = v, vm = v;
    (wrt_velocity ? vp : qp)[j] += h;
    (wrt_velocity ? vm : qm)[j] -= h;
    J.col(j) = (forces_at(sys, qp, vp) - forces_at(sys, qm, vm)) / (2 * h);
  }
  return J;
}

// Relative error in the Frobenius norm: every entry counts (including those
// outside the sparsity pattern, where the analytic matrix is 0), and the
// scale is that of the whole matrix, so tiny entries do not need a relative
// match of their own. A zero reference (D without dampers) demands an exact 0.
double relative_error(const MatrixXd& analytic, const MatrixXd& reference) {
  return (analytic - reference).norm() / std::max(reference.norm(), 1e-300);
}

// A random state near the initial one: positions moved by up to `jitter`
// (enough to compress some springs and stretch others), velocities O(1).
State perturbed_state(const ParticleSystem& sys, double jitter, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  const Dimensions d = sys.dimensions();
  State s = sys.initial_state();
  for (int i = 0; i < d.nq; ++i) s.q(d)[i] += jitter * uniform(rng);
  for (int i = 0; i < d.nv; ++i) s.v(d)[i] = uniform(rng);
  return s;
}

ClothSpec small_cloth(double damping) {
  ClothSpec spec;
  spec.nx = 4;
  spec.ny = 3;
  spec.width = 0.6;
  spec.height = 0.4;
  spec.total_mass = 0.3;
  spec.stretch = SpringParameters{1.0e3, damping};
  spec.shear = SpringParameters{2.0e2, 0.5 * damping};
  spec.bend = SpringParameters{10.0, 0.1 * damping};
  spec.drag = damping > 0 ? 0.3 : 0.0;
  return spec;
}

RopeSpec small_rope(double damping) {
  RopeSpec spec;
  spec.nodes = 6;
  spec.length = 1.0;
  spec.total_mass = 0.1;
  spec.stretch = SpringParameters{5.0e3, damping};
  spec.bend = SpringParameters{2.0, 0.1 * damping};
  spec.drag = damping > 0 ? 0.2 : 0.0;
  return spec;
}

// Two nodes, the first pinned: every term can be written down by hand.
ParticleDescription pendulum(double k, double c, double rest_length) {
  ParticleDescription d;
  d.name = "p";
  d.positions = {Vector3d(0, 0, 0), Vector3d(0, 0, -1.5)};
  d.masses = {3.0, 2.0};
  d.springs = {Spring{0, 1, rest_length, k, c}};
  d.pinned = {0};
  return d;
}

// --- ParticleSystem basics -------------------------------------------------

TEST(ParticleSystem, FreeNodesAreTheDofsInNodeOrder) {
  ClothSpec spec = small_cloth(0.0);
  spec.pinned = std::vector<int>{1, 5, 5};  // a duplicate pin is harmless
  const ParticleSystem sys(make_cloth(spec));
  EXPECT_EQ(sys.dimensions(), (Dimensions{30, 30, 0}));
  EXPECT_EQ(sys.dof_of_node(0), 0);
  EXPECT_EQ(sys.dof_of_node(1), -1);
  EXPECT_EQ(sys.dof_of_node(2), 3);
  EXPECT_EQ(sys.dof_of_node(5), -1);
  EXPECT_EQ(sys.dof_of_node(6), 12);

  const State s = sys.initial_state();
  EXPECT_EQ(s.x.size(), 60);
  EXPECT_EQ(s.t, 0.0);
  EXPECT_TRUE(s.v(sys.dimensions()).isZero());
  EXPECT_EQ(Vector3d(s.x.segment<3>(3)), sys.description().positions[2]);
}

TEST(ParticleSystem, CapabilitiesDescribeAConservativeParticleSystem) {
  const ParticleSystem sys(make_rope(small_rope(0.1)));
  const Capabilities c = sys.capabilities();
  EXPECT_TRUE(c.identity_velocity_map);
  EXPECT_TRUE(c.constant_mass_matrix);
  EXPECT_TRUE(c.diagonal_mass_matrix);
  EXPECT_TRUE(c.symmetric_jacobians);
  EXPECT_TRUE(c.analytic_jacobians);
  EXPECT_TRUE(c.automatic_jacobians);
  EXPECT_TRUE(c.has_energy);
  EXPECT_FALSE(c.has_quaternions);
}

TEST(ParticleSystem, NamesSkipPinnedNodesAndUseOriginalIndices) {
  const ParticleSystem sys(make_rope(small_rope(0.0)));  // node 0 pinned
  const std::vector<std::string> names = sys.position_names();
  ASSERT_EQ(names.size(), 15u);
  EXPECT_EQ(names[0], "rope/n1/x");
  EXPECT_EQ(names[1], "rope/n1/y");
  EXPECT_EQ(names[2], "rope/n1/z");
  EXPECT_EQ(names[14], "rope/n5/z");
  EXPECT_EQ(sys.velocity_names(), names);
  EXPECT_EQ(sys.name(), "rope");
}

TEST(ParticleSystem, MassMatrixIsTheDiagonalOfFreeNodeMasses) {
  ParticleDescription d = pendulum(1.0, 0.0, 1.0);
  d.positions.push_back(Vector3d(1, 0, 0));
  d.masses.push_back(0.5);
  const ParticleSystem sys(d);
  SparseMatrix M = sys.mass_matrix_pattern();
  EXPECT_EQ(M.nonZeros(), 6);
  sys.mass_matrix(sys.initial_state().q(sys.dimensions()), &M);
  const VectorXd expected = (VectorXd(6) << 2, 2, 2, 0.5, 0.5, 0.5).finished();
  EXPECT_EQ(MatrixXd(M), MatrixXd(expected.asDiagonal()));
}

TEST(ParticleSystem, ForcesMatchHandComputedSpringGravityAndDrag) {
  // Node 1 hangs 1.5 m below the pinned node 0 with L = 1: the spring pulls it
  // up by k (l - L) = 10 * 0.5; moving down at 2 m/s, the damper adds
  // c * 2 = 0.6 upwards, and drag -alpha m v = +0.4 * 2 * 2.
  ParticleDescription d = pendulum(10.0, 0.3, 1.0);
  d.drag = 0.4;
  const ParticleSystem sys(d);
  const VectorXd q = Vector3d(0, 0, -1.5);
  const VectorXd v = Vector3d(0, 0, -2.0);
  const VectorXd F = forces_at(sys, q, v);
  const double expected_z = 10.0 * 0.5 + 0.3 * 2.0 + 0.4 * 2.0 * 2.0 - 2.0 * 9.81;
  EXPECT_NEAR(F[0], 0.0, 1e-14);
  EXPECT_NEAR(F[1], 0.0, 1e-14);
  EXPECT_NEAR(F[2], expected_z, 1e-12);
}

// Two nodes joined by one spring: a at the origin, b at (3, 4, 0), so
// l = 5 against L = 4 and k = 2; no gravity. With a pinned, the Jacobians
// are b's 3x3 blocks.
ParticleDescription spring_pair(bool pin_a) {
  ParticleDescription d;
  d.name = "pair";
  d.positions = {Vector3d(0, 0, 0), Vector3d(3, 4, 0)};
  d.masses = {1.0, 1.0};
  d.springs = {Spring{0, 1, 4.0, 2.0, 0.0}};
  if (pin_a) d.pinned = {0};
  d.gravity.setZero();
  return d;
}

TEST(ParticleSystem, SpringForcesAreEqualAndOppositeAlongTheAxis) {
  const ParticleSystem sys(spring_pair(false));
  const VectorXd F = forces_at(sys, sys.initial_state().q(sys.dimensions()), VectorXd::Zero(6));
  // l = 5, L = 4: node a is pulled towards b with k (l - L) = 2 along (3, 4)/5.
  EXPECT_TRUE(F.head<3>().isApprox(Vector3d(1.2, 1.6, 0.0), 1e-14));
  EXPECT_TRUE(F.tail<3>().isApprox(-Vector3d(1.2, 1.6, 0.0), 1e-14));
}

TEST(ParticleSystem, TensionEstimateReplacesOnlyTheTransverseStiffness) {
  // One spring, a at the origin (pinned: K is b's 3x3 block), b at (3, 4, 0):
  // l = 5, L = 4, k = 2, u = (3, 4, 0)/5. The reference puts b at (5, 0, 0):
  // l_p = 5, u_p = (1, 0, 0), so u_p . d = 3. The exact transverse
  // stiffness is k (l - L)/l = 0.4; the estimate gives k (l_p - L)/l = 0.4
  // as well, and carried k (u_p . d - L)/l = -0.4, which the definite
  // request clamps to 0. The axial term k u u^T never changes.
  const ParticleSystem sys(spring_pair(true));
  const VectorXd q = sys.initial_state().q(sys.dimensions());
  const VectorXd v = VectorXd::Zero(3);
  const Vector3d p_b(5.0, 0.0, 0.0);
  const Vector3d u(0.6, 0.8, 0.0);
  const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - u * u.transpose();
  auto block = [&](const double* positions, bool carried, bool definite) {
    ForceJacobians J = sys.jacobian_pattern();
    JacobianRequest request;
    request.definite = definite;
    request.tension_positions = positions;
    request.tension_carried = carried;
    sys.force_jacobians(0.0, q, v, VectorXd(), request, &J);
    return std::make_pair(Eigen::Matrix3d(MatrixXd(J.dF_dq)), J.approximated_terms);
  };
  const Eigen::Matrix3d axial = -2.0 * u * u.transpose();
  EXPECT_TRUE(block(nullptr, false, false).first.isApprox(axial - 0.4 * P, 1e-14));
  EXPECT_TRUE(block(p_b.data(), false, false).first.isApprox(axial - 0.4 * P, 1e-14));
  EXPECT_TRUE(block(p_b.data(), true, false).first.isApprox(axial + 0.4 * P, 1e-14));
  const auto clamped = block(p_b.data(), true, true);
  EXPECT_TRUE(clamped.first.isApprox(axial, 1e-14));
  EXPECT_EQ(clamped.second, 1);
  // At the evaluation point itself, carried or not, the estimate is exact.
  EXPECT_TRUE(block(q.data(), true, false).first.isApprox(axial - 0.4 * P, 1e-14));
  // The forces never see it.
  EXPECT_TRUE(forces_at(sys, q, v).isApprox(-Vector3d(1.2, 1.6, 0.0), 1e-14));
}

// The iteration matrices' requests (the definite clamp, the tension
// estimate) change dF/dq only (JacobianRequest): an integrator takes the
// damping matrix of its line-search potential from an iteration matrix's
// Jacobians. A damped cloth (drag too) in motion, every spring compressed
// by 3% so the clamp acts, the tension estimated at positions stretched
// by 2%: dF/dv is the default request's to the last bit, dF/dq is not.
TEST(ParticleSystem, DampingMatrixIsTheSameWhateverTheRequest) {
  const ParticleSystem sys(make_cloth(small_cloth(0.8)));
  const Dimensions d = sys.dimensions();
  const VectorXd q = 0.97 * sys.initial_state().q(d);
  const VectorXd p = 1.02 * sys.initial_state().q(d);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  VectorXd v(d.nv);
  for (int i = 0; i < d.nv; ++i) v[i] = uniform(rng);
  auto jacobians = [&](const JacobianRequest& request) {
    ForceJacobians J = sys.jacobian_pattern();
    sys.force_jacobians(0.0, q, v, VectorXd(), request, &J);
    return J;
  };
  const ForceJacobians plain = jacobians(JacobianRequest{});
  ASSERT_GT(MatrixXd(plain.dF_dv).norm(), 0.0);
  JacobianRequest definite, estimate, carried, both;
  definite.definite = both.definite = true;
  estimate.tension_positions = carried.tension_positions = both.tension_positions = p.data();
  carried.tension_carried = both.tension_carried = true;
  for (const JacobianRequest* request : {&definite, &estimate, &carried, &both}) {
    const ForceJacobians J = jacobians(*request);
    ASSERT_EQ(J.dF_dv.nonZeros(), plain.dF_dv.nonZeros());
    EXPECT_TRUE(std::equal(J.dF_dv.valuePtr(), J.dF_dv.valuePtr() + J.dF_dv.nonZeros(),
                           plain.dF_dv.valuePtr()));
    EXPECT_GT(MatrixXd(J.dF_dq - plain.dF_dq).norm(), 1e-3 * MatrixXd(plain.dF_dq).norm());
  }
}

TEST(ParticleSystem, CollapsedSpringGivesFiniteForcesAndJacobians) {
  ParticleDescription d;
  d.name = "zero";
  d.positions = {Vector3d(1, 1, 1), Vector3d(1, 1, 1), Vector3d(0, 0, 0)};
  d.masses = {1.0, 1.0, 1.0};
  // A zero-rest-length spring between coincident nodes (legal), and a spring
  // with L > 0 that is collapsed in the state below.
  d.springs = {Spring{0, 1, 0.0, 5.0, 1.0}, Spring{1, 2, 1.0, 7.0, 1.0}};
  const ParticleSystem sys(d);
  VectorXd q = sys.initial_state().q(sys.dimensions());
  q.segment<3>(6) = q.segment<3>(3);  // node 2 onto node 1
  const VectorXd v = VectorXd::Ones(9);
  EXPECT_TRUE(forces_at(sys, q, v).allFinite());
  for (bool definite : {false, true}) {
    const Jacobians J = jacobians_at(sys, q, v, definite);
    EXPECT_TRUE(J.K.allFinite());
    EXPECT_TRUE(J.D.allFinite());
    // k I: exact for the L = 0 spring; the documented stand-in for L > 0.
    EXPECT_TRUE((J.K.block<3, 3>(0, 3).isApprox(5.0 * Eigen::Matrix3d::Identity())));
    EXPECT_TRUE((J.K.block<3, 3>(3, 6).isApprox(7.0 * Eigen::Matrix3d::Identity())));
    EXPECT_EQ(J.approximated, definite ? 1 : 0);
  }
}

TEST(ParticleSystem, PinnedNodesStayPutAndSpringsToThemPull) {
  const ParticleSystem sys(make_rope(small_rope(0.0)));
  const Dimensions d = sys.dimensions();
  // Move node 1 (DOF 0) away from the pinned node 0: the force on it points
  // back towards node 0's initial position (0, 0, 0).
  VectorXd q = sys.initial_state().q(d);
  q.segment<3>(0) = Vector3d(0.3, 0.0, 0.0);
  const VectorXd F = forces_at(sys, q, VectorXd::Zero(d.nv));
  EXPECT_LT(F[0], -100.0);
}

// --- Jacobians ---------------------------------------------------------------

TEST(ParticleSystem, JacobianPatternHasNodeBlocksAndSpringBlocksOnly) {
  const ParticleSystem sys(make_cloth(small_cloth(0.1)));
  const ForceJacobians& P = sys.jacobian_pattern();
  const int nv = sys.dimensions().nv;
  int both_free = 0;
  for (const Spring& s : sys.description().springs) {
    both_free += sys.dof_of_node(s.a) >= 0 && sys.dof_of_node(s.b) >= 0;
  }
  // Cloth springs connect distinct node pairs, so no two blocks coincide.
  EXPECT_EQ(P.dF_dq.nonZeros(), 9 * (nv / 3) + 18 * both_free);
  EXPECT_EQ(P.dF_dq.rows(), nv);
  EXPECT_EQ(P.dF_dq.cols(), nv);
  EXPECT_TRUE(is_structurally_symmetric(P.dF_dq));
  EXPECT_EQ(MatrixXd(P.dF_dv).cwiseAbs().sum(), 0.0);
  for (int k = 0; k < P.dF_dq.nonZeros(); ++k) {
    EXPECT_EQ(P.dF_dq.innerIndexPtr()[k], P.dF_dv.innerIndexPtr()[k]);
  }
  EXPECT_EQ(P.dF_dz.rows(), nv);
  EXPECT_EQ(P.dF_dz.cols(), 0);
  EXPECT_EQ(P.dfz_dq.rows(), 0);
  EXPECT_EQ(P.dfz_dq.cols(), nv);
  EXPECT_EQ(P.dfz_dv.rows(), 0);
  EXPECT_EQ(P.dfz_dv.cols(), nv);
  EXPECT_EQ(P.dfz_dz.size(), 0);
}

// K drops the derivative of the damping force through u(x), so K is compared
// with differences of F either with c = 0 (any v) or with v = 0 (any c): in
// both cases the dropped term is exactly zero. D has no dropped term.
void expect_jacobians_match_differences(const ParticleSystem& sys, const State& s) {
  const Dimensions d = sys.dimensions();
  const VectorXd q = s.q(d), v = s.v(d);
  const Jacobians J = jacobians_at(sys, q, v);
  EXPECT_LT(relative_error(J.K, central_difference(sys, q, v, false)), 1e-6);
  EXPECT_LT(relative_error(J.D, central_difference(sys, q, v, true)), 1e-6);
  EXPECT_EQ(J.approximated, 0);
  EXPECT_TRUE(J.K.isApprox(J.K.transpose(), 1e-15));
  EXPECT_TRUE(J.D.isApprox(J.D.transpose(), 1e-15));
}

TEST(ParticleSystem, ClothJacobiansMatchCentralDifferencesWithoutDamping) {
  const ParticleSystem sys(make_cloth(small_cloth(0.0)));
  for (unsigned seed : {1u, 2u, 3u})
    expect_jacobians_match_differences(sys, perturbed_state(sys, 0.05, seed));
}

TEST(ParticleSystem, ClothJacobiansMatchCentralDifferencesAtRestWithDamping) {
  const ParticleSystem sys(make_cloth(small_cloth(2.0)));
  State s = perturbed_state(sys, 0.05, 4);
  s.v(sys.dimensions()).setZero();
  expect_jacobians_match_differences(sys, s);
}

TEST(ParticleSystem, RopeJacobiansMatchCentralDifferences) {
  const ParticleSystem undamped(make_rope(small_rope(0.0)));
  expect_jacobians_match_differences(undamped, perturbed_state(undamped, 0.1, 5));
  const ParticleSystem damped(make_rope(small_rope(1.0)));
  State s = perturbed_state(damped, 0.1, 6);
  s.v(damped.dimensions()).setZero();
  expect_jacobians_match_differences(damped, s);
}

TEST(ParticleSystem, DampingJacobianIsExactAtAnyVelocity) {
  // F is affine in v, so D matches differences at any state, also with drag,
  // down to round-off (~1e-13 here).
  const ParticleSystem sys(make_cloth(small_cloth(2.0)));
  const State s = perturbed_state(sys, 0.05, 7);
  const Dimensions d = sys.dimensions();
  const Jacobians J = jacobians_at(sys, s.q(d), s.v(d));
  EXPECT_LT(relative_error(J.D, central_difference(sys, s.q(d), s.v(d), true)), 1e-8);
  // The damping-through-u term really is dropped from K at v != 0: K then
  // differs from the differences (otherwise this comparison proves nothing).
  EXPECT_GT(relative_error(J.K, central_difference(sys, s.q(d), s.v(d), false)), 1e-6);
}

TEST(ParticleSystem, CompleteJacobianMatchesDifferencesAtAnyVelocity) {
  // With request.complete, K keeps the damping term through u(x): exact at
  // v != 0 with dampers and drag, and unsymmetric there.
  for (const ParticleSystem& sys :
       {ParticleSystem(make_cloth(small_cloth(2.0))), ParticleSystem(make_rope(small_rope(1.0)))}) {
    const State s = perturbed_state(sys, 0.05, 21);
    const Dimensions d = sys.dimensions();
    const Jacobians J = jacobians_at(sys, s.q(d), s.v(d), false, true);
    EXPECT_LT(relative_error(J.K, central_difference(sys, s.q(d), s.v(d), false)), 1e-6);
    EXPECT_LT(relative_error(J.D, central_difference(sys, s.q(d), s.v(d), true)), 1e-8);
    EXPECT_FALSE(J.K.isApprox(J.K.transpose(), 1e-6));
    // D does not depend on the request.
    EXPECT_EQ(J.D, jacobians_at(sys, s.q(d), s.v(d)).D);
  }
}

TEST(ParticleSystem, AutomaticJacobiansEqualTheCompleteAnalyticOnes) {
  // The same derivative taken twice (by hand and by dual numbers through the
  // force kernel): equal to round-off, pinned nodes, drag and all.
  for (const ParticleSystem& sys :
       {ParticleSystem(make_cloth(small_cloth(2.0))), ParticleSystem(make_rope(small_rope(1.0)))}) {
    for (unsigned seed : {22u, 23u}) {
      const State s = perturbed_state(sys, 0.05, seed);
      const Dimensions d = sys.dimensions();
      const Jacobians analytic = jacobians_at(sys, s.q(d), s.v(d), false, true);
      const Jacobians automatic = automatic_jacobians_at(sys, s.q(d), s.v(d));
      EXPECT_LT(relative_error(automatic.K, analytic.K), 1e-14);
      EXPECT_LT(relative_error(automatic.D, analytic.D), 1e-14);
      EXPECT_EQ(automatic.approximated, 0);
    }
  }
}

TEST(ParticleSystem, AutomaticJacobiansIgnoreTheDefiniteRequest) {
  const ParticleSystem sys(make_cloth(small_cloth(0.0)));
  const Dimensions d = sys.dimensions();
  State s = perturbed_state(sys, 0.02, 24);
  s.q(d) *= 0.6;  // every spring compressed: the definite request would clamp
  const Jacobians exact = jacobians_at(sys, s.q(d), s.v(d), false, true);
  const Jacobians automatic = automatic_jacobians_at(sys, s.q(d), s.v(d), true);
  ASSERT_GT(jacobians_at(sys, s.q(d), s.v(d), true).approximated, 0);
  EXPECT_LT(relative_error(automatic.K, exact.K), 1e-14);
  EXPECT_EQ(automatic.approximated, 0);
}

TEST(ParticleSystem, AutomaticJacobianOfACollapsedSpringIsFinite) {
  // forces() defines a collapsed spring's force as 0, and AD differentiates
  // forces() as it is: finite, where a naive |d| would give NaN lanes.
  ParticleDescription d = pendulum(10.0, 1.0, 0.5);
  d.positions[1] = d.positions[0];
  const ParticleSystem sys(d);
  const VectorXd q = sys.initial_state().q(sys.dimensions());
  const Jacobians automatic = automatic_jacobians_at(sys, q, VectorXd::Ones(3));
  EXPECT_TRUE(automatic.K.allFinite());
  EXPECT_TRUE(automatic.D.allFinite());
}

TEST(ParticleSystem, ForceJacobiansOverwriteInsteadOfAccumulating) {
  const ParticleSystem sys(make_cloth(small_cloth(1.0)));
  const State s = perturbed_state(sys, 0.05, 8);
  const Dimensions d = sys.dimensions();
  ForceJacobians J = sys.jacobian_pattern();
  std::fill(J.dF_dq.valuePtr(), J.dF_dq.valuePtr() + J.dF_dq.nonZeros(), 123.0);
  std::fill(J.dF_dv.valuePtr(), J.dF_dv.valuePtr() + J.dF_dv.nonZeros(), -7.0);
  sys.force_jacobians(0.0, s.q(d), s.v(d), s.z(d), JacobianRequest{}, &J);
  sys.force_jacobians(0.0, s.q(d), s.v(d), s.z(d), JacobianRequest{}, &J);
  const Jacobians fresh = jacobians_at(sys, s.q(d), s.v(d));
  EXPECT_EQ(MatrixXd(J.dF_dq), fresh.K);
  EXPECT_EQ(MatrixXd(J.dF_dv), fresh.D);
}

TEST(ParticleSystem, DefiniteRequestClampsCompressedSpringsToPsd) {
  const ParticleSystem sys(make_cloth(small_cloth(0.0)));
  const Dimensions d = sys.dimensions();
  // Shrink the sheet to 60% and wrinkle it: every spring is compressed.
  State s = perturbed_state(sys, 0.02, 9);
  s.q(d) *= 0.6;
  const VectorXd q = s.q(d), v = s.v(d);

  const Jacobians exact = jacobians_at(sys, q, v, false);
  const Jacobians definite = jacobians_at(sys, q, v, true);
  Eigen::SelfAdjointEigenSolver<MatrixXd> exact_eig(-exact.K), definite_eig(-definite.K);
  const double scale = exact.K.norm();
  // Without the clamp -K is indefinite here, so the check below means something.
  EXPECT_LT(exact_eig.eigenvalues().minCoeff(), -1e-3 * scale);
  EXPECT_GE(definite_eig.eigenvalues().minCoeff(), -1e-9 * scale);
  EXPECT_EQ(exact.approximated, 0);
  EXPECT_GT(definite.approximated, 0);
  EXPECT_LE(definite.approximated, static_cast<long>(sys.description().springs.size()));
  // Only K changes; D and the residual do not depend on the request.
  EXPECT_EQ(exact.D, definite.D);
}

TEST(ParticleSystem, DefiniteRequestKeepsStretchedSpringsExact) {
  const ParticleSystem sys(make_rope(small_rope(0.0)));
  State s = sys.initial_state();
  s.q(sys.dimensions()) *= 1.1;  // every spring stretched by 10%
  const Dimensions d = sys.dimensions();
  const Jacobians exact = jacobians_at(sys, s.q(d), s.v(d), false);
  const Jacobians definite = jacobians_at(sys, s.q(d), s.v(d), true);
  EXPECT_EQ(definite.approximated, 0);
  EXPECT_EQ(exact.K, definite.K);
}

#ifdef STIFFSIM_COUNTS_ALLOCATIONS
TEST(ParticleSystem, ForcesAndJacobiansDoNotAllocate) {
  const ParticleSystem sys(make_cloth(small_cloth(1.0)));
  const State s = perturbed_state(sys, 0.05, 10);
  const Dimensions d = sys.dimensions();
  VectorXd F(d.nv);
  ForceJacobians J = sys.jacobian_pattern();
  SparseMatrix M = sys.mass_matrix_pattern();
  const JacobianRequest request{true};
  const std::unique_ptr<SystemData> data = sys.make_data();
  g_allocations = 0;
  g_count_allocations = true;
  sys.forces(*data, 0.0, s.q(d), s.v(d), s.z(d), F);
  sys.force_jacobians(*data, 0.0, s.q(d), s.v(d), s.z(d), request, &J);
  sys.force_jacobians(*data, 0.0, s.q(d), s.v(d), s.z(d), JacobianRequest{false, true}, &J);
  sys.automatic_force_jacobians(*data, 0.0, s.q(d), s.v(d), s.z(d), request, &J);
  sys.mass_matrix(*data, s.q(d), &M);
  g_count_allocations = false;
  EXPECT_EQ(g_allocations.load(), 0);

  // The counter does see allocations made inside the library.
  g_count_allocations = true;
  const std::vector<std::string> names = sys.position_names();
  g_count_allocations = false;
  EXPECT_GT(g_allocations.load(), 0);
}
#endif

// --- Energy ------------------------------------------------------------------

TEST(ParticleSystem, EnergyIsKineticPlusGravityPlusSpringIncludingPinnedNodes) {
  ParticleDescription d = pendulum(10.0, 0.0, 1.0);
  d.positions[0] = Vector3d(0, 0, 1.0);  // pinned node at z = 1: constant m g z
  const ParticleSystem sys(d);
  State s = sys.initial_state();
  s.v(sys.dimensions()) = Vector3d(1, 2, 0);
  const double kinetic = 0.5 * 2.0 * 5.0;
  const double gravity = 3.0 * 9.81 * 1.0 + 2.0 * 9.81 * (-1.5);
  const double spring = 0.5 * 10.0 * (2.5 - 1.0) * (2.5 - 1.0);
  EXPECT_NEAR(sys.energy(s), kinetic + gravity + spring, 1e-12);
}

// dE/dt along the flow (q_dot = v, v_dot = M^-1 F), by central differences of
// E over a step of 1e-6 s; the reference scale is the power v.F exchanged
// between kinetic and potential energy, which must cancel.
double energy_rate(const ParticleSystem& sys, const State& s) {
  const Dimensions d = sys.dimensions();
  SparseMatrix M = sys.mass_matrix_pattern();
  sys.mass_matrix(s.q(d), &M);
  const VectorXd F = forces_at(sys, s.q(d), s.v(d));
  const VectorXd accel = F.cwiseQuotient(MatrixXd(M).diagonal());
  const double h = 1e-6;
  State plus = s, minus = s;
  plus.q(d) += h * s.v(d);
  plus.v(d) += h * accel;
  minus.q(d) -= h * s.v(d);
  minus.v(d) -= h * accel;
  return (sys.energy(plus) - sys.energy(minus)) / (2 * h);
}

TEST(ParticleSystem, EnergyIsConservedAlongTheUndampedFlow) {
  for (const ParticleSystem& sys :
       {ParticleSystem(make_cloth(small_cloth(0.0))), ParticleSystem(make_rope(small_rope(0.0)))}) {
    const State s = perturbed_state(sys, 0.05, 11);
    const Dimensions d = sys.dimensions();
    const double power = std::abs(s.v(d).dot(forces_at(sys, s.q(d), s.v(d))));
    ASSERT_GT(power, 1.0);
    EXPECT_LT(std::abs(energy_rate(sys, s)), 1e-6 * power) << sys.name();
  }
}

TEST(ParticleSystem, EnergyDecaysAtThePowerOfTheNonconservativeForces) {
  const ParticleSystem damped(make_cloth(small_cloth(2.0)));
  const ParticleSystem undamped(make_cloth(small_cloth(0.0)));
  const State s = perturbed_state(damped, 0.05, 12);
  const Dimensions d = damped.dimensions();
  const VectorXd nonconservative =
      forces_at(damped, s.q(d), s.v(d)) - forces_at(undamped, s.q(d), s.v(d));
  const double expected = s.v(d).dot(nonconservative);
  ASSERT_LT(expected, -1.0);  // dampers and drag only take energy out
  EXPECT_NEAR(energy_rate(damped, s), expected, 1e-6 * std::abs(expected));
}

// --- Validation --------------------------------------------------------------

void expect_input_error(const ParticleDescription& d, const std::string& fragment) {
  try {
    ParticleSystem sys(d);
    ADD_FAILURE() << "no InputError, expected one containing '" << fragment << "'";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
  }
}

TEST(ParticleSystem, RejectsInvalidDescriptionsNamingTheComponent) {
  ParticleDescription d = pendulum(10.0, 0.1, 1.0);
  d.name = "cloth";
  {
    auto bad = d;
    bad.pinned = {500};
    expect_input_error(bad, "cloth: pinned node 500 out of range [0, 2)");
  }
  {
    auto bad = d;
    bad.masses[1] = 0.0;
    expect_input_error(bad, "cloth: mass of node 1 must be finite and > 0");
  }
  {
    auto bad = d;
    bad.masses[1] = std::nan("");
    expect_input_error(bad, "mass of node 1");
  }
  {
    auto bad = d;
    bad.positions[1].y() = INFINITY;
    expect_input_error(bad, "cloth: position of node 1 is not finite");
  }
  {
    auto bad = d;
    bad.springs[0].b = 2;
    expect_input_error(bad, "cloth: spring 0: node 2 out of range [0, 2)");
  }
  {
    auto bad = d;
    bad.springs[0].b = 0;
    expect_input_error(bad, "cloth: spring 0: connects node 0 to itself");
  }
  {
    auto bad = d;
    bad.springs[0].k = -1.0;
    expect_input_error(bad, "cloth: spring 0: stiffness k must be finite and >= 0");
  }
  {
    auto bad = d;
    bad.springs[0].c = -0.5;
    expect_input_error(bad, "cloth: spring 0: damping c");
  }
  {
    auto bad = d;
    bad.springs[0].rest_length = -1.0;
    expect_input_error(bad, "cloth: spring 0: rest length");
  }
  {
    auto bad = d;
    bad.masses.pop_back();
    expect_input_error(bad, "cloth: 1 masses given for 2 nodes");
  }
  {
    auto bad = d;
    bad.drag = -1.0;
    expect_input_error(bad, "cloth: drag");
  }
  {
    auto bad = d;
    bad.positions.clear();
    bad.masses.clear();
    expect_input_error(bad, "cloth: has no nodes");
  }
}

// --- Builders ----------------------------------------------------------------

int count_springs_with(const ParticleDescription& d, double k) {
  int n = 0;
  for (const Spring& s : d.springs) n += s.k == k;
  return n;
}

TEST(MakeCloth, SpringCountsMatchTheClosedForm) {
  ClothSpec spec;
  spec.nx = 7;
  spec.ny = 5;
  spec.stretch = SpringParameters{1.0, 0.0};
  spec.shear = SpringParameters{2.0, 0.0};
  spec.bend = SpringParameters{3.0, 0.0};
  const ParticleDescription d = make_cloth(spec);
  const int nx = 7, ny = 5;
  EXPECT_EQ(count_springs_with(d, 1.0), (nx - 1) * ny + nx * (ny - 1));
  EXPECT_EQ(count_springs_with(d, 2.0), 2 * (nx - 1) * (ny - 1));
  EXPECT_EQ(count_springs_with(d, 3.0), (nx - 2) * ny + nx * (ny - 2));
  EXPECT_EQ(d.springs.size(), 58u + 48u + 46u);

  spec.shear.reset();
  spec.bend.reset();
  EXPECT_EQ(make_cloth(spec).springs.size(), 58u);
}

TEST(MakeCloth, GeometryMassesRestLengthsAndDefaultPins) {
  ClothSpec spec;
  spec.nx = 5;
  spec.ny = 3;
  spec.width = 2.0;
  spec.height = 0.5;
  spec.total_mass = 1.5;
  spec.stretch = SpringParameters{1.0, 0.0};
  spec.shear = SpringParameters{1.0, 0.0};
  spec.bend = SpringParameters{1.0, 0.0};
  const ParticleDescription d = make_cloth(spec);
  ASSERT_EQ(d.positions.size(), 15u);
  EXPECT_EQ(d.positions[3 + 5 * 2], Vector3d(1.5, 0.5, 0.0));  // node (3, 2)
  double total = 0;
  for (double m : d.masses) {
    EXPECT_DOUBLE_EQ(m, 0.1);
    total += m;
  }
  EXPECT_NEAR(total, 1.5, 1e-14);
  EXPECT_EQ(d.pinned, (std::vector<int>{10, 14}));
  for (const Spring& s : d.springs) {
    EXPECT_DOUBLE_EQ(s.rest_length, (d.positions[s.b] - d.positions[s.a]).norm());
    EXPECT_GT(s.rest_length, 0.0);
  }
  EXPECT_EQ(d.name, "cloth");
}

TEST(MakeRope, DefaultsPinNodeZeroOnAHorizontalLine) {
  RopeSpec spec;
  spec.nodes = 5;
  spec.length = 2.0;
  spec.total_mass = 0.5;
  spec.stretch = SpringParameters{100.0, 0.1};
  spec.bend = SpringParameters{1.0, 0.0};
  const ParticleDescription d = make_rope(spec);
  EXPECT_EQ(d.pinned, std::vector<int>{0});
  EXPECT_EQ(d.positions[4], Vector3d(2.0, 0.0, 0.0));
  EXPECT_EQ(d.positions[1], Vector3d(0.5, 0.0, 0.0));
  EXPECT_EQ(count_springs_with(d, 100.0), 4);
  EXPECT_EQ(count_springs_with(d, 1.0), 3);
  for (double m : d.masses) EXPECT_DOUBLE_EQ(m, 0.1);
  EXPECT_DOUBLE_EQ(d.springs.back().rest_length, 1.0);
  EXPECT_EQ(d.springs.back().a, 2);
  EXPECT_EQ(d.springs.back().b, 4);
}

template <typename Spec, typename Build>
void expect_builder_error(const Spec& spec, Build build, const std::string& fragment) {
  try {
    build(spec);
    ADD_FAILURE() << "no InputError, expected one containing '" << fragment << "'";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
  }
}

TEST(MakeCloth, RejectsBadParametersNamingComponentAndParameter) {
  ClothSpec good;
  good.name = "sail";
  good.nx = 20;
  good.ny = 20;
  auto expect = [&](auto edit, const std::string& fragment) {
    ClothSpec spec = good;
    edit(spec);
    expect_builder_error(spec, make_cloth, fragment);
  };
  expect([](ClothSpec& s) { s.nx = 1; }, "sail: nodes must be at least [2, 2]");
  expect([](ClothSpec& s) { s.ny = -3; }, "sail: nodes");
  expect([](ClothSpec& s) { s.nx = s.ny = 100000; }, "sail: 10000000000 nodes exceed the limit");
  expect([](ClothSpec& s) { s.width = 0.0; }, "sail: size[0] (width) must be finite and > 0");
  expect([](ClothSpec& s) { s.height = NAN; }, "sail: size[1] (height)");
  expect([](ClothSpec& s) { s.total_mass = -1.0; }, "sail: total_mass must be finite and > 0");
  expect([](ClothSpec& s) { s.stretch = SpringParameters{-1.0, 0.0}; }, "sail: stretch.k");
  expect([](ClothSpec& s) { s.shear = SpringParameters{1.0, -1.0}; }, "sail: shear.c");
  expect([](ClothSpec& s) { s.bend = SpringParameters{INFINITY, 0.0}; }, "sail: bend.k");
  expect([](ClothSpec& s) { s.drag = -0.1; }, "sail: drag");
  expect(
      [](ClothSpec& s) {
        s.pinned = std::vector<int>{0, 500};
      },
      "sail: pinned node 500 out of range [0, 400)");
}

TEST(MakeRope, RejectsBadParametersNamingComponentAndParameter) {
  RopeSpec good;
  auto expect = [&](auto edit, const std::string& fragment) {
    RopeSpec spec = good;
    edit(spec);
    expect_builder_error(spec, make_rope, fragment);
  };
  expect([](RopeSpec& s) { s.nodes = 1; }, "rope: nodes must be at least 2 (got 1)");
  expect([](RopeSpec& s) { s.nodes = 2000000000; }, "rope: 2000000000 nodes exceed the limit");
  expect([](RopeSpec& s) { s.length = -1.0; }, "rope: length must be finite and > 0");
  expect([](RopeSpec& s) { s.total_mass = 0.0; }, "rope: total_mass");
  expect([](RopeSpec& s) { s.bend = SpringParameters{1.0, NAN}; }, "rope: bend.c");
  expect([](RopeSpec& s) { s.pinned = std::vector<int>{-1}; }, "rope: pinned node -1 out of range");
}

// --- Surface meshes ------------------------------------------------------------

// The unit square split along its diagonal 0-2 into triangles (0,1,2), (0,2,3).
TriangleMesh unit_square() {
  TriangleMesh m;
  m.vertices = {Vector3d(0, 0, 0), Vector3d(1, 0, 0), Vector3d(1, 1, 0), Vector3d(0, 1, 0)};
  m.triangles = {{0, 1, 2}, {0, 2, 3}};
  return m;
}

SurfaceMeshSpec square_spec() {
  SurfaceMeshSpec spec;
  spec.name = "sheet";
  spec.mesh = unit_square();
  spec.density = 0.3;
  spec.stretch = SpringParameters{100.0, 0.1};
  spec.bend = SpringParameters{1.0, 0.01};
  return spec;
}

TEST(MakeSurfaceMesh, TwoTrianglesGiveFiveStretchSpringsAndOneBendSpring) {
  const ParticleDescription d = make_surface_mesh(square_spec());
  EXPECT_EQ(count_springs_with(d, 100.0), 5);
  ASSERT_EQ(count_springs_with(d, 1.0), 1);
  const Spring& bend = d.springs.back();
  EXPECT_EQ(std::min(bend.a, bend.b), 1);  // the vertices opposite the diagonal 0-2
  EXPECT_EQ(std::max(bend.a, bend.b), 3);
  EXPECT_DOUBLE_EQ(bend.rest_length, std::sqrt(2.0));
  EXPECT_DOUBLE_EQ(bend.c, 0.01);
}

TEST(MakeSurfaceMesh, MassesAreDensityTimesAThirdOfAdjacentAreas) {
  const ParticleDescription d = make_surface_mesh(square_spec());
  // Vertices 0 and 2 touch both triangles (area 1/2 each), 1 and 3 only one.
  EXPECT_DOUBLE_EQ(d.masses[0], 0.3 * 1.0 / 3.0);
  EXPECT_DOUBLE_EQ(d.masses[1], 0.3 * 0.5 / 3.0);
  EXPECT_DOUBLE_EQ(d.masses[2], 0.3 * 1.0 / 3.0);
  EXPECT_DOUBLE_EQ(d.masses[3], 0.3 * 0.5 / 3.0);
  EXPECT_NEAR(d.masses[0] + d.masses[1] + d.masses[2] + d.masses[3], 0.3, 1e-15);
}

TEST(MakeSurfaceMesh, GridOfQuadsHasOneBendSpringPerInteriorEdge) {
  // n x n vertices, each quad split in two: 3 (n-1)^2 + 2 (n-1) edges, of
  // which 4 (n-1) are on the boundary.
  const int n = 5;
  SurfaceMeshSpec spec = square_spec();
  spec.mesh.vertices.clear();
  spec.mesh.triangles.clear();
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) spec.mesh.vertices.emplace_back(i, j, 0.0);
  }
  for (int j = 0; j + 1 < n; ++j) {
    for (int i = 0; i + 1 < n; ++i) {
      const int a = i + n * j, b = a + 1, c = a + 1 + n, e = a + n;
      spec.mesh.triangles.push_back({a, b, c});
      spec.mesh.triangles.push_back({a, c, e});
    }
  }
  const ParticleDescription d = make_surface_mesh(spec);
  const int edges = 3 * (n - 1) * (n - 1) + 2 * (n - 1);
  EXPECT_EQ(count_springs_with(d, 100.0), edges);
  EXPECT_EQ(count_springs_with(d, 1.0), edges - 4 * (n - 1));
  double total = 0;
  for (double m : d.masses) total += m;
  EXPECT_NEAR(total, 0.3 * (n - 1) * (n - 1), 1e-12);
  EXPECT_NO_THROW(ParticleSystem{d});
}

TEST(MakeSurfaceMesh, RejectsUnreferencedVerticesAndDegenerateTriangles) {
  {
    SurfaceMeshSpec spec = square_spec();
    spec.mesh.vertices.emplace_back(5, 5, 5);
    expect_builder_error(spec, make_surface_mesh,
                         "sheet: vertex 4 (OBJ vertex 5) belongs to no triangle");
  }
  {
    SurfaceMeshSpec spec = square_spec();
    spec.mesh.vertices[3] = Vector3d(2, 2, 0);  // on the line through 0 and 2
    expect_builder_error(spec, make_surface_mesh,
                         "sheet: triangle 1 (vertices 0, 2, 3) has zero area");
  }
  {
    SurfaceMeshSpec spec = square_spec();
    spec.mesh.triangles[1] = {0, 2, 2};
    expect_builder_error(spec, make_surface_mesh, "triangle 1 (vertices 0, 2, 2) has zero area");
  }
  {
    SurfaceMeshSpec spec = square_spec();
    spec.mesh.triangles[1] = {0, 2, 9};
    expect_builder_error(spec, make_surface_mesh,
                         "sheet: triangle 1 (vertices 0, 2, 9): vertex "
                         "index out of range [0, 4)");
  }
  {
    SurfaceMeshSpec spec = square_spec();
    spec.density = 0.0;
    expect_builder_error(spec, make_surface_mesh, "sheet: density must be finite and > 0");
  }
  {
    SurfaceMeshSpec spec = square_spec();
    spec.pinned = {4};
    expect_builder_error(spec, make_surface_mesh, "sheet: pinned node 4 out of range [0, 4)");
  }
  {
    SurfaceMeshSpec spec = square_spec();
    spec.mesh.triangles.clear();
    expect_builder_error(spec, make_surface_mesh, "sheet: mesh has no triangles");
  }
}

// A cloth's bend springs are covered (two collinear stretch springs, 100
// times as stiff and 10 times as damped, span each); its stretch and shear
// springs are not, nor are springs to a pinned node. A bend spring less
// than kCoverageRatio times weaker is not covered either.
TEST(ParticleSystem, CoveredCouplingsAreTheBendSpringsBetweenFreeNodes) {
  ClothSpec spec;
  spec.nx = 5;
  spec.ny = 4;
  spec.stretch = SpringParameters{1.0e3, 0.5};
  spec.shear = SpringParameters{1.0e2, 0.1};
  spec.bend = SpringParameters{10.0, 0.05};
  const ParticleSystem sys(make_cloth(spec));
  std::vector<std::array<int, 2>> expected;
  for (const Spring& s : sys.description().springs) {
    const auto& la = sys.description().lattice[s.a];
    const auto& lb = sys.description().lattice[s.b];
    const bool two_apart = std::abs(la[0] - lb[0]) + std::abs(la[1] - lb[1]) == 2 &&
                           (la[0] == lb[0] || la[1] == lb[1]);
    if (two_apart && sys.dof_of_node(s.a) >= 0 && sys.dof_of_node(s.b) >= 0) {
      expected.push_back({sys.dof_of_node(s.a), sys.dof_of_node(s.b)});
    }
  }
  std::vector<std::array<int, 2>> covered = sys.covered_couplings();
  std::sort(covered.begin(), covered.end());
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(expected.size(), 18u);  // 22 bend springs, 4 of them to a pinned corner
  EXPECT_EQ(covered, expected);

  spec.bend = SpringParameters{2.0e2, 0.05};  // 5 times weaker than stretch
  EXPECT_TRUE(ParticleSystem(make_cloth(spec)).covered_couplings().empty());
  spec.bend = SpringParameters{10.0, 0.1};  // damped 5 times less than stretch
  EXPECT_TRUE(ParticleSystem(make_cloth(spec)).covered_couplings().empty());
}

}  // namespace
}  // namespace stiffsim
