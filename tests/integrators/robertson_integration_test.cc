// The implicit integrators on a pure first-order stiff system (nq = nv = 0):
// Robertson's chemical kinetics against its published solution.

#include <gtest/gtest.h>

#include <cmath>

#include "stiffsim/integrators/implicit_euler.h"
#include "stiffsim/integrators/integrator_factory.h"
#include "stiffsim/integrators/velocity_implicit_euler.h"
#include "stiffsim/model/robertson.h"
#include "test_systems.h"

namespace stiffsim {
namespace {

struct RobertsonCase {
  const char* method;
  double accuracy;
};

class RobertsonTo40 : public ::testing::TestWithParam<RobertsonCase> {};

TEST_P(RobertsonTo40, MatchesThePublishedSolutionAndConservesMass) {
  // Reference values at t = 40 (Hairer & Wanner, "Solving ODEs II", and
  // every stiff-solver test set): y1 = 0.7158, y3 = 0.2842 to four digits.
  RobertsonSystem sys;
  IntegratorSettings s;
  s.max_step = 40.0;
  s.initial_step = 1e-6;
  s.accuracy = GetParam().accuracy;
  ImplicitSettings implicit;
  implicit.error_estimator = ImplicitErrorEstimate::kStepDoubling;
  auto integrator = make_integrator(GetParam().method, sys, s, implicit);
  integrator->initialize(sys.initial_state());
  integrator->integrate_to(40.0);
  const Eigen::VectorXd& y = integrator->state().x;
  ASSERT_EQ(y.size(), 3);
  EXPECT_NEAR(y[0] / 0.7158, 1.0, 1e-3) << "y1 = " << y[0];
  EXPECT_NEAR(y[2] / 0.2842, 1.0, 1e-3) << "y3 = " << y[2];
  // Every Newton update keeps 1^T y: 1^T f = 0, so the columns of
  // I - h df/dy sum to 1 and 1^T dy = -1^T r = 0 up to round-off.
  EXPECT_NEAR(y.sum(), 1.0, 1e-10);
  // The stiff part costs the implicit methods nothing: a few hundred steps,
  // where an explicit method needs ~ 40 / 1e-3.
  EXPECT_LT(integrator->statistics().steps_taken, 2000);
}

// The accuracy bounds each step's local error. The first-order methods
// accumulate theirs over the run: at 1e-4 they end 1.6e-3 (y1) and 4.2e-3
// (y3) away from the reference, at 1e-5 still 1.5e-3 on y3; 2e-6 brings them
// inside 1e-3 (364 steps). The extrapolated methods reach it at 1e-4.
INSTANTIATE_TEST_SUITE_P(Implicit, RobertsonTo40,
                         ::testing::Values(RobertsonCase{"vie", 2e-6}, RobertsonCase{"ie", 2e-6},
                                           RobertsonCase{"vie2", 1e-4},
                                           RobertsonCase{"ie2", 1e-4}));

TEST(Robertson, VieWithHalfStepsEqualsTwoIeSteps) {
  // With nq = nv = 0 both methods are implicit Euler on z; VIE with its
  // estimate propagates two half steps.
  RobertsonSystem sys;
  ImplicitSettings implicit;
  implicit.max_newton_iterations = 100;
  const double h = 1e-2;
  VelocityImplicitEuler vie(sys, fixed(h, true, 1e-10), implicit);
  ImplicitEuler ie(sys, fixed(h / 2, false, 1e-10), implicit);
  vie.initialize(sys.initial_state());
  ie.initialize(sys.initial_state());
  vie.step_at_most(h);
  ie.integrate_to(h);
  EXPECT_EQ(ie.statistics().steps_taken, 2);
  // Both stop where eta |dy| <= 0.05 * 1e-10 (absolute): 1e-11 apart at most.
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(vie.state().x[i], ie.state().x[i], 1e-11) << "y" << i + 1;
  }
  EXPECT_GT(ie.state().x[2], 1e-7);  // the comparison is not between zeros
}

}  // namespace
}  // namespace stiffsim
