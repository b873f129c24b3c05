// Claims about the extrapolated velocity-implicit Euler ("vie2"): x_e =
// 2 x_small - x_big from the step-doubling pair, checked against closed forms
// and against plain VIE on the same steps.

#include <gtest/gtest.h>

#include <cmath>

#include "stiffsim/integrators/integrator_factory.h"
#include "stiffsim/integrators/runge_kutta45.h"
#include "stiffsim/integrators/velocity_implicit_euler.h"
#include "test_systems.h"

namespace stiffsim {
namespace {

ImplicitSettings extrapolated() {
  ImplicitSettings s;
  s.extrapolate = true;
  return s;
}

TEST(ExtrapolatedVie, GlobalErrorIsSecondOrderWherePlainVieIsFirst) {
  const SpringDamper sd;
  auto sys = sd.system();
  std::vector<double> hs, e1, e2;
  // Four halvings from h = 0.01 (h w0 = 0.1): both errors stay far above
  // the Newton tolerance (accuracy 1e-10) and round-off.
  for (double h = 0.01; h > 0.01 / 17; h /= 2) {
    VelocityImplicitEuler vie(*sys, fixed(h), ImplicitSettings{});
    VelocityImplicitEuler vie2(*sys, fixed(h), extrapolated());
    for (VelocityImplicitEuler* m : {&vie, &vie2}) {
      m->initialize(sys->initial_state());
      m->integrate_to(1.0);
    }
    hs.push_back(h);
    e1.push_back(std::abs(vie.state().x[0] - sd.position(1.0)));
    e2.push_back(std::abs(vie2.state().x[0] - sd.position(1.0)));
  }
  const double slope1 = fitted_slope(hs, e1), slope2 = fitted_slope(hs, e2);
  EXPECT_GT(slope2, 1.8);
  EXPECT_LT(slope2, 2.2);
  EXPECT_GT(slope1, 0.9);
  EXPECT_LT(slope1, 1.1);
  // At the smallest step the second-order result is far ahead.
  EXPECT_LT(100 * e2.back(), e1.back());
}

TEST(ExtrapolatedVie, SecondOrderAtTheShippedAccuracy) {
  // A swinging 10x10 cloth (stretch k = 1e3) over 0.25 s at fixed steps,
  // against RK45 at accuracy 1e-10 (an independent method; its own error is
  // ~1e-12 m). At the shipped accuracy 1e-3 the Newton tolerance of the three
  // solves used to be 5e-5, and the extrapolation amplified those errors
  // into a floor; the extrapolation's own tolerance rule must leave the
  // errors those of exact solves (accuracy 1e-10) and of order 2.
  auto sys = cloth(10, 1e3);
  const double t_final = 0.25;
  const int nq = sys->dimensions().nq;
  IntegratorSettings tight;
  tight.accuracy = 1e-10;
  RungeKutta45 rk45(*sys, tight);
  rk45.initialize(sys->initial_state());
  rk45.integrate_to(t_final);
  const Eigen::VectorXd reference = rk45.state().x.head(nq);
  std::vector<double> hs, errors;
  for (double h : {2e-3, 1e-3, 5e-4}) {
    double e[2];
    int k = 0;
    for (double accuracy : {1e-3, 1e-10}) {
      VelocityImplicitEuler vie2(*sys, fixed(h, false, accuracy), extrapolated());
      vie2.initialize(sys->initial_state());
      vie2.integrate_to(t_final);
      e[k++] = (vie2.state().x.head(nq) - reference).lpNorm<Eigen::Infinity>();
      EXPECT_EQ(vie2.statistics().extrapolation_rejections, 0);
    }
    // The solves' errors must be a small part of the step's error: 10% moves
    // a fitted order by at most 0.15. (Measured: at most 6%; with the
    // tolerance kappa * accuracy of the other methods, 49% at h = 1e-3.)
    EXPECT_NEAR(e[0], e[1], 0.1 * e[1]) << "h = " << h;
    hs.push_back(h);
    errors.push_back(e[0]);
  }
  // Measured slope 1.90 (1.85 at accuracy 1e-10 over these steps: the
  // cloth is not yet fully in the asymptotic range).
  const double slope = fitted_slope(hs, errors);
  EXPECT_GT(slope, 1.8);
  EXPECT_LT(slope, 2.2);
}

TEST(ExtrapolatedVie, DampsTheStiffLinearTestEquation) {
  // y' = lambda y, lambda = -1e6, one step h = 1: z = -1e6 and
  // R(z) = 2 / (1 - z/2)^2 - 1 / (1 - z) = -9.99992e-7. L-stability asks
  // |R| -> 0; the bound is 1e-3.
  const double lambda = -1e6;
  LinearTestSystem sys(lambda);
  VelocityImplicitEuler vie2(sys, fixed(1.0), extrapolated());
  vie2.initialize(sys.initial_state());
  vie2.step_at_most(1.0);
  const double z = lambda * 1.0;
  const double R = 2.0 / ((1 - z / 2) * (1 - z / 2)) - 1.0 / (1 - z);
  const double y1 = vie2.state().x[0];
  EXPECT_LT(std::abs(y1), 1e-3);
  // Newton on a linear equation is exact after one iteration; the step is
  // the stability function to round-off.
  EXPECT_NEAR(y1, R, 1e-12);
}

TEST(ExtrapolatedVie, NeverAmplifiesAnUndampedOscillator) {
  // |R(iy)| <= 1 on the imaginary axis: on an undamped spring (w0 = 10) at
  // h w0 = 1 the energy never grows, though it decays far less than with
  // plain VIE.
  SpringDamper sd;
  sd.c = 0.0;
  auto sys = sd.system();
  VelocityImplicitEuler vie2(*sys, fixed(0.1), extrapolated());
  VelocityImplicitEuler vie(*sys, fixed(0.1), ImplicitSettings{});
  const double e0 = sys->energy(sys->initial_state());
  for (VelocityImplicitEuler* m : {&vie, &vie2}) {
    m->initialize(sys->initial_state());
    double last = e0;
    for (int k = 1; k <= 200; ++k) {
      m->step_at_most(0.1 * k);
      const double e = sys->energy(m->state());
      ASSERT_LE(e, last * (1 + 1e-12)) << m->method_name() << " step " << k;
      last = e;
    }
  }
  EXPECT_GT(sys->energy(vie2.state()), 10 * sys->energy(vie.state()));
}

TEST(ExtrapolatedVie, StiffClothStaysFiniteWithBoundedEnergy) {
  auto sys = cloth(10, 1e6);
  VelocityImplicitEuler vie2(*sys, fixed(1.0 / 60, false, 1e-3), extrapolated());
  vie2.initialize(sys->initial_state());
  const double e0 = sys->energy(sys->initial_state());
  double emax = e0;
  for (int k = 1; k <= 120; ++k) {
    vie2.integrate_to(k / 60.0);
    ASSERT_TRUE(vie2.state().x.allFinite()) << "t = " << vie2.state().t;
    emax = std::max(emax, sys->energy(vie2.state()));
  }
  // The extrapolation is not dissipative step by step as implicit Euler is,
  // but the cloth starts at rest, flat, with zero kinetic and spring energy:
  // the gravitational energy it can give back is bounded by its drop.
  EXPECT_LE(emax, e0 + 1e-3 * std::abs(e0) + 1e-6);
  EXPECT_DOUBLE_EQ(vie2.state().t, 2.0);
}

TEST(ExtrapolatedVie, CostsTheSameNewtonSolvesAsVieWithTheEstimate) {
  auto sys = cloth(8, 1e3);
  VelocityImplicitEuler vie(*sys, fixed(1.0 / 60, true, 1e-3), ImplicitSettings{});
  VelocityImplicitEuler vie2(*sys, fixed(1.0 / 60, false, 1e-3), extrapolated());
  for (VelocityImplicitEuler* m : {&vie, &vie2}) {
    m->initialize(sys->initial_state());
    m->integrate_to(0.5);
  }
  const IntegratorStatistics &a = vie.statistics(), &b = vie2.statistics();
  EXPECT_EQ(a.steps_taken, b.steps_taken);
  EXPECT_EQ(b.newton_solves, 3 * b.steps_taken);
  EXPECT_EQ(a.newton_solves, b.newton_solves);
  EXPECT_GT(b.error_estimator_newton_raphson_iterations, 0);
  EXPECT_TRUE(vie2.report().extrapolated);
  EXPECT_FALSE(vie.report().extrapolated);
  EXPECT_EQ(vie2.method_name(), "vie2");
}

TEST(ExtrapolatedVie, ErrorControlReachesTheAccuracyWithFewerSteps) {
  // The controller sees |x_big - x_small| (a bound for the extrapolated
  // result's error), so at a given accuracy vie2 takes the same kind of
  // steps as vie but lands much closer to the closed form.
  const SpringDamper sd;
  auto sys = sd.system();
  IntegratorSettings s;
  s.max_step = 0.1;
  s.accuracy = 1e-4;
  auto vie = make_integrator("vie", *sys, s, ImplicitSettings{});
  auto vie2 = make_integrator("vie2", *sys, s, ImplicitSettings{});
  for (auto* m : {vie.get(), vie2.get()}) {
    m->initialize(sys->initial_state());
    m->integrate_to(1.0);
  }
  const double e1 = std::abs(vie->state().x[0] - sd.position(1.0));
  const double e2 = std::abs(vie2->state().x[0] - sd.position(1.0));
  EXPECT_LT(10 * e2, e1) << "vie " << e1 << ", vie2 " << e2;
  EXPECT_LT(e2, 1e-3);
}

}  // namespace
}  // namespace stiffsim
