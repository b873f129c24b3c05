// The articulated-body recursion as VIE's Newton step (--newton-solve
// recursive) against the assembled exact Newton matrix: both solve the same
// step equations with the same exact residual, so their trajectories agree
// to the accumulated Newton tolerance; and auto chooses the recursion only
// where it should.

#include <gtest/gtest.h>

#include "../model/articulated_fixtures.h"
#include "stiffsim/error.h"
#include "stiffsim/integrators/implicit_euler.h"
#include "stiffsim/integrators/velocity_implicit_euler.h"
#include "stiffsim/model/articulated.h"
#include "stiffsim/model/compliant.h"

namespace stiffsim {
namespace {

struct Outcome {
  Eigen::VectorXd x;
  IntegratorStatistics stats;
  IntegratorReport report;
};

Outcome run_fixed(const System& system, NewtonSolve solve, double h, double t_final,
                  double accuracy) {
  IntegratorSettings settings;
  settings.fixed_step = true;
  settings.max_step = h;
  settings.accuracy = accuracy;
  ImplicitSettings implicit;
  implicit.newton_solve = solve;
  // The comparison needs both solves at the accuracy's tolerance, not at
  // the fixed step's own error.
  implicit.step_error_tolerance = false;
  VelocityImplicitEuler vie(system, settings, implicit);
  vie.initialize(system.initial_state());
  vie.integrate_to(t_final);
  return {vie.state().x, vie.statistics(), vie.report()};
}

ArticulatedOptions sprung(int joints, double angle) {
  ArticulatedOptions o;
  o.initial_q = Eigen::VectorXd::Constant(joints, angle);
  o.joint_forces.assign(joints, JointForce{1e4, 0.0, 0.5});
  return o;
}

// Each step's solve stops within the Newton tolerance kappa * accuracy of
// the root (weighted by the update sizes); 200 steps of a dissipative chain
// cannot accumulate more than 200 such errors. The runs use a tight
// accuracy so that the bound is far below the motion (0.05 rad).
constexpr double kAccuracy = 1e-8;
constexpr int kSteps = 200;
constexpr double kBound = kSteps * 0.05 * kAccuracy;

TEST(RecursiveNewton, StiffChainMatchesTheAssembledNewtonMatrix) {
  const ArticulatedSystem chain(serial_chain(30), sprung(30, 0.05));
  const Outcome recursive =
      run_fixed(chain, NewtonSolve::kRecursive, 1e-3, kSteps * 1e-3, kAccuracy);
  const Outcome fresh = run_fixed(chain, NewtonSolve::kFresh, 1e-3, kSteps * 1e-3, kAccuracy);
  EXPECT_EQ(recursive.report.newton_solve, "recursive");
  EXPECT_EQ(recursive.stats.step_shrinkages_from_substep_failures, 0);
  EXPECT_GT(recursive.stats.recursive_factorizations, 0);
  EXPECT_EQ(recursive.stats.iteration_matrix_factorizations, 0);
  EXPECT_EQ(recursive.stats.jacobian_evaluations, 0);
  EXPECT_EQ(recursive.stats.mass_matrix_assemblies, 0);
  // The motion is not trivial: the chain moved far more than the bound.
  const Eigen::VectorXd x0 = chain.initial_state().x;
  EXPECT_GT((fresh.x - x0).lpNorm<Eigen::Infinity>(), 1e3 * kBound);
  EXPECT_LT((recursive.x - fresh.x).lpNorm<Eigen::Infinity>(), kBound);
}

TEST(RecursiveNewton, FloatingTreeMatchesTheAssembledNewtonMatrix) {
  // Quaternions (N(q) != I), planar and prismatic joints, a floating base.
  ArticulatedOptions o;
  const ArticulatedSystem tree(branched_tree(true), o);
  const Outcome recursive =
      run_fixed(tree, NewtonSolve::kRecursive, 1e-3, kSteps * 1e-3, kAccuracy);
  const Outcome fresh = run_fixed(tree, NewtonSolve::kFresh, 1e-3, kSteps * 1e-3, kAccuracy);
  EXPECT_GT(recursive.stats.recursive_factorizations, 0);
  EXPECT_GT((fresh.x - tree.initial_state().x).lpNorm<Eigen::Infinity>(), 1e3 * kBound);
  EXPECT_LT((recursive.x - fresh.x).lpNorm<Eigen::Infinity>(), kBound);
}

TEST(RecursiveNewton, AutoTakesItForLargeTreesOnly) {
  const ArticulatedSystem small(serial_chain(100), sprung(100, 0.05));
  const ArticulatedSystem large(serial_chain(300), sprung(300, 0.05));
  EXPECT_EQ(run_fixed(small, NewtonSolve::kAuto, 1e-3, 2e-3, 1e-3).report.newton_solve, "chord");
  EXPECT_EQ(run_fixed(large, NewtonSolve::kAuto, 1e-3, 2e-3, 1e-3).report.newton_solve,
            "recursive");
}

TEST(RecursiveNewton, RefusedWhereItCannotApply) {
  const ArticulatedSystem chain(serial_chain(20), sprung(20, 0.05));
  ImplicitSettings recursive;
  recursive.newton_solve = NewtonSolve::kRecursive;
  EXPECT_THROW(ImplicitEuler(chain, IntegratorSettings{}, recursive), InputError);
  const auto compliant = make_compliant(serial_chain(3), ArticulatedOptions{}, BushingParameters{});
  EXPECT_THROW(VelocityImplicitEuler(*compliant, IntegratorSettings{}, recursive), InputError);
}

}  // namespace
}  // namespace stiffsim
