// PD joint drives (JointDrive in articulated.h) against closed forms: the
// damped oscillator of one driven joint, a ramp the drive tracks exactly,
// the drive's stiffness and damping in K and D, and an implicit step that
// holds a drive at gains where the explicit one diverges.

#include <gtest/gtest.h>

#include <cmath>

#include "stiffsim/error.h"
#include "stiffsim/integrators/runge_kutta45.h"
#include "stiffsim/integrators/semi_explicit_euler.h"
#include "stiffsim/integrators/velocity_implicit_euler.h"
#include "stiffsim/model/articulated.h"
#include "stiffsim/model/path.h"

namespace stiffsim {
namespace {

ArticulatedSystem driven_chain(int links, double kp, double kd, ScalarPath target,
                               Eigen::Vector3d gravity = Eigen::Vector3d::Zero()) {
  ArticulatedOptions o;
  o.gravity = gravity;
  for (int i = 0; i < links; ++i) o.drives.push_back(JointDrive{i, kp, kd, target});
  return ArticulatedSystem(make_chain_tree(links), o);
}

double joint_inertia(const ArticulatedSystem& sys) {
  SparseMatrix M = sys.mass_matrix_pattern();
  sys.mass_matrix(Eigen::VectorXd::Zero(1), &M);
  return Eigen::MatrixXd(M)(0, 0);
}

TEST(ScalarPath, KeyframesInterpolateAndHoldTheirEnds) {
  const ScalarPath p = ScalarPath::keyframes({0.0, 1.0, 3.0}, {0.0, 2.0, 1.0}, "test");
  EXPECT_DOUBLE_EQ(p.value(-1.0), 0.0);
  EXPECT_DOUBLE_EQ(p.value(0.5), 1.0);
  EXPECT_DOUBLE_EQ(p.rate(0.5), 2.0);
  EXPECT_DOUBLE_EQ(p.value(2.0), 1.5);
  EXPECT_DOUBLE_EQ(p.rate(2.0), -0.5);
  EXPECT_DOUBLE_EQ(p.value(4.0), 1.0);
  EXPECT_DOUBLE_EQ(p.rate(4.0), 0.0);
  EXPECT_DOUBLE_EQ(p.rate(-1.0), 0.0);
  // The rate is the derivative of the value (central differences).
  const ScalarPath s = ScalarPath::sinusoid(0.1, 0.3, 2.0, 0.4, "test");
  for (double t : {0.0, 0.13, 0.71}) {
    const double d = 1e-6;
    EXPECT_NEAR(s.rate(t), (s.value(t + d) - s.value(t - d)) / (2 * d), 1e-6);
  }
  EXPECT_THROW(ScalarPath::keyframes({0.0, 0.0}, {1.0, 2.0}, "test"), InputError);
  EXPECT_THROW(ScalarPath::keyframes({}, {}, "test"), InputError);
}

TEST(JointDrive, OneJointFollowsTheDampedOscillatorClosedForm) {
  // No gravity: I q'' = kp (q* - q) - kd q', from rest at q = 0.
  const double kp = 40.0, kd = 0.05, target = 0.3;
  const ArticulatedSystem sys = driven_chain(1, kp, kd, ScalarPath::constant(target));
  const double I = joint_inertia(sys);
  const double w0 = std::sqrt(kp / I), zeta = kd / (2.0 * std::sqrt(kp * I));
  ASSERT_LT(zeta, 1.0);
  const double wd = w0 * std::sqrt(1.0 - zeta * zeta);
  IntegratorSettings tight;
  tight.accuracy = 1e-11;
  RungeKutta45 rk45(sys, tight);
  rk45.initialize(sys.initial_state());
  for (double t : {0.05, 0.2, 0.5}) {
    rk45.integrate_to(t);
    const double closed = target - target * std::exp(-zeta * w0 * t) *
                                       (std::cos(wd * t) + zeta * w0 / wd * std::sin(wd * t));
    EXPECT_NEAR(rk45.state().x[0], closed, 1e-8) << "t = " << t;
  }
}

TEST(JointDrive, ImplicitStepTracksARampExactly) {
  // Started on the ramp p(t) = t with its velocity, the drive's torque is
  // kp (t - q) + kd (1 - v) = 0 along q = t: a step that evaluates the
  // target at the end of the step (as the implicit step must) stays on it.
  const ScalarPath ramp = ScalarPath::keyframes({0.0, 1.0}, {0.0, 1.0}, "ramp");
  const ArticulatedSystem sys = driven_chain(1, 1e5, 50.0, ramp);
  State s = sys.initial_state();
  s.x[1] = 1.0;
  IntegratorSettings settings;
  settings.fixed_step = true;
  settings.max_step = 0.01;
  VelocityImplicitEuler vie(sys, settings, ImplicitSettings{});
  vie.initialize(s);
  vie.integrate_to(0.5);
  EXPECT_NEAR(vie.state().x[0], 0.5, 1e-9);
  EXPECT_NEAR(vie.state().x[1], 1.0, 1e-9);
}

TEST(JointDrive, GainsAppearInKAndD) {
  // dF/dq and dF/dv of a driven chain differ from the undriven one's by
  // -kp and -kd on the driven joints' diagonal, and the analytic Jacobians
  // equal the automatic ones.
  const Eigen::Vector3d g(0.0, 0.0, -9.81);
  const double kp = 250.0, kd = 3.0;
  ArticulatedOptions plain;
  plain.gravity = g;
  ArticulatedOptions driven = plain;
  driven.drives.push_back(JointDrive{1, kp, kd, ScalarPath::sinusoid(0.2, 0.1, 1.0, 0.0, "p")});
  driven.drives.push_back(JointDrive{3, kp, kd, ScalarPath::constant(-0.4)});
  plain.initial_q = driven.initial_q = Eigen::VectorXd::LinSpaced(5, -0.5, 0.7);
  const ArticulatedSystem a(make_chain_tree(5), plain), b(make_chain_tree(5), driven);
  const Eigen::VectorXd q = plain.initial_q, v = Eigen::VectorXd::LinSpaced(5, 1.0, -2.0);
  const Eigen::VectorXd z;
  ForceJacobians Ja = a.jacobian_pattern(), Jb = b.jacobian_pattern(), Jauto = b.jacobian_pattern();
  a.force_jacobians(0.3, q, v, z, JacobianRequest{}, &Ja);
  b.force_jacobians(0.3, q, v, z, JacobianRequest{}, &Jb);
  b.automatic_force_jacobians(0.3, q, v, z, JacobianRequest{}, &Jauto);
  Eigen::MatrixXd dK = Eigen::MatrixXd(Jb.dF_dq) - Eigen::MatrixXd(Ja.dF_dq);
  Eigen::MatrixXd dD = Eigen::MatrixXd(Jb.dF_dv) - Eigen::MatrixXd(Ja.dF_dv);
  Eigen::MatrixXd expected_K = Eigen::MatrixXd::Zero(5, 5), expected_D = expected_K;
  expected_K(1, 1) = expected_K(3, 3) = -kp;
  expected_D(1, 1) = expected_D(3, 3) = -kd;
  EXPECT_LT((dK - expected_K).norm(), 1e-9 * kp);
  EXPECT_LT((dD - expected_D).norm(), 1e-9 * kp);
  EXPECT_LT((Eigen::MatrixXd(Jb.dF_dq) - Eigen::MatrixXd(Jauto.dF_dq)).norm(), 1e-10 * kp);
  EXPECT_LT((Eigen::MatrixXd(Jb.dF_dv) - Eigen::MatrixXd(Jauto.dF_dv)).norm(), 1e-10 * kp);
  // The torque itself: F_driven - F_plain = kp (p(t) - q) + kd (p'(t) - v).
  Eigen::VectorXd Fa(5), Fb(5);
  const double t = 0.3;
  a.forces(t, q, v, z, Fa);
  b.forces(t, q, v, z, Fb);
  const ScalarPath& p1 = driven.drives[0].target;
  EXPECT_NEAR(Fb[1] - Fa[1], kp * (p1.value(t) - q[1]) + kd * (p1.rate(t) - v[1]), 1e-9 * kp);
  EXPECT_NEAR(Fb[3] - Fa[3], kp * (-0.4 - q[3]) + kd * (0.0 - v[3]), 1e-9 * kp);
  EXPECT_NEAR(Fb[0] - Fa[0], 0.0, 1e-12);
  EXPECT_FALSE(b.capabilities().passive);
  EXPECT_TRUE(a.capabilities().passive);
}

// energy() counts each drive's spring about its target: with constant
// targets the implicit step may only dissipate it.
double driven_energy(const ArticulatedSystem& sys, const State& s) {
  double springs = 0.0;
  for (const JointDrive& d : sys.options().drives) {
    const double dq = s.x[sys.body_q_offset(d.body)] - d.target.value(s.t);
    springs += 0.5 * d.kp * dq * dq;
  }
  State still = s;
  still.x.tail(sys.dimensions().nv).setZero();
  ArticulatedOptions undriven = sys.options();
  undriven.drives.clear();
  undriven.initial_q = s.x.head(sys.dimensions().nq);
  const ArticulatedSystem plain(sys.tree(), undriven);
  // The drive's share of energy() is exactly its springs.
  EXPECT_NEAR(sys.energy(still) - plain.energy(still), springs, 1e-9 * (1.0 + springs));
  return sys.energy(s);
}

TEST(JointDrive, ImplicitStepHoldsAStiffDriveTheExplicitStepCannot) {
  // chain_10 under gravity, every joint driven to 0.2 rad at kp = 1e6
  // (h sqrt(kp / I) of order 100 at h = 5 ms, far outside the explicit
  // step's stability bound of 2).
  const ArticulatedSystem sys =
      driven_chain(10, 1e6, 10.0, ScalarPath::constant(0.2), Eigen::Vector3d(0, 0, -9.81));
  IntegratorSettings settings;
  settings.fixed_step = true;
  settings.max_step = 5e-3;
  VelocityImplicitEuler vie(sys, settings, ImplicitSettings{});
  vie.initialize(sys.initial_state());
  double previous = driven_energy(sys, vie.state());
  while (vie.state().t < 1.0 - 1e-12) {
    vie.step_at_most(1.0);
    const double e = driven_energy(sys, vie.state());
    ASSERT_LE(e, previous + 1e-9 * std::abs(previous)) << "t = " << vie.state().t;
    previous = e;
  }
  EXPECT_EQ(vie.statistics().substep_failures, 0);
  // Gravity's torque at the root (10 links of 0.1 kg, centre 0.5 m down)
  // deflects it by about 0.5 N m / kp = 5e-7 rad.
  for (int i = 0; i < 10; ++i) EXPECT_NEAR(vie.state().x[i], 0.2, 1e-5) << "joint " << i;
  SemiExplicitEuler explicit_euler(sys, settings);
  explicit_euler.initialize(sys.initial_state());
  EXPECT_THROW(explicit_euler.integrate_to(1.0), IntegrationError);
}

TEST(JointDrive, InvalidDrivesAreRejected) {
  ArticulatedOptions o;
  o.drives.push_back(JointDrive{0, -1.0, 0.0, ScalarPath::constant(0.0)});
  EXPECT_THROW(ArticulatedSystem(make_chain_tree(2), o), InputError);
  o.drives = {JointDrive{0, 1.0, 0.0, ScalarPath::constant(0.0)},
              JointDrive{0, 1.0, 0.0, ScalarPath::constant(0.0)}};
  EXPECT_THROW(ArticulatedSystem(make_chain_tree(2), o), InputError);
  o.drives = {JointDrive{5, 1.0, 0.0, ScalarPath::constant(0.0)}};
  EXPECT_THROW(ArticulatedSystem(make_chain_tree(2), o), InputError);
}

}  // namespace
}  // namespace stiffsim
