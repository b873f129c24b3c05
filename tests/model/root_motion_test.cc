// A welded root that translates along a prescribed path
// (ArticulatedOptions::root_motion): a pendulum on a shaken base against its
// own equation of motion, a constant displacement that only shifts the
// world, the analytic Jacobians against automatic differentiation with the
// base moving, point kinematics against differences in time, and the cases
// it refuses.

#include <gtest/gtest.h>

#include <cmath>

#include "stiffsim/error.h"
#include "stiffsim/integrators/runge_kutta45.h"
#include "stiffsim/model/articulated.h"
#include "stiffsim/model/path.h"

namespace stiffsim {
namespace {

using Paths = std::array<ScalarPath, 3>;

Paths still() {
  return {ScalarPath::constant(0.0), ScalarPath::constant(0.0), ScalarPath::constant(0.0)};
}

ArticulatedSystem chain(int links, std::optional<Paths> motion,
                        Eigen::Vector3d gravity = Eigen::Vector3d(0.0, 0.0, -9.81)) {
  ArticulatedOptions o;
  o.gravity = gravity;
  o.root_motion = std::move(motion);
  return ArticulatedSystem(make_chain_tree(links), o);
}

TEST(RootMotion, PendulumOnAShakenBaseFollowsItsEquationOfMotion) {
  // make_chain_tree(1): a rod about y through the origin, mass m with its
  // centre L below the pivot, I_p about the pivot. With the base at
  // x_b = A sin(w t), in the base frame gravity is (-x_b'', 0, -g), so
  //   I_p theta'' = m L (x_b'' cos(theta) - g sin(theta)).
  const double A = 0.02, f = 3.0, w = 2.0 * M_PI * f, g = 9.81;
  Paths shake = still();
  shake[0] = ScalarPath::sinusoid(0.0, A, f, 0.0, "x");
  const ArticulatedSystem sys = chain(1, shake);
  const TreeBody& b = sys.tree().bodies[0];
  const double m = b.inertia.mass, L = -b.inertia.com.z();
  const double Ip = b.inertia.inertia(1, 1) + m * L * L;
  auto theta_ddot = [&](double t, double theta) {
    const double xb_ddot = -A * w * w * std::sin(w * t);
    return m * L / Ip * (xb_ddot * std::cos(theta) - g * std::sin(theta));
  };
  // The reference: classical RK4 at 1e-5 s on the scalar equation
  // (global error ~ (w h)^4, far below the tolerance).
  double theta = 0.0, omega = 0.0, t = 0.0;
  const double dt = 1e-5;
  IntegratorSettings tight;
  tight.accuracy = 1e-11;
  RungeKutta45 rk45(sys, tight);
  rk45.initialize(sys.initial_state());
  for (double t_check : {0.1, 0.25, 0.5}) {
    while (t < t_check - 0.5 * dt) {
      const double k1t = omega, k1w = theta_ddot(t, theta);
      const double k2t = omega + 0.5 * dt * k1w,
                   k2w = theta_ddot(t + 0.5 * dt, theta + 0.5 * dt * k1t);
      const double k3t = omega + 0.5 * dt * k2w,
                   k3w = theta_ddot(t + 0.5 * dt, theta + 0.5 * dt * k2t);
      const double k4t = omega + dt * k3w, k4w = theta_ddot(t + dt, theta + dt * k3t);
      theta += dt / 6.0 * (k1t + 2 * k2t + 2 * k3t + k4t);
      omega += dt / 6.0 * (k1w + 2 * k2w + 2 * k3w + k4w);
      t += dt;
    }
    rk45.integrate_to(t_check);
    // The shaking swings it visibly: the check is not of a pendulum at rest.
    EXPECT_GT(std::abs(theta), 1e-3);
    EXPECT_NEAR(rk45.state().x[0], theta, 1e-8) << "t = " << t_check;
    EXPECT_NEAR(rk45.state().x[1], omega, 1e-6) << "t = " << t_check;
  }
}

TEST(RootMotion, AConstantDisplacementShiftsTheWorldAndNothingElse) {
  Paths shift = still();
  shift[0] = ScalarPath::constant(0.3);
  shift[2] = ScalarPath::constant(-1.0);
  const ArticulatedSystem moved = chain(3, shift), fixed = chain(3, std::nullopt);
  State s = fixed.initial_state();
  s.x[0] = 0.4;
  s.x[4] = -0.7;
  IntegratorSettings tight;
  tight.accuracy = 1e-9;
  RungeKutta45 a(moved, tight), b(fixed, tight);
  a.initialize(s);
  b.initialize(s);
  a.integrate_to(0.3);
  b.integrate_to(0.3);
  EXPECT_EQ(a.state().x, b.state().x);  // the same arithmetic: gravity alone
  PointKinematics pa, pb;
  const Dimensions d = moved.dimensions();
  const Eigen::VectorXd q = a.state().q(d), v = a.state().v(d);
  moved.point_kinematics(0.3, 2, Eigen::Vector3d(0.0, 0.0, -0.1), q, v, &pa);
  fixed.point_kinematics(0.3, 2, Eigen::Vector3d(0.0, 0.0, -0.1), q, v, &pb);
  EXPECT_TRUE(pa.p.isApprox(pb.p + Eigen::Vector3d(0.3, 0.0, -1.0), 1e-15));
  EXPECT_TRUE(pa.p_dot.isApprox(pb.p_dot, 1e-15));
  EXPECT_FALSE(moved.capabilities().passive);
  EXPECT_TRUE(fixed.capabilities().passive);
}

TEST(RootMotion, AnalyticJacobiansEqualAutomaticDifferentiationWithTheBaseMoving) {
  Paths shake = still();
  shake[0] = ScalarPath::sinusoid(0.1, 0.05, 2.0, 0.3, "x");
  shake[2] = ScalarPath::sinusoid(0.0, 0.08, 1.5, 1.0, "z");
  const ArticulatedSystem sys = chain(4, shake);
  const Dimensions d = sys.dimensions();
  Eigen::VectorXd q(d.nq), v(d.nv), z(0), a(d.nv);
  q << 0.3, -0.5, 0.8, 0.1;
  v << 1.0, -0.4, 0.2, 0.7;
  a << 0.5, -1.0, 2.0, 0.3;
  const double t = 0.37;  // where both axes accelerate
  JacobianRequest request;
  request.complete = true;
  request.acceleration = a.data();
  ForceJacobians analytic = sys.jacobian_pattern(), automatic = sys.jacobian_pattern();
  sys.force_jacobians(t, q, v, z, request, &analytic);
  sys.automatic_force_jacobians(t, q, v, z, request, &automatic);
  const Eigen::MatrixXd Ka(analytic.dF_dq), Kd(automatic.dF_dq);
  EXPECT_LT((Ka - Kd).cwiseAbs().maxCoeff(), 1e-12 * (1.0 + Kd.cwiseAbs().maxCoeff()));
  EXPECT_LT(
      (Eigen::MatrixXd(analytic.dF_dv) - Eigen::MatrixXd(automatic.dF_dv)).cwiseAbs().maxCoeff(),
      1e-12);
  // And the base's acceleration is in them: gravity's stiffness changes.
  ForceJacobians still_base = sys.jacobian_pattern();
  const ArticulatedSystem fixed = chain(4, std::nullopt);
  fixed.force_jacobians(t, q, v, z, request, &still_base);
  EXPECT_GT((Ka - Eigen::MatrixXd(still_base.dF_dq)).cwiseAbs().maxCoeff(), 1e-4);
}

TEST(RootMotion, PointVelocityIsTheTimeDerivativeOfItsPosition) {
  Paths shake = still();
  shake[0] = ScalarPath::sinusoid(0.0, 0.1, 2.0, 0.0, "x");
  shake[1] = ScalarPath::sinusoid(0.2, 0.05, 1.0, 0.5, "y");
  const ArticulatedSystem sys = chain(3, shake);
  Eigen::VectorXd q(3), v(3);
  q << 0.2, -0.4, 0.6;
  v << 1.5, 0.5, -2.0;
  const Eigen::Vector3d local(0.01, 0.0, -0.08);
  const double t = 0.21, dt = 1e-6;
  PointKinematics now, ahead, behind;
  sys.point_kinematics(t, 2, local, q, v, &now);
  const Eigen::VectorXd qa = q + dt * v, qb = q - dt * v;
  sys.point_kinematics(t + dt, 2, local, qa, v, &ahead);
  sys.point_kinematics(t - dt, 2, local, qb, v, &behind);
  const Eigen::Vector3d central = (ahead.p - behind.p) / (2.0 * dt);
  EXPECT_LT((now.p_dot - central).norm(), 1e-6 * (1.0 + now.p_dot.norm()));
  // The base's own velocity is part of it.
  EXPECT_GT(std::abs(sys.root_velocity(t).x()), 0.1);
}

TEST(RootMotion, RefusesKeyframesAFloatingRootAndBushings) {
  Paths keyed = still();
  keyed[2] = ScalarPath::keyframes({0.0, 1.0}, {0.0, 0.5}, "z");
  try {
    chain(2, keyed);
    ADD_FAILURE() << "keyframes accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("root_motion.z is keyframed"), std::string::npos)
        << e.what();
  }
  RigidTree floating = make_chain_tree(2);
  floating.bodies[0].type = JointType::kFloating;
  ArticulatedOptions o;
  o.root_motion = still();
  try {
    ArticulatedSystem sys(floating, o);
    ADD_FAILURE() << "floating root accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("joined to the world by a floating joint"),
              std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace stiffsim
