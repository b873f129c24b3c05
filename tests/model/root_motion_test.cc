// A welded root that translates along a prescribed path
// (ArticulatedOptions::root_motion): a path's acceleration against its
// rate, a pendulum on a shaken base against its own equation of motion, a
// constant displacement that only shifts the world, forces, residual and
// Jacobians equal to a fixed base's under gravity g - d''(t), the analytic
// Jacobians against automatic differentiation with the base moving, point
// kinematics against differences in time and against a fixed base carried
// along d(t), an attachment that sees the base where it is, and the cases
// it refuses.

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <memory>
#include <optional>
#include <vector>

#include "stiffsim/error.h"
#include "stiffsim/integrators/runge_kutta45.h"
#include "stiffsim/model/articulated.h"
#include "stiffsim/model/compliant.h"
#include "stiffsim/model/path.h"
#include "stiffsim/scene.h"

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

TEST(RootMotion, PathAccelerationIsTheDerivativeOfItsRate) {
  const double A = 0.3, f = 1.7, phase = 0.4, w = 2.0 * M_PI * f;
  const ScalarPath s = ScalarPath::sinusoid(0.1, A, f, phase, "s");
  for (double t : {0.0, 0.13, 0.61}) {
    EXPECT_NEAR(s.acceleration(t), -A * w * w * std::sin(w * t + phase), 1e-12);
    const double h = 1e-5;  // truncation ~ h^2 A w^4 / 6 < 1e-7
    EXPECT_NEAR(s.acceleration(t), (s.rate(t + h) - s.rate(t - h)) / (2.0 * h), 1e-6);
  }
  EXPECT_EQ(ScalarPath::constant(2.0).acceleration(0.3), 0.0);
  EXPECT_EQ(ScalarPath::sinusoid(0.5, 0.2, 0.0, 0.3, "still").acceleration(0.7), 0.0);
  const ScalarPath keyed = ScalarPath::keyframes({0.0, 1.0}, {0.0, 1.0}, "k");
  EXPECT_FALSE(keyed.has_continuous_rate());
  EXPECT_TRUE(s.has_continuous_rate());
  EXPECT_TRUE(ScalarPath::constant(1.0).has_continuous_rate());
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

TEST(RootMotion, ForcesResidualAndJacobiansAreAFixedBasesUnderShiftedGravity) {
  // At one instant the shaken tree is the fixed one with gravity g - d''(t):
  // forces, momentum residual and both Jacobians (K holds gravity's
  // stiffness) must agree. d'' is written out here, not taken from the path.
  const double Ax = 0.05, fx = 2.0, px = 0.3, Az = 0.08, fz = 1.5, pz = 1.0;
  Paths shake = still();
  shake[0] = ScalarPath::sinusoid(0.1, Ax, fx, px, "x");
  shake[2] = ScalarPath::sinusoid(0.0, Az, fz, pz, "z");
  const double t = 0.37, wx = 2.0 * M_PI * fx, wz = 2.0 * M_PI * fz;
  const Eigen::Vector3d d_ddot(-Ax * wx * wx * std::sin(wx * t + px), 0.0,
                               -Az * wz * wz * std::sin(wz * t + pz));
  const Eigen::Vector3d g(0.0, 0.0, -9.81);
  const ArticulatedSystem moving = chain(4, shake, g), fixed = chain(4, std::nullopt, g - d_ddot);
  const Dimensions d = moving.dimensions();
  Eigen::VectorXd q(d.nq), v(d.nv), z(0), dv(d.nv);
  q << 0.3, -0.5, 0.8, 0.1;
  v << 1.0, -0.4, 0.2, 0.7;
  dv << 0.01, -0.02, 0.005, 0.03;
  const double h = 0.01;
  Eigen::VectorXd Fm(d.nv), Ff(d.nv), rm(d.nv), rf(d.nv);
  moving.forces(t, q, v, z, Fm);
  fixed.forces(t, q, v, z, Ff);
  EXPECT_LT((Fm - Ff).cwiseAbs().maxCoeff(), 1e-13) << (Fm - Ff).transpose();
  moving.momentum_residual(t, q, v, z, dv, h, rm);
  fixed.momentum_residual(t, q, v, z, dv, h, rf);
  EXPECT_LT((rm - rf).cwiseAbs().maxCoeff(), 1e-15) << (rm - rf).transpose();
  // The base's acceleration is no small correction here.
  Eigen::VectorXd Fg(d.nv);
  chain(4, std::nullopt, g).forces(t, q, v, z, Fg);
  EXPECT_GT((Fm - Fg).cwiseAbs().maxCoeff(), 1e-3);
  const Eigen::VectorXd a = dv / h;
  JacobianRequest request;
  request.complete = true;
  request.acceleration = a.data();
  for (bool automatic : {false, true}) {
    ForceJacobians Jm = moving.jacobian_pattern(), Jf = fixed.jacobian_pattern();
    if (automatic) {
      moving.automatic_force_jacobians(t, q, v, z, request, &Jm);
      fixed.automatic_force_jacobians(t, q, v, z, request, &Jf);
    } else {
      moving.force_jacobians(t, q, v, z, request, &Jm);
      fixed.force_jacobians(t, q, v, z, request, &Jf);
    }
    EXPECT_LT((Eigen::MatrixXd(Jm.dF_dq) - Eigen::MatrixXd(Jf.dF_dq)).cwiseAbs().maxCoeff(), 1e-13)
        << "automatic: " << automatic;
    EXPECT_LT((Eigen::MatrixXd(Jm.dF_dv) - Eigen::MatrixXd(Jf.dF_dv)).cwiseAbs().maxCoeff(), 1e-13)
        << "automatic: " << automatic;
  }
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

TEST(RootMotion, PointsAreAFixedBasesCarriedAlongThePath) {
  // Same q and v on a shaken and a fixed chain: every link point sits d(t)
  // further and moves d'(t) faster; its Jacobian is the fixed one's.
  const double A = 0.1, f = 2.0, phase = 0.7, w = 2.0 * M_PI * f;
  Paths shake = still();
  shake[1] = ScalarPath::sinusoid(0.2, A, f, phase, "y");
  shake[2] = ScalarPath::constant(-0.5);
  const ArticulatedSystem moving = chain(3, shake), fixed = chain(3, std::nullopt);
  Eigen::VectorXd q(3), v(3);
  q << 0.2, -0.4, 0.6;
  v << 1.5, 0.5, -2.0;
  const Eigen::Vector3d local(0.01, 0.02, -0.08);
  for (double t : {0.0, 0.21, 0.4}) {
    const Eigen::Vector3d d(0.0, 0.2 + A * std::sin(w * t + phase), -0.5);
    const Eigen::Vector3d d_dot(0.0, A * w * std::cos(w * t + phase), 0.0);
    for (int body = 0; body < 3; ++body) {
      PointKinematics pm, pf;
      moving.point_kinematics(t, body, local, q, v, &pm);
      fixed.point_kinematics(t, body, local, q, v, &pf);
      EXPECT_LT((pm.p - (pf.p + d)).norm(), 1e-15) << "t " << t << " body " << body;
      EXPECT_LT((pm.p_dot - (pf.p_dot + d_dot)).norm(), 1e-14) << "t " << t << " body " << body;
      EXPECT_EQ(pm.dofs, pf.dofs);
      for (size_t k = 0; k < pm.J.size(); ++k) EXPECT_EQ(pm.J[k], pf.J[k]);
    }
  }
}

TEST(RootMotion, AnAttachmentSeesTheBaseWhereItIs) {
  // Link 2 of a shaken chain tied to a world point: the scene's force on
  // the chain is the chain's own plus J^T f, f = k (W - p) - c p_dot, with
  // p and p_dot those of a fixed chain carried by d(t) and d'(t). Its
  // Jacobians stay those of central differences.
  const double A = 0.06, f = 1.5, w = 2.0 * M_PI * f, k = 40.0, c = 0.3;
  Paths shake = still();
  shake[0] = ScalarPath::sinusoid(0.0, A, f, 0.0, "x");
  const Eigen::Vector3d local(0.02, 0.0, -0.1), W(0.3, 0.1, -0.2);
  auto make_scene = [&]() {
    std::vector<std::unique_ptr<System>> parts;
    ArticulatedOptions o;
    o.root_motion = shake;
    parts.push_back(std::make_unique<ArticulatedSystem>(make_chain_tree(3), o));
    std::vector<Attachment> at(1);
    at[0] = {"tie", {0, 2, local}, {-1, 0, W}, k, c};
    return std::make_unique<Scene>("tied", std::move(parts), std::move(at));
  };
  const std::unique_ptr<Scene> scene = make_scene();
  const ArticulatedSystem alone = chain(3, shake), fixed = chain(3, std::nullopt);
  Eigen::VectorXd q(3), v(3), z(0);
  q << 0.3, -0.2, 0.5;
  v << -0.8, 1.1, 0.4;
  const double t = 0.1;
  const Eigen::Vector3d d(A * std::sin(w * t), 0.0, 0.0), d_dot(A * w * std::cos(w * t), 0.0, 0.0);
  PointKinematics pf;
  fixed.point_kinematics(t, 2, local, q, v, &pf);
  const Eigen::Vector3d force = k * (W - (pf.p + d)) - c * (pf.p_dot + d_dot);
  Eigen::VectorXd expected(3), F(3);
  alone.forces(t, q, v, z, expected);
  for (size_t j = 0; j < pf.dofs.size(); ++j) expected[pf.dofs[j]] += pf.J[j].dot(force);
  scene->forces(t, q, v, z, F);
  EXPECT_LT((F - expected).cwiseAbs().maxCoeff(), 1e-12) << (F - expected).transpose();

  Eigen::MatrixXd Kd(3, 3), Dd(3, 3);
  for (int j = 0; j < 3; ++j) {
    Eigen::VectorXd qp = q, qm = q, vp = v, vm = v, Fp(3), Fm(3);
    qp[j] += 1e-6;
    qm[j] -= 1e-6;
    scene->forces(t, qp, v, z, Fp);
    scene->forces(t, qm, v, z, Fm);
    Kd.col(j) = (Fp - Fm) / 2e-6;
    vp[j] += 1e-3;
    vm[j] -= 1e-3;
    scene->forces(t, q, vp, z, Fp);
    scene->forces(t, q, vm, z, Fm);
    Dd.col(j) = (Fp - Fm) / 2e-3;
  }
  ForceJacobians J = scene->jacobian_pattern();
  JacobianRequest request;
  request.complete = true;
  scene->force_jacobians(t, q, v, z, request, &J);
  EXPECT_LT((Eigen::MatrixXd(J.dF_dq) - Kd).norm(), 1e-6 * Kd.norm())
      << Eigen::MatrixXd(J.dF_dq) - Kd;
  EXPECT_LT((Eigen::MatrixXd(J.dF_dv) - Dd).norm(), 1e-8 * (1.0 + Dd.norm()));
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
  try {
    make_compliant(make_chain_tree(2), o, BushingParameters{});
    ADD_FAILURE() << "compliant formulation accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("root_motion needs the exact formulation"),
              std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace stiffsim
