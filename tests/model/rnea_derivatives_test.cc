// The analytic derivatives of the recursive Newton-Euler algorithm and of the
// compliant formulation's bushings against ArticulatedSystem's forward-mode
// automatic differentiation of the same forces, on every joint type and at
// random states; and the claim that computing them allocates nothing.

#include "stiffsim/model/rnea_derivatives.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <atomic>
#include <cstdlib>
#include <random>
#include <stdexcept>
#include <string>

#include "articulated_fixtures.h"
#include "stiffsim/model/compliant.h"
#include "stiffsim/model/forest_derivatives.h"
#include "stiffsim/model/urdf.h"

// Not under AddressSanitizer, whose own malloc a replacement would shadow.
#if defined(__GLIBC__) && !defined(__SANITIZE_ADDRESS__)
// Counts every heap allocation (operator new and Eigen both end in malloc)
// while g_count_allocations is set.
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

struct RandomState {
  Eigen::VectorXd q, v, a;
};

// Uniform coordinates, velocities and accelerations; every quaternion has
// norm `quaternion_norm` (1: a projected state; else a Newton iterate).
RandomState random_state(const ArticulatedSystem& sys, unsigned seed, double quaternion_norm) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Dimensions d = sys.dimensions();
  RandomState s{Eigen::VectorXd(d.nq), Eigen::VectorXd(d.nv), Eigen::VectorXd(d.nv)};
  for (int i = 0; i < d.nq; ++i) s.q[i] = u(rng);
  for (int i = 0; i < d.nv; ++i) s.v[i] = 2.0 * u(rng);
  for (int i = 0; i < d.nv; ++i) s.a[i] = 3.0 * u(rng);
  const auto& bodies = sys.tree().bodies;
  for (int i = 0; i < static_cast<int>(bodies.size()); ++i) {
    if (bodies[i].type != JointType::kFloating) continue;
    auto quat = s.q.segment<4>(sys.body_q_offset(i) + 3);
    quat *= quaternion_norm / quat.norm();
  }
  return s;
}

// max |a - b| / max |b| over the values of two matrices with one pattern.
double relative_difference(const SparseMatrix& a, const SparseMatrix& b) {
  const Eigen::Map<const Eigen::VectorXd> va(a.valuePtr(), a.nonZeros());
  const Eigen::Map<const Eigen::VectorXd> vb(b.valuePtr(), b.nonZeros());
  return (va - vb).cwiseAbs().maxCoeff() / vb.cwiseAbs().maxCoeff();
}

// Both paths evaluate the same derivatives with different roundings: sums of
// O(n) terms no larger than the largest entry, so the difference is a few
// hundred ulps of it at most for these sizes; 1e-10 leaves room and still
// catches any missing term (those are O(1) relative).
constexpr double kTolerance = 1e-10;

struct Jacobians {
  ForceJacobians analytic, automatic;
};

// The analytic Jacobians are the system's: the recursion's terms plus its
// force elements' (joint springs, dampers, drives, bushings).
Jacobians both_jacobians(const ArticulatedSystem& sys, const RandomState& s,
                         bool with_acceleration) {
  JacobianRequest request;
  if (with_acceleration) request.acceleration = s.a.data();
  Jacobians J{sys.jacobian_pattern(), sys.jacobian_pattern()};
  sys.automatic_force_jacobians(0.0, s.q, s.v, Eigen::VectorXd(), request, &J.automatic);
  sys.force_jacobians(0.0, s.q, s.v, Eigen::VectorXd(), request, &J.analytic);
  return J;
}

void expect_matches_automatic(const ArticulatedSystem& sys, const RandomState& s,
                              bool with_acceleration) {
  const Jacobians J = both_jacobians(sys, s, with_acceleration);
  ASSERT_GT(J.automatic.dF_dq.coeffs().cwiseAbs().maxCoeff(), 0.0);
  ASSERT_GT(J.automatic.dF_dv.coeffs().cwiseAbs().maxCoeff(), 0.0);
  EXPECT_LE(relative_difference(J.analytic.dF_dq, J.automatic.dF_dq), kTolerance)
      << sys.name() << (with_acceleration ? " with" : " without") << " acceleration";
  EXPECT_LE(relative_difference(J.analytic.dF_dv, J.automatic.dF_dv), kTolerance)
      << sys.name() << (with_acceleration ? " with" : " without") << " acceleration";
}

