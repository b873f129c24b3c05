// SUNDIALS CVODE as a peer integrator: the sparse KLU path against closed
// forms and RK45, the dense path on an articulated chain, and the stub when
// stiffsim is built without SUNDIALS.

#include "stiffsim/peers/cvode_peer.h"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <vector>

#include "../integrators/test_systems.h"
#include "../model/articulated_fixtures.h"
#include "stiffsim/integrators/runge_kutta45.h"
#include "stiffsim/model/articulated.h"

namespace stiffsim {
namespace {

[[maybe_unused]] std::vector<double> uniform_times(double t_final, int count) {
  std::vector<double> t;
  for (int i = 1; i <= count; ++i) t.push_back(t_final * i / count);
  return t;
}

#ifdef STIFFSIM_HAVE_CVODE

TEST(CvodePeer, SpringDamperMatchesClosedFormWithKlu) {
  ASSERT_TRUE(cvode_available());
  SpringDamper sd;
  auto sys = sd.system();
  CvodeOptions options;
  options.relative_tolerance = 1e-10;
  options.absolute_tolerance = 1e-12;
  const std::vector<double> times = uniform_times(2.0, 40);
  const PeerRun run = run_cvode(*sys, sys->initial_state(), times, options);
  ASSERT_FALSE(run.failed) << run.message;
  ASSERT_EQ(run.samples.size(), times.size());
  EXPECT_EQ(run.method, "cvode-bdf-klu");
  EXPECT_NE(run.settings.find("KLU"), std::string::npos) << run.settings;
  double worst = 0.0;
  for (std::size_t i = 0; i < times.size(); ++i) {
    EXPECT_DOUBLE_EQ(run.times[i], times[i]);
    worst = std::max(worst, sd.error(State(run.times[i], run.samples[i])));
  }
  EXPECT_LT(worst, 1e-7);
  EXPECT_GT(run.steps, 0);
  EXPECT_GT(run.rhs_evaluations, run.steps);
  EXPECT_GT(run.jacobian_evaluations, 0);
  EXPECT_GT(run.linear_setups, 0);
  EXPECT_GE(run.wall_seconds, 0.0);
  std::printf("spring-damper: max error %.3g, %ld steps, %ld rhs, %ld jac, %ld setups, %.3g s\n  %s\n",
              worst, run.steps, run.rhs_evaluations, run.jacobian_evaluations, run.linear_setups,
              run.wall_seconds, run.settings.c_str());
}

TEST(CvodePeer, ClothAgreesWithRungeKutta45) {
  auto sys = cloth(6, 1000.0);
  const State initial = sys->initial_state();
  const double t_final = 0.2;

  IntegratorSettings settings;
  settings.accuracy = 1e-10;
  settings.max_step = 0.01;
  RungeKutta45 rk(*sys, settings);
  rk.initialize(initial);
  rk.integrate_to(t_final);

  CvodeOptions options;
  options.relative_tolerance = 1e-8;
  options.absolute_tolerance = 1e-10;
  const PeerRun run = run_cvode(*sys, initial, {0.1, t_final}, options);
  ASSERT_FALSE(run.failed) << run.message;
  ASSERT_EQ(run.samples.size(), 2u);
  EXPECT_NE(run.settings.find("KLU"), std::string::npos) << run.settings;
  const Dimensions d = sys->dimensions();
  const double dq = (run.samples[1].head(d.nq) - rk.state().x.head(d.nq)).lpNorm<Eigen::Infinity>();
  const double moved = (rk.state().x.head(d.nq) - initial.x.head(d.nq)).lpNorm<Eigen::Infinity>();
  EXPECT_GT(moved, 1e-2);  // the cloth did fall
  EXPECT_LT(dq, 1e-5);
  std::printf("cloth 6x6: max position difference to RK45 %.3g m, %ld steps, %ld rhs, %ld jac, %.3g s\n",
              dq, run.steps, run.rhs_evaluations, run.jacobian_evaluations, run.wall_seconds);
}

TEST(CvodePeer, DoublePendulumConservesEnergyOnDensePath) {
  ArticulatedOptions opts;
  opts.initial_q = Eigen::Vector2d(0.3, 0.3);
  ArticulatedSystem sys(serial_chain(2), opts);
  const State initial = sys.initial_state();
  CvodeOptions options;
  options.relative_tolerance = 1e-10;
  options.absolute_tolerance = 1e-12;
  const PeerRun run = run_cvode(sys, initial, uniform_times(2.0, 20), options);
  ASSERT_FALSE(run.failed) << run.message;
  ASSERT_EQ(run.samples.size(), 20u);
  EXPECT_EQ(run.method, "cvode-bdf-dense");
  EXPECT_NE(run.settings.find("dense"), std::string::npos) << run.settings;
  const double e0 = sys.energy(initial);
  double worst = 0.0;
  for (std::size_t i = 0; i < run.samples.size(); ++i) {
    worst = std::max(worst, std::abs(sys.energy(State(run.times[i], run.samples[i])) - e0) / std::abs(e0));
  }
  EXPECT_LT(worst, 1e-6);
  std::printf("double pendulum: relative energy drift %.3g, %ld steps, %ld rhs (with DQ Jacobian), "
              "%ld jac, %.3g s\n  %s\n",
              worst, run.steps, run.rhs_evaluations, run.jacobian_evaluations, run.wall_seconds,
              run.settings.c_str());
}

TEST(CvodePeer, FloatingBaseSamplesHaveUnitQuaternions) {
  ArticulatedOptions opts;
  const RigidTree tree = branched_tree(true);
  {
    // Spinning and tumbling: the base quaternion really moves.
    ArticulatedSystem at_rest(tree, opts);
    opts.initial_q = at_rest.initial_state().x.head(at_rest.dimensions().nq);
    opts.initial_v = Eigen::VectorXd::Constant(at_rest.dimensions().nv, 1.5);
  }
  ArticulatedSystem sys(tree, opts);
  ASSERT_TRUE(sys.capabilities().has_quaternions);
  CvodeOptions options;
  options.relative_tolerance = 1e-6;
  options.absolute_tolerance = 1e-8;
  const PeerRun run = run_cvode(sys, sys.initial_state(), {0.05, 0.1}, options);
  ASSERT_FALSE(run.failed) << run.message;
  EXPECT_NE(run.settings.find("quaternion"), std::string::npos) << run.settings;
  for (const Eigen::VectorXd& x : run.samples) {
    Eigen::VectorXd q = x.head(sys.dimensions().nq);
    // Projecting an already projected sample changes nothing measurable.
    Eigen::VectorXd p = q;
    sys.project_positions(p);
    EXPECT_LT((p - q).lpNorm<Eigen::Infinity>(), 1e-14);
  }
  EXPECT_GT((run.samples.back() - sys.initial_state().x).norm(), 1e-2);
}

TEST(CvodePeer, RejectsBadSampleTimes) {
  SpringDamper sd;
  auto sys = sd.system();
  EXPECT_THROW(run_cvode(*sys, sys->initial_state(), {0.2, 0.1}, CvodeOptions{}),
               std::invalid_argument);
  EXPECT_THROW(run_cvode(*sys, sys->initial_state(), {0.0}, CvodeOptions{}), std::invalid_argument);
}

// A system whose forces blow up after t = 0.05: CVODE fails, which comes back
// as failed with the flag and the time, not as an exception.
class ExplodingSpring : public LinearTestSystem {
 public:
  ExplodingSpring() : LinearTestSystem(-1.0) {}
  void misc_derivatives(SystemData& data, double t, const ConstVectorRef& q,
                        const ConstVectorRef& v, const ConstVectorRef& z,
                        VectorRef zdot) const override {
    if (t > 0.05) throw std::runtime_error("exploded");
    LinearTestSystem::misc_derivatives(data, t, q, v, z, zdot);
  }
};

TEST(CvodePeer, FailureIsReportedNotThrown) {
  ExplodingSpring sys;
  const PeerRun run = run_cvode(sys, sys.initial_state(), {0.01, 1.0}, CvodeOptions{});
  EXPECT_TRUE(run.failed);
  EXPECT_EQ(run.samples.size(), 1u);
  EXPECT_NE(run.message.find("CVODE flag CV_"), std::string::npos) << run.message;
  EXPECT_NE(run.message.find("exploded"), std::string::npos) << run.message;
  std::printf("failure message: %s\n", run.message.c_str());
}

#else  // !STIFFSIM_HAVE_CVODE

TEST(CvodePeer, StubWithoutSundials) {
  EXPECT_FALSE(cvode_available());
  SpringDamper sd;
  auto sys = sd.system();
  EXPECT_THROW(run_cvode(*sys, sys->initial_state(), {0.1}, CvodeOptions{}), std::runtime_error);
}

#endif  // STIFFSIM_HAVE_CVODE

TEST(CvodePeer, AvailabilityMatchesBuild) {
#ifdef STIFFSIM_HAVE_CVODE
  EXPECT_TRUE(cvode_available());
#else
  EXPECT_FALSE(cvode_available());
  GTEST_SKIP() << "stiffsim was built without SUNDIALS: the CVODE tests are compiled out";
#endif
}

}  // namespace
}  // namespace stiffsim
