// The per-step hot path of VIE allocates nothing once its workspaces are
// sized: checked by counting malloc calls while a cloth is stepped.

#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>

#include "../model/articulated_fixtures.h"
#include "stiffsim/integrators/velocity_implicit_euler.h"
#include "stiffsim/model/articulated.h"
#include "stiffsim/model/compliant.h"
#include "stiffsim/model/particle_meshes.h"
#include "stiffsim/model/particles.h"
#include "stiffsim/scene.h"

// Not under AddressSanitizer, whose own malloc a replacement would shadow.
#if defined(__GLIBC__) && !defined(__SANITIZE_ADDRESS__)
extern "C" void* __libc_malloc(size_t size);
static std::atomic<bool> g_counting{false};
static std::atomic<long> g_allocations{0};
extern "C" void* malloc(size_t size) {
  if (g_counting.load(std::memory_order_relaxed)) ++g_allocations;
  return __libc_malloc(size);
}

namespace stiffsim {
namespace {

long allocations_while_stepping(bool error_estimate) {
  ClothSpec spec;
  spec.nx = spec.ny = 6;  // 102 DOFs on the dense LDLT path, which allocates nothing either
  spec.total_mass = 0.4;
  spec.stretch = SpringParameters{1e3, 0.5};
  spec.shear = SpringParameters{1e2, 0.1};
  spec.bend = SpringParameters{10.0, 0.05};
  const ParticleSystem cloth(make_cloth(spec));
  IntegratorSettings settings;
  settings.fixed_step = true;
  settings.max_step = 1.0 / 240;
  settings.error_estimate = error_estimate;
  // Asked for: auto takes CHOLMOD for so sparse a pattern (29% of
  // entries), whose numeric factorization allocates inside the library.
  ImplicitSettings dense;
  dense.linear_solver = LinearSolverKind::kDenseLDLT;
  VelocityImplicitEuler vie(cloth, settings, dense);
  vie.initialize(cloth.initial_state());
  vie.integrate_to(0.25);  // warm-up: every workspace sized, solver analyzed
  g_allocations = 0;
  g_counting = true;
  vie.integrate_to(0.5);
  g_counting = false;
  EXPECT_GT(vie.statistics().newton_raphson_iterations, 0);
  return g_allocations.load();
}

TEST(VieAllocation, FixedStepAllocatesNothing) { EXPECT_EQ(allocations_while_stepping(false), 0); }

TEST(VieAllocation, StepWithErrorEstimateAllocatesNothing) {
  EXPECT_EQ(allocations_while_stepping(true), 0);
}

// The Krylov path: GMRES on the exact Jacobian (the Krylov basis, the
// residuals of its matrix-free products and of the line search, the chord
// test) of a rope large enough for CHOLMOD
// (300 DOFs). CHOLMOD's own numeric factorization allocates its workspace
// inside the library, so the window counted is one without a
// factorization (asserted), at a step where the first one stays a good
// preconditioner.
TEST(VieAllocation, KrylovPathAllocatesNothing) {
  RopeSpec spec;
  spec.nodes = 101;
  spec.total_mass = 0.1;
  spec.stretch = SpringParameters{1e3, 0.1};
  spec.bend = SpringParameters{1.0, 0.01};
  const ParticleSystem rope(make_rope(spec));
  IntegratorSettings settings;
  settings.fixed_step = true;
  settings.max_step = 1e-4;
  ImplicitSettings krylov;
  krylov.newton_solve = NewtonSolve::kKrylov;
  VelocityImplicitEuler vie(rope, settings, krylov);
  vie.initialize(rope.initial_state());
  vie.integrate_to(0.01);
  const long factorizations = vie.statistics().iteration_matrix_factorizations;
  const long krylov_solves = vie.statistics().krylov_solves;
  g_allocations = 0;
  g_counting = true;
  vie.integrate_to(0.02);
  g_counting = false;
  const IntegratorStatistics& st = vie.statistics();
  EXPECT_GT(st.krylov_solves, krylov_solves);
  EXPECT_EQ(st.iteration_matrix_factorizations, factorizations);
  EXPECT_EQ(g_allocations.load(), 0);
}

// Articulated systems evaluate into their Data workspace: steps of an exact
// chain (the articulated-body recursion), of a branched tree on a floating
// base (quaternions, N(q) != I) and of a compliant chain (assembled sparse
// matrix, seeded automatic differentiation) allocate nothing once warm.
long allocations_stepping(const System& system, const ImplicitSettings& implicit, double h,
                          double warm_up, double t_final, IntegratorStatistics* stats) {
  IntegratorSettings settings;
  settings.fixed_step = true;
  settings.max_step = h;
  VelocityImplicitEuler vie(system, settings, implicit);
  vie.initialize(system.initial_state());
  vie.integrate_to(warm_up);
  g_allocations = 0;
  g_counting = true;
  vie.integrate_to(t_final);
  g_counting = false;
  *stats = vie.statistics();
  return g_allocations.load();
}

TEST(VieAllocation, ExactChainOnTheRecursionAllocatesNothing) {
  ArticulatedOptions o;
  o.initial_q = Eigen::VectorXd::Constant(40, 0.05);
  o.joint_forces.assign(40, JointForce{1e4, 0.0, 0.1});
  const ArticulatedSystem chain(serial_chain(40), o);
  ImplicitSettings recursive;
  recursive.newton_solve = NewtonSolve::kRecursive;
  IntegratorStatistics st;
  EXPECT_EQ(allocations_stepping(chain, recursive, 1e-3, 0.01, 0.03, &st), 0);
  EXPECT_GT(st.recursive_factorizations, 0);
  EXPECT_EQ(st.iteration_matrix_factorizations, 0);
  EXPECT_EQ(st.mass_matrix_assemblies, 0);  // residuals by inverse dynamics
}

TEST(VieAllocation, FloatingTreeOnTheRecursionAllocatesNothing) {
  ArticulatedOptions o;
  const ArticulatedSystem tree(branched_tree(true), o);
  ImplicitSettings recursive;
  recursive.newton_solve = NewtonSolve::kRecursive;
  IntegratorStatistics st;
  EXPECT_EQ(allocations_stepping(tree, recursive, 1e-3, 0.01, 0.03, &st), 0);
  EXPECT_GT(st.recursive_factorizations, 0);
}

TEST(VieAllocation, CompliantChainAllocatesNothing) {
  ArticulatedOptions o;
  o.initial_q = Eigen::VectorXd::Constant(8, 0.2);
  const auto chain = make_compliant(serial_chain(8), o, BushingParameters{1e5, 10.0, 1e3, 0.1});
  // A fresh Jacobian (seeded forward mode) and dense factorization at every
  // iterate, so the window surely contains both.
  ImplicitSettings fresh;
  fresh.newton_solve = NewtonSolve::kFresh;
  IntegratorStatistics st;
  EXPECT_EQ(allocations_stepping(*chain, fresh, 1e-3, 0.01, 0.03, &st), 0);
  EXPECT_GT(st.jacobian_evaluations, 20);
}

// What the CLI steps: a Scene. Two ropes under gravity, the second hanging
// from the first's free end by an attachment: the scene splits forces,
// Jacobians and the energy guard's energies over its components and adds
// the coupling blocks, all into workspaces sized once.
TEST(VieAllocation, SceneOfTiedRopesAllocatesNothing) {
  auto rope = [](const char* name, const Eigen::Vector3d& origin, bool pinned) {
    RopeSpec spec;
    spec.name = name;
    spec.nodes = 12;
    spec.total_mass = 0.05;
    spec.stretch = SpringParameters{1e3, 0.1};
    spec.bend = SpringParameters{1.0, 0.01};
    spec.origin = origin;
    if (!pinned) spec.pinned = std::vector<int>{};
    return std::make_unique<ParticleSystem>(make_rope(spec));
  };
  std::vector<std::unique_ptr<System>> parts;
  parts.push_back(rope("upper", Eigen::Vector3d::Zero(), true));
  parts.push_back(rope("lower", Eigen::Vector3d(1.0, 0.0, 0.0), false));
  std::vector<Attachment> tie = {
      {"tie", {0, 11, Eigen::Vector3d::Zero()}, {1, 0, Eigen::Vector3d::Zero()}, 1e3, 0.1}};
  const Scene scene("tied ropes", std::move(parts), std::move(tie));
  IntegratorStatistics st;
  EXPECT_EQ(allocations_stepping(scene, ImplicitSettings{}, 1e-3, 0.02, 0.05, &st), 0);
  EXPECT_GT(st.newton_raphson_iterations, 30);
}

// A rope hanging from a link of a floating tree: the attachment's point
// kinematics run through the floating joint (its quaternion's columns) at
// every force and Jacobian evaluation, into the scene's reserved scratch.
TEST(VieAllocation, RopeOnAFloatingTreeAllocatesNothing) {
  std::vector<std::unique_ptr<System>> parts;
  parts.push_back(std::make_unique<ArticulatedSystem>(branched_tree(true), ArticulatedOptions{}));
  RopeSpec spec;
  spec.name = "rope";
  spec.nodes = 8;
  spec.total_mass = 0.05;
  spec.stretch = SpringParameters{1e3, 0.1};
  spec.bend = SpringParameters{1.0, 0.01};
  spec.pinned = std::vector<int>{7};
  parts.push_back(std::make_unique<ParticleSystem>(make_rope(spec)));
  const int leaf = parts[0]->point_elements() - 1;
  std::vector<Attachment> grip = {{"grip",
                                   {0, leaf, Eigen::Vector3d(0.05, 0.0, 0.0)},
                                   {1, 0, Eigen::Vector3d::Zero()},
                                   1e3,
                                   0.5}};
  const Scene scene("rope on a tree", std::move(parts), std::move(grip));
  IntegratorStatistics st;
  EXPECT_EQ(allocations_stepping(scene, ImplicitSettings{}, 1e-3, 0.02, 0.05, &st), 0);
  EXPECT_GT(st.newton_raphson_iterations, 30);
}

TEST(VieAllocation, CounterSeesAllocations) {
  g_allocations = 0;
  g_counting = true;
  void* p = std::malloc(64);
  g_counting = false;
  std::free(p);
  EXPECT_EQ(g_allocations.load(), 1);
}

}  // namespace
}  // namespace stiffsim
#endif
