// The pieces the reports are built from: the scenes match the shipped models,
// errors are measured on the right coordinates, runs sample where asked and
// stop on their budget, and the fitted exponent is a least-squares slope.

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "stiffsim/model/urdf.h"
#include "stiffsim/reports/bench_scenes.h"
#include "stiffsim/reports/method_run.h"

namespace stiffsim {
namespace {

TEST(Reports, ChainTreeIsTheShippedChainUrdf) {
  const RigidTree shipped =
      load_urdf(std::string(STIFFSIM_SOURCE_DIR) + "/models/chain_10.urdf", UrdfOptions{"chain", false}, nullptr);
  const RigidTree built = make_chain_tree(10);
  ASSERT_EQ(shipped.bodies.size(), built.bodies.size());
  for (std::size_t i = 0; i < built.bodies.size(); ++i) {
    const TreeBody &a = shipped.bodies[i], &b = built.bodies[i];
    EXPECT_EQ(a.joint, b.joint);
    EXPECT_EQ(a.parent, b.parent);
    EXPECT_TRUE(a.axis.isApprox(b.axis));
    EXPECT_TRUE(a.placement.isApprox(b.placement, 1e-15)) << i;
    EXPECT_DOUBLE_EQ(a.inertia.mass, b.inertia.mass);
    EXPECT_TRUE(a.inertia.com.isApprox(b.inertia.com));
    EXPECT_TRUE(a.inertia.inertia.isApprox(b.inertia.inertia, 1e-12));
  }
}

TEST(Reports, FittedExponentIsTheLogLogSlope) {
  std::vector<double> x, y;
  for (double n : {1e3, 1e4, 1e5}) {
    x.push_back(n);
    y.push_back(3e-7 * std::pow(n, 1.07));
  }
  EXPECT_NEAR(fitted_exponent(x, y), 1.07, 1e-12);
}

TEST(Reports, RunsSampleAtTheSceneTimesAndErrorsSkipQuaternions) {
  BenchScene s = compliant_chain_scene(3, 0.1, 1e4, 1e2, 0.1);
  s.sample_period = 0.025;
  BenchRunOptions o;
  const MethodRun a = run_stiffsim(s, {"vie", true, 1e-3}, o);
  ASSERT_TRUE(a.finished) << a.message;
  ASSERT_EQ(a.times.size(), 4u);
  EXPECT_NEAR(a.times.back(), 0.1, 1e-15);
  MethodRun b = a;
  // A change in a quaternion entry is not a position error; one in x is.
  b.samples[2][3] += 0.5;
  EXPECT_EQ(max_position_error(*s.scene, b, a), 0.0);
  b.samples[2][0] += 0.25;
  EXPECT_EQ(max_position_error(*s.scene, b, a), 0.25);
  // A run that stopped early has no error to report.
  b.times.pop_back();
  EXPECT_EQ(max_position_error(*s.scene, b, a), std::numeric_limits<double>::infinity());
}

TEST(Reports, BudgetStopsARunAndSaysSo) {
  BenchScene s = cloth_scene(12, 1e3, 100.0);
  BenchRunOptions o;
  o.wall_budget_seconds = 0.05;
  const MethodRun run = run_stiffsim(s, {"rk45", false, 1e-10}, o);
  EXPECT_FALSE(run.finished);
  EXPECT_TRUE(run.over_budget);
  EXPECT_NE(run.message.find("budget"), std::string::npos);
}

TEST(Reports, ExplicitBlowUpIsAClearFailureNotAFinishedRun) {
  BenchScene s = cloth_scene(6, 1e6, 0.5);
  const MethodRun run = run_stiffsim(s, {"semi-explicit-euler", true, 1e-2}, BenchRunOptions{});
  EXPECT_FALSE(run.finished);
  EXPECT_FALSE(run.non_finite);
  EXPECT_NE(run.message.find("semi-explicit-euler"), std::string::npos) << run.message;
}

}  // namespace
}  // namespace stiffsim
