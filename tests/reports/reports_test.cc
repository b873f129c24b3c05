// The pieces the reports are built from: the scenes match the shipped models,
// errors are measured on the right coordinates, runs sample where asked and
// stop on their budget, a run in a process of its own comes back whole with
// its peak memory (or with why it did not), and the fitted exponent is a
// least-squares slope.

#include <gtest/gtest.h>
#include <sys/resource.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "stiffsim/model/urdf.h"
#include "stiffsim/reports/bench_scenes.h"
#include "stiffsim/reports/child_process_run.h"
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

TEST(Reports, RunInAChildProcessComesBackFieldForField) {
  // Made up rather than simulated: a run's Newton decisions follow measured
  // wall time, so two runs of one scene need not agree to the bit.
  MethodRun made;
  made.spec = {"ie", true, 2.5e-3};
  // 40 samples of 6,000 coordinates: 1.9 MB, many times a pipe's buffer.
  for (int k = 0; k < 40; ++k) {
    made.times.push_back(0.005 * (k + 1));
    made.samples.push_back(Eigen::VectorXd::LinSpaced(6000, k, k + 1.0 / 3.0));
  }
  made.wall_seconds = 1.25, made.first_step_wall_seconds = 0.125;
  made.steps = 7, made.newton_iterations = 11, made.factorizations = 3;
  made.newton_failures = 1, made.derivative_evaluations = 19;
  made.stats.factor_nonzeros = 12345, made.stats.krylov_seconds = 0.5;
  made.first_step_stats.steps_taken = 1;
  made.linear_solver = "cholmod-supernodal-llt", made.settings = "rtol 1e-3, atol 1e-5";
  made.over_budget = true, made.message = "over the 30 s budget at t = 0.035";
  made.energy_start = 1.0, made.energy_max = 2.0, made.energy_end = 1.5, made.kinetic_max = 0.75;
  made.non_finite = true;

  const MethodRun back = run_in_child_process([&] { return made; }, {});
  EXPECT_EQ(back.spec.label(), made.spec.label());
  EXPECT_EQ(back.times, made.times);
  ASSERT_EQ(back.samples.size(), made.samples.size());
  for (std::size_t k = 0; k < made.samples.size(); ++k) EXPECT_EQ(back.samples[k], made.samples[k]);
  EXPECT_EQ(back.wall_seconds, made.wall_seconds);
  EXPECT_EQ(back.first_step_wall_seconds, made.first_step_wall_seconds);
  EXPECT_EQ(back.steps, made.steps);
  EXPECT_EQ(back.newton_iterations, made.newton_iterations);
  EXPECT_EQ(back.factorizations, made.factorizations);
  EXPECT_EQ(back.newton_failures, made.newton_failures);
  EXPECT_EQ(back.derivative_evaluations, made.derivative_evaluations);
  // Plain numbers (NaN where unset): byte for byte.
  EXPECT_EQ(std::memcmp(&back.stats, &made.stats, sizeof made.stats), 0);
  EXPECT_EQ(std::memcmp(&back.first_step_stats, &made.first_step_stats, sizeof made.stats), 0);
  EXPECT_EQ(back.linear_solver, made.linear_solver);
  EXPECT_EQ(back.settings, made.settings);
  EXPECT_EQ(back.finished, made.finished);
  EXPECT_EQ(back.over_budget, made.over_budget);
  EXPECT_EQ(back.message, made.message);
  EXPECT_EQ(back.energy_start, made.energy_start);
  EXPECT_EQ(back.energy_max, made.energy_max);
  EXPECT_EQ(back.energy_end, made.energy_end);
  EXPECT_EQ(back.kinetic_max, made.kinetic_max);
  EXPECT_EQ(back.non_finite, made.non_finite);
  EXPECT_GT(back.peak_resident_mb, 0.0);  // measured by this process, not sent
}

TEST(Reports, PeakMemoryOfARunHoldsItsStateMatrixAndFactor) {
  auto run_rope = [](int nodes) {
    return run_in_child_process(
        [nodes] {
          BenchScene s = rope_scene_at_shipped_spacing(nodes, 1e5, 0.005);
          s.sample_period = s.t_final;
          return run_stiffsim(s, {"vie", true, 1e-3}, BenchRunOptions{});
        },
        {});
  };
  const MethodRun tiny = run_rope(10);
  const MethodRun large = run_rope(30000);
  ASSERT_TRUE(tiny.finished) << tiny.message;
  ASSERT_TRUE(large.finished) << large.message;
  // The large run holds at once its state (positions and velocities), the
  // Newton matrix and its factor (8 bytes a value, indices not counted);
  // the tiny one holds next to nothing beyond the pages both share with this
  // process. So the large peak exceeds the tiny one by at least those bytes.
  const double state_bytes = 8.0 * large.samples.back().size();
  const double matrix_bytes =
      8.0 * (large.stats.iteration_matrix_nonzeros + large.stats.factor_nonzeros);
  const double bound_mb = (state_bytes + matrix_bytes) / (1024.0 * 1024.0);
  EXPECT_GT(bound_mb, 10.0);  // the bound says something
  EXPECT_GE(large.peak_resident_mb - tiny.peak_resident_mb, bound_mb)
      << "tiny " << tiny.peak_resident_mb << " MB, large " << large.peak_resident_mb << " MB";
}

TEST(Reports, ChildThatThrowsGivesItsMessage) {
  const MethodRun run = run_in_child_process(
      []() -> MethodRun { throw std::runtime_error("scene file is truncated"); }, {});
  EXPECT_FALSE(run.finished);
  EXPECT_EQ(run.message, "scene file is truncated");
  EXPECT_GT(run.peak_resident_mb, 0.0);
}

TEST(Reports, ChildThatCrashesGivesAFailedRunNamingTheSignal) {
  const MethodRun run = run_in_child_process(
      []() -> MethodRun {
        const rlimit no_core{0, 0};  // nothing to learn from its core file
        setrlimit(RLIMIT_CORE, &no_core);
        std::abort();
      },
      {});
  EXPECT_FALSE(run.finished);
  EXPECT_FALSE(run.over_budget);
  EXPECT_NE(run.message.find("died of signal 6"), std::string::npos) << run.message;
}

TEST(Reports, ChildThatNeverReturnsIsKilledAsOverItsBudget) {
  ChildProcessOptions options;
  options.kill_after_seconds = 0.2;
  const MethodRun run = run_in_child_process(
      []() -> MethodRun {
        for (;;) pause();  // a step that never ends
      },
      options);
  EXPECT_FALSE(run.finished);
  EXPECT_TRUE(run.over_budget);
  EXPECT_NE(run.message.find("killed at its 0.2 s time limit"), std::string::npos) << run.message;
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
