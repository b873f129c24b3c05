// Pinned nodes that move along a path (PinMotion in particles.h): the path
// reaches forces, Jacobians and energy at the evaluation time, a rope
// carried at constant velocity moves rigidly (closed form), and the
// Jacobians stay exact with a moving end.

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>

#include "stiffsim/error.h"
#include "stiffsim/integrators/runge_kutta45.h"
#include "stiffsim/integrators/velocity_implicit_euler.h"
#include "stiffsim/model/particle_meshes.h"
#include "stiffsim/model/particles.h"

namespace stiffsim {
namespace {

using Eigen::MatrixXd;
using Eigen::Vector3d;
using Eigen::VectorXd;

// A rope of `nodes` along x, node 0 pinned and moving by `motion`.
ParticleDescription carried_rope(int nodes, const PinMotion& motion, Vector3d gravity) {
  RopeSpec spec;
  spec.nodes = nodes;
  spec.length = 1.0;
  spec.total_mass = 0.1;
  spec.stretch = SpringParameters{1e4, 0.5};
  spec.bend = SpringParameters{2.0, 0.05};
  spec.gravity = gravity;
  ParticleDescription d = make_rope(spec);
  d.pin_motions = {motion};
  return d;
}

PinMotion constant_velocity(const Vector3d& u) {
  PinMotion m;
  m.node = 0;
  for (int k = 0; k < 3; ++k)
    m.displacement[k] = ScalarPath::keyframes({0.0, 10.0}, {0.0, 10.0 * u[k]}, "pin");
  return m;
}

TEST(MovingPin, ForcesSeeThePinWhereItsPathPutsIt) {
  // Node 1's spring to the pin: the same force as with a fixed pin placed at
  // the path's position, and the damper sees the path's rate.
  PinMotion m;
  m.node = 0;
  m.displacement[1] = ScalarPath::sinusoid(0.0, 0.2, 1.0, 0.0, "pin");
  const ParticleSystem moving(carried_rope(3, m, Vector3d::Zero()));
  const double t = 0.1;
  ParticleDescription fixed = carried_rope(3, m, Vector3d::Zero());
  fixed.pin_motions.clear();
  fixed.positions[0] += Vector3d(0.0, m.displacement[1].value(t), 0.0);
  const ParticleSystem still(fixed);
  const State s = moving.initial_state();
  const Dimensions d = moving.dimensions();
  VectorXd v = VectorXd::Zero(d.nv), F_moving(d.nv), F_still(d.nv);
  moving.forces(t, s.q(d), v, VectorXd(), F_moving);
  // The fixed pin at rest sees node 1 moving at minus the pin's velocity.
  v.segment<3>(0) = -Vector3d(0.0, m.displacement[1].rate(t), 0.0);
  v.segment<3>(3) = v.segment<3>(0);
  still.forces(t, s.q(d), v, VectorXd(), F_still);
  // Drag is zero and gravity off, so only the springs differ by velocity:
  // the relative velocities of every spring are the same in both.
  EXPECT_LT((F_moving - F_still).norm(), 1e-12 * F_still.norm());
  EXPECT_EQ(moving.pinned_position(0, t), fixed.positions[0]);
  EXPECT_FALSE(moving.capabilities().passive);
  EXPECT_TRUE(still.capabilities().passive);
}

TEST(MovingPin, ARopeCarriedAtConstantVelocityMovesRigidly) {
  // No gravity, every free node started with the pin's velocity u: every
  // spring keeps its length and no relative velocity, so the forces vanish
  // and x_i(t) = x_i(0) + u t exactly; VIE's step (forces at the step's end
  // time) reproduces it to round-off, and so does RK45 (forces at its stage
  // times).
  const Vector3d u(0.3, -0.2, 0.5);
  const ParticleSystem sys(carried_rope(8, constant_velocity(u), Vector3d::Zero()));
  const Dimensions d = sys.dimensions();
  State s = sys.initial_state();
  for (int i = 0; i < d.nv / 3; ++i) s.v(d).segment<3>(3 * i) = u;
  IntegratorSettings fixed;
  fixed.fixed_step = true;
  fixed.max_step = 0.01;
  VelocityImplicitEuler vie(sys, fixed, ImplicitSettings{});
  vie.initialize(s);
  vie.integrate_to(1.0);
  // RK45 is explicit on a stiff rope: at a loose accuracy its steps sit at
  // the stability bound and round-off grows to the tolerance's size.
  IntegratorSettings tight;
  tight.accuracy = 1e-10;
  RungeKutta45 rk45(sys, tight);
  rk45.initialize(s);
  rk45.integrate_to(1.0);
  for (const IntegratorBase* integrator :
       {static_cast<const IntegratorBase*>(&vie), static_cast<const IntegratorBase*>(&rk45)}) {
    const State& end = integrator->state();
    for (int i = 0; i < d.nv / 3; ++i) {
      const Vector3d expected = s.q(d).segment<3>(3 * i) + u * end.t;
      EXPECT_LT((Vector3d(end.q(d).segment<3>(3 * i)) - expected).norm(), 1e-10)
          << integrator->method_name() << ", node " << i + 1;
    }
    // The pin is where its path says, and the first free node keeps its
    // distance to it.
    EXPECT_LT((sys.pinned_position(0, end.t) - (Vector3d::Zero() + u * end.t)).norm(), 1e-14);
  }
}

TEST(MovingPin, JacobiansStayExactWithAMovingEnd) {
  // Complete analytic K and D equal AD and central differences with the pin
  // displaced and moving (its velocity enters the damper's x-derivative).
  PinMotion m;
  m.node = 0;
  m.displacement[0] = ScalarPath::sinusoid(0.0, 0.1, 2.0, 0.3, "pin");
  m.displacement[2] = ScalarPath::keyframes({0.0, 1.0}, {0.0, 0.4}, "pin");
  const ParticleSystem sys(carried_rope(5, m, Vector3d(0, 0, -9.81)));
  const Dimensions d = sys.dimensions();
  const double t = 0.37;
  VectorXd q = sys.initial_state().q(d);
  VectorXd v = VectorXd::LinSpaced(d.nv, -1.0, 1.0);
  for (int i = 0; i < d.nq; ++i) q[i] += 0.02 * std::sin(3.0 * i);
  auto F = [&](const VectorXd& qq, const VectorXd& vv) {
    VectorXd out(d.nv);
    sys.forces(t, qq, vv, VectorXd(), out);
    return out;
  };
  MatrixXd Kd(d.nv, d.nv), Dd(d.nv, d.nv);
  for (int j = 0; j < d.nv; ++j) {
    VectorXd qp = q, qm = q, vp = v, vm = v;
    qp[j] += 1e-6;
    qm[j] -= 1e-6;
    vp[j] += 1e-2;
    vm[j] -= 1e-2;
    Kd.col(j) = (F(qp, v) - F(qm, v)) / 2e-6;
    Dd.col(j) = (F(q, vp) - F(q, vm)) / 2e-2;
  }
  ForceJacobians J = sys.jacobian_pattern(), A = sys.jacobian_pattern();
  JacobianRequest complete;
  complete.complete = true;
  sys.force_jacobians(t, q, v, VectorXd(), complete, &J);
  sys.automatic_force_jacobians(t, q, v, VectorXd(), complete, &A);
  EXPECT_LT((MatrixXd(J.dF_dq) - Kd).norm(), 1e-6 * Kd.norm());
  EXPECT_LT((MatrixXd(J.dF_dv) - Dd).norm(), 1e-9 * Dd.norm());
  EXPECT_LT((MatrixXd(J.dF_dq) - MatrixXd(A.dF_dq)).norm(), 1e-12 * Kd.norm());
  EXPECT_LT((MatrixXd(J.dF_dv) - MatrixXd(A.dF_dv)).norm(), 1e-12 * Dd.norm());
}

TEST(MovingPin, EnergyPlacesThePinOnItsPath) {
  // Spring energy to a pin lifted by dz: 1/2 k (l - L)^2 with the lifted
  // length, plus the pin's gravity term at its lifted height.
  PinMotion m;
  m.node = 0;
  m.displacement[2] = ScalarPath::keyframes({0.0, 1.0}, {0.0, 0.3}, "pin");
  ParticleDescription d;
  d.name = "p";
  d.positions = {Vector3d(0, 0, 0), Vector3d(1.0, 0, 0)};
  d.masses = {3.0, 2.0};
  d.springs = {Spring{0, 1, 1.0, 100.0, 0.0}};
  d.pinned = {0};
  d.pin_motions = {m};
  const ParticleSystem sys(d);
  State s = sys.initial_state();
  s.t = 0.5;  // pin at z = 0.15
  const double l = std::hypot(1.0, 0.15);
  const double expected = 0.5 * 100.0 * (l - 1.0) * (l - 1.0) + 3.0 * 9.81 * 0.15;
  EXPECT_NEAR(sys.energy(s), expected, 1e-12);
}

TEST(MovingPin, InvalidMotionsAreRejected) {
  PinMotion m;
  m.node = 2;  // not pinned
  EXPECT_THROW(ParticleSystem(carried_rope(3, m, Vector3d::Zero())), InputError);
  m.node = 7;  // out of range
  EXPECT_THROW(ParticleSystem(carried_rope(3, m, Vector3d::Zero())), InputError);
  ParticleDescription twice =
      carried_rope(3, constant_velocity(Vector3d::UnitX()), Vector3d::Zero());
  twice.pin_motions.push_back(twice.pin_motions[0]);
  EXPECT_THROW(ParticleSystem{twice}, InputError);
}

}  // namespace
}  // namespace stiffsim