// Random states, unit and slightly non-unit quaternions, with and without
// the acceleration term.
void expect_matches_automatic_everywhere(const ArticulatedSystem& sys, unsigned seed) {
  for (double norm : {1.0, 0.97, 1.04}) {
    for (bool with_acceleration : {false, true}) {
      expect_matches_automatic(sys, random_state(sys, seed++, norm), with_acceleration);
    }
  }
}

// A spring (rest 0.2) and a damper on every 1-DOF joint.
std::vector<JointForce> springs_and_dampers(const RigidTree& tree, double k, double c) {
  std::vector<JointForce> f(tree.bodies.size());
  for (std::size_t i = 0; i < f.size(); ++i) {
    if (joint_nv(tree.bodies[i].type) == 1) f[i] = JointForce{k, 0.2, c};
  }
  return f;
}

ArticulatedOptions with_springs(const RigidTree& tree) {
  ArticulatedOptions o;
  o.joint_forces = springs_and_dampers(tree, 30.0, 0.7);
  return o;
}

RigidTree shipped(const std::string& file, bool floating_base) {
  return load_urdf(std::string(STIFFSIM_SOURCE_DIR) + "/models/" + file,
                   UrdfOptions{"", floating_base}, nullptr);
}

// Every joint type below every other: a planar root, a floating joint in
// mid-chain (with a rotated placement: its translation is not along the
// world axes), prismatic and revolute joints below it, and a second branch.
RigidTree mixed_tree() {
  RigidTree t;
  t.name = "mixed";
  auto add = [&](const std::string& name, int parent, JointType type, Eigen::Vector3d axis,
                 Eigen::Vector3d offset, double turn, double mass) {
    TreeBody b;
    b.link = name;
    b.joint = name + "_joint";
    b.parent = parent;
    b.type = type;
    b.axis = axis.normalized();
    b.placement.linear() =
        Eigen::AngleAxisd(turn, Eigen::Vector3d(0.3, -1.0, 0.5).normalized()).toRotationMatrix();
    b.placement.translation() = offset;
    b.inertia.mass = mass;
    b.inertia.com = Eigen::Vector3d(0.03, -0.02, 0.05) * (1.0 + parent);
    const Eigen::Matrix3d R =
        Eigen::AngleAxisd(0.4 + turn, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
    b.inertia.inertia = R * Eigen::Vector3d(0.02, 0.03, 0.045).asDiagonal() * R.transpose();
    b.damping = 0.05;
    t.bodies.push_back(b);
    return static_cast<int>(t.bodies.size()) - 1;
  };
  const int root = add("plate", -1, JointType::kPlanar, {0, 0.2, 1}, {0.1, 0.0, 0.3}, 0.3, 1.2);
  const int arm = add("arm", root, JointType::kRevolute, {1, 0, 0.3}, {0.0, 0.1, 0.2}, -0.4, 0.6);
  const int drone = add("drone", arm, JointType::kFloating, {1, 0, 0}, {0.2, -0.1, 0.1}, 0.7, 0.9);
  const int slide =
      add("slide", drone, JointType::kPrismatic, {0, 1, 1}, {0.0, 0.0, -0.2}, 0.2, 0.4);
  add("tip", slide, JointType::kRevolute, {0, 0, 1}, {0.1, 0.0, 0.0}, 1.1, 0.3);
  add("flap", drone, JointType::kPlanar, {1, 1, 0}, {-0.1, 0.1, 0.0}, -0.6, 0.5);
  add("side", root, JointType::kPrismatic, {1, 0, 0}, {-0.2, 0.0, 0.1}, 0.9, 0.7);
  return t;
}

TEST(RneaDerivatives, ChainsMatchAutomaticDifferentiation) {
  for (int links : {1, 2, 10, 40}) {
    const RigidTree tree = make_chain_tree(links);
    const ArticulatedSystem sys(tree, with_springs(tree));
    expect_matches_automatic_everywhere(sys, 100u + links);
  }
}

TEST(RneaDerivatives, ChainWithoutJointForcesMatchesAutomaticDifferentiation) {
  const ArticulatedSystem sys(make_chain_tree(12), {});
  expect_matches_automatic_everywhere(sys, 7u);
}

TEST(RneaDerivatives, ShippedTreeMatchesAutomaticDifferentiation) {
  // Fixed joints welded, URDF damping, rotated inertial frames, a prismatic
  // slide.
  const RigidTree tree = shipped("tree.urdf", false);
  const ArticulatedSystem sys(tree, with_springs(tree));
  expect_matches_automatic_everywhere(sys, 200u);
}

TEST(RneaDerivatives, FreeBodyMatchesAutomaticDifferentiation) {
  // The shipped box has its centre of mass at its origin: with world linear
  // and body angular velocities neither its gravity, nor its gyroscopic
  // torque, nor its mass matrix depends on its pose, so K is zero (both
  // paths leave rounding noise of a few ulps of F per unit turn) and D must
  // match.
  const RigidTree box = shipped("free_body.urdf", true);
  const ArticulatedSystem sys(box, {});
  for (unsigned seed : {300u, 301u}) {
    for (bool with_acceleration : {false, true}) {
      const RandomState s = random_state(sys, seed, seed == 300u ? 1.0 : 1.05);
      const Jacobians J = both_jacobians(sys, s, with_acceleration);
      Eigen::VectorXd F(sys.dimensions().nv);
      sys.forces(0.0, s.q, s.v, Eigen::VectorXd(), F);
      const double scale = F.cwiseAbs().maxCoeff();
      EXPECT_LE(J.analytic.dF_dq.coeffs().cwiseAbs().maxCoeff(), 1e-12 * scale);
      EXPECT_LE(J.automatic.dF_dq.coeffs().cwiseAbs().maxCoeff(), 1e-12 * scale);
      EXPECT_LE(relative_difference(J.analytic.dF_dv, J.automatic.dF_dv), kTolerance);
    }
  }
  // Off its centre of mass the box's forces depend on its orientation.
  RigidTree offset = box;
  offset.bodies[0].inertia.com = Eigen::Vector3d(0.05, -0.02, 0.1);
  expect_matches_automatic_everywhere(ArticulatedSystem(offset, {}), 310u);
}

TEST(RneaDerivatives, BranchedTreesWithPlanarAndPrismaticJointsMatch) {
  for (bool floating_base : {false, true}) {
    const RigidTree tree = branched_tree(floating_base);
    const ArticulatedSystem sys(tree, with_springs(tree));
    expect_matches_automatic_everywhere(sys, floating_base ? 400u : 500u);
  }
}

TEST(RneaDerivatives, FloatingAndPlanarJointsInsideATreeMatch) {
  ArticulatedOptions o = with_springs(mixed_tree());
  o.gravity = Eigen::Vector3d(1.5, -2.0, -9.0);  // not along an axis of any frame
  const ArticulatedSystem sys(mixed_tree(), o);
  expect_matches_automatic_everywhere(sys, 600u);
}

TEST(RneaDerivatives, QuaternionColumnsVanishAlongTheQuaternion) {
  // The rotation depends on q / |q| only.
  const ArticulatedSystem sys(mixed_tree(), {});
  RneaDerivatives rnea = make_rnea_derivatives(sys);
  const RandomState s = random_state(sys, 700u, 1.1);
  ForceJacobians J = sys.jacobian_pattern();
  rnea.compute(s.q, s.v, nullptr, &J.dF_dq, &J.dF_dv);
  const int qo = sys.body_q_offset(2) + 3;  // the drone's quaternion
  ASSERT_EQ(sys.tree().bodies[2].type, JointType::kFloating);
  const Eigen::MatrixXd K(J.dF_dq);
  const Eigen::VectorXd radial = K.middleCols<4>(qo) * s.q.segment<4>(qo);
  EXPECT_LE(radial.cwiseAbs().maxCoeff(), 1e-12 * K.cwiseAbs().maxCoeff());
}

TEST(RneaDerivatives, RejectsTheCompliantFormulation) {
  const auto compliant = make_compliant(make_chain_tree(3), {}, BushingParameters{});
  EXPECT_THROW(make_rnea_derivatives(*compliant), std::invalid_argument);
}

TEST(RneaDerivatives, RejectsAPatternThatIsNotTheTrees) {
  const ArticulatedSystem sys(make_chain_tree(3), {});
  PatternBuilder diagonal(3, 3);
  diagonal.add_diagonal(0, 3);
  const SparseMatrix P = diagonal.build();
  const RigidTree tree = make_chain_tree(3);
  EXPECT_THROW(RneaDerivatives(tree, body_inertias(tree), Eigen::Vector3d(0, 0, -9.81), P,
                               sys.jacobian_pattern().dF_dv),
               std::invalid_argument);
}

// --- The compliant formulation: bushings between free bodies. ---

// force_jacobians() (analytic for systems with bushings) against the
// automatic path, at one state.
void expect_bushings_match_automatic(const ArticulatedSystem& sys, const RandomState& s,
                                     bool with_acceleration) {
  JacobianRequest request;
  if (with_acceleration) request.acceleration = s.a.data();
  ForceJacobians analytic = sys.jacobian_pattern(), automatic = sys.jacobian_pattern();
  sys.force_jacobians(0.0, s.q, s.v, Eigen::VectorXd(), request, &analytic);
  sys.automatic_force_jacobians(0.0, s.q, s.v, Eigen::VectorXd(), request, &automatic);
  ASSERT_GT(automatic.dF_dq.coeffs().cwiseAbs().maxCoeff(), 0.0);
  ASSERT_GT(automatic.dF_dv.coeffs().cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ(analytic.approximated_terms, 0);
  EXPECT_LE(relative_difference(analytic.dF_dq, automatic.dF_dq), kTolerance)
      << sys.name() << (with_acceleration ? " with" : " without") << " acceleration";
  EXPECT_LE(relative_difference(analytic.dF_dv, automatic.dF_dv), kTolerance)
      << sys.name() << (with_acceleration ? " with" : " without") << " acceleration";
}

void expect_bushings_match_automatic_everywhere(const ArticulatedSystem& sys, unsigned seed) {
  for (double norm : {1.0, 0.97, 1.04}) {
    for (bool with_acceleration : {false, true}) {
      expect_bushings_match_automatic(sys, random_state(sys, seed++, norm), with_acceleration);
    }
  }
}

// Soft enough that no one term (linear, angular, joint spring) hides the
// others' errors in the relative difference.
constexpr BushingParameters kSoftBushings{1e3, 2.0, 1e2, 0.3};

TEST(BushingElements, CompliantChainsMatchAutomaticDifferentiation) {
  // Revolute bushings, the first to the world; joint springs and dampers on
  // the atan2 angle.
  for (int links : {1, 2, 10}) {
    const RigidTree tree = make_chain_tree(links);
    expect_bushings_match_automatic_everywhere(
        *make_compliant(tree, with_springs(tree), kSoftBushings), 900u + links);
  }
  // Without joint forces (the joint spring's branch is skipped) and with the
  // default, stiff bushings.
  expect_bushings_match_automatic_everywhere(
      *make_compliant(make_chain_tree(6), {}, BushingParameters{}), 920u);
}

TEST(BushingElements, RevolutePrismaticAndPlanarBushingsMatch) {
  // branched_tree: revolute, prismatic (with its spring on the offset) and
  // planar joints, rotated placements, off-centre masses; on a floating base
  // the torso's bushing hangs from a free body instead of the world.
  for (bool floating_base : {false, true}) {
    const RigidTree tree = branched_tree(floating_base);
    ArticulatedOptions o = with_springs(tree);
    o.gravity = Eigen::Vector3d(1.5, -2.0, -9.0);
    expect_bushings_match_automatic_everywhere(*make_compliant(tree, o, kSoftBushings),
                                               floating_base ? 940u : 960u);
  }
}

TEST(BushingElements, FreeBodyAmongBushingsMatches) {
  // mixed_tree's floating joint stays a free body without a bushing; its
  // children's bushings hang from it; URDF damping on every joint.
  expect_bushings_match_automatic_everywhere(
      *make_compliant(mixed_tree(), with_springs(mixed_tree()), kSoftBushings), 980u);
}

TEST(BushingElements, QuaternionColumnsVanishAlongTheQuaternion) {
  const auto sys =
      make_compliant(branched_tree(true), with_springs(branched_tree(true)), kSoftBushings);
  const RandomState s = random_state(*sys, 990u, 1.1);
  ForceJacobians J = sys->jacobian_pattern();
  sys->force_jacobians(0.0, s.q, s.v, Eigen::VectorXd(), JacobianRequest{}, &J);
  const Eigen::MatrixXd K(J.dF_dq);
  for (int body = 0; body < static_cast<int>(sys->tree().bodies.size()); ++body) {
    const int qo = sys->body_q_offset(body) + 3;
    const Eigen::VectorXd radial = K.middleCols<4>(qo) * s.q.segment<4>(qo);
    EXPECT_LE(radial.cwiseAbs().maxCoeff(), 1e-12 * K.cwiseAbs().maxCoeff()) << body;
  }
}

TEST(ForestDerivatives, RejectsASystemWithoutBushings) {
  const ArticulatedSystem sys(make_chain_tree(3), {});
  EXPECT_THROW(ForestDerivatives{sys}, std::invalid_argument);
}

#ifdef STIFFSIM_COUNTS_ALLOCATIONS
// Allocations of two force_jacobians() calls (without and with the
// acceleration term) on a data that made its workspaces in a first call.
long steady_jacobian_allocations(const ArticulatedSystem& sys, const RandomState& s) {
  const std::unique_ptr<SystemData> data = sys.make_data();
  ForceJacobians J = sys.jacobian_pattern();
  JacobianRequest with_acceleration;
  with_acceleration.acceleration = s.a.data();
  const Eigen::VectorXd z;
  sys.force_jacobians(*data, 0.0, s.q, s.v, z, JacobianRequest{}, &J);
  g_allocations = 0;
  g_count_allocations = true;
  sys.force_jacobians(*data, 0.0, s.q, s.v, z, JacobianRequest{}, &J);
  sys.force_jacobians(*data, 0.5, s.q, s.v, z, with_acceleration, &J);
  g_count_allocations = false;
  return g_allocations.load();
}

TEST(BushingElements, CompliantJacobiansAllocateNothing) {
  const RigidTree chain = make_chain_tree(30);
  const auto chain_sys = make_compliant(chain, with_springs(chain), kSoftBushings);
  const RigidTree tree = branched_tree(true);
  const auto tree_sys = make_compliant(tree, with_springs(tree), kSoftBushings);
  for (const ArticulatedSystem* sys : {chain_sys.get(), tree_sys.get()}) {
    // The free bodies' derivatives and every bushing element's.
    EXPECT_EQ(steady_jacobian_allocations(*sys, random_state(*sys, 995u, 1.02)), 0) << sys->name();
  }
}
#endif

#ifdef STIFFSIM_COUNTS_ALLOCATIONS
TEST(RneaDerivatives, ComputeAllocatesNothing) {
  const RigidTree chain = make_chain_tree(30);
  const ArticulatedSystem chain_sys(chain, with_springs(chain));
  const RigidTree tree = branched_tree(true);
  const ArticulatedSystem tree_sys(tree, with_springs(tree));
  const ArticulatedSystem mixed_sys(mixed_tree(), {});
  for (const ArticulatedSystem* sys : {&chain_sys, &tree_sys, &mixed_sys}) {
    RneaDerivatives rnea = make_rnea_derivatives(*sys);
    const RandomState s = random_state(*sys, 800u, 1.02);
    ForceJacobians J = sys->jacobian_pattern();
    g_allocations = 0;
    g_count_allocations = true;
    rnea.compute(s.q, s.v, nullptr, &J.dF_dq, &J.dF_dv);
    rnea.compute(s.q, s.v, s.a.data(), &J.dF_dq, &J.dF_dv);
    g_count_allocations = false;
    EXPECT_EQ(g_allocations.load(), 0) << sys->name();
    // The system's analytic Jacobians: the recursion, then the joint
    // springs' and drives' elements.
    EXPECT_EQ(steady_jacobian_allocations(*sys, s), 0) << sys->name() << " (system)";
  }
}
#endif

}  // namespace
}  // namespace stiffsim
