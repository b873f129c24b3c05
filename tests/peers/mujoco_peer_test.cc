// MuJoCo as a peer: the same URDF, springs, dampers, gravity and initial
// state in MuJoCo (RK4 at a small step) and in stiffsim's exact model
// (RK45 at a tight accuracy) give the same joint trajectories; the sign and
// axis conventions of the joint angles agree (the branched tree, which has
// no mirror symmetry, checks that: a planar chain would not notice q -> -q).
// Published robots on a welded and on a floating base check the free joint:
// a turned, moving base whose angular velocity MuJoCo read in another frame
// would move elsewhere.

#include "stiffsim/peers/mujoco_peer.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

#include "stiffsim/integrators/runge_kutta45.h"
#include "stiffsim/integrators/velocity_implicit_euler.h"
#include "stiffsim/model/articulated.h"
#include "stiffsim/model/compliant.h"
#include "stiffsim/model/urdf.h"

namespace stiffsim {
namespace {

const std::string kModels = std::string(STIFFSIM_SOURCE_DIR) + "/models/";
const std::string kRobots = std::string(STIFFSIM_SOURCE_DIR) + "/tests/data/urdf/";

// Built with or without MuJoCo: the mapping needs only the system.
TEST(MujocoPeer, CompliantSystemHasNoMujocoProblem) {
  const RigidTree tree = load_urdf(kModels + "chain_2.urdf", UrdfOptions{"chain", false}, nullptr);
  const auto sys = make_compliant(tree, ArticulatedOptions{}, BushingParameters{});
  EXPECT_THROW(mujoco_problem(*sys, kModels + "chain_2.urdf"), std::invalid_argument);
}

TEST(MujocoPeer, MovingRootHasNoMujocoProblem) {
  // A base held at a constant offset moves nothing MuJoCo would see; a
  // shaken one would be compared against a still MuJoCo base.
  const RigidTree tree = load_urdf(kModels + "chain_2.urdf", UrdfOptions{"chain", false}, nullptr);
  ArticulatedOptions o;
  o.root_motion = {ScalarPath::constant(0.2), ScalarPath::constant(0.0),
                   ScalarPath::constant(-0.1)};
  EXPECT_NO_THROW(mujoco_problem(ArticulatedSystem(tree, o), kModels + "chain_2.urdf"));
  (*o.root_motion)[1] = ScalarPath::sinusoid(0.0, 0.01, 2.0, 0.0, "y");
  try {
    mujoco_problem(ArticulatedSystem(tree, o), kModels + "chain_2.urdf");
    ADD_FAILURE() << "a shaken base was mapped";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("moving root"), std::string::npos) << e.what();
  }
}

#ifndef STIFFSIM_HAVE_MUJOCO

TEST(MujocoPeer, UnavailableWithoutMujoco) {
  EXPECT_FALSE(mujoco_available());
  MujocoProblem problem;
  problem.urdf_path = kModels + "chain_2.urdf";
  EXPECT_THROW(run_mujoco(problem), std::runtime_error);
}

#else

struct Spring {
  double stiffness = 0.0, rest = 0.0, damping = 0.0;
};

struct Comparison {
  double max_dq = 0.0;  // largest joint difference at t_final
  double max_dv = 0.0;
  double moved = 0.0;   // largest |q(t_final) - q0| in stiffsim's solution
};

// Every 1-DOF joint of `file` starts at q0; stiffsim RK45 (accuracy 1e-10)
// against MuJoCo RK4 at step h, both to t_final.
Comparison compare(const std::string& file, double q0, Spring spring, double h, double t_final) {
  const std::string path = kModels + file;
  RigidTree tree = load_urdf(path, UrdfOptions{"chain", false}, nullptr);

  MujocoProblem problem;
  problem.urdf_path = path;
  problem.integrator = "RK4";
  problem.step = h;
  problem.t_final = t_final;
  problem.sample_times = {0.0, t_final};

  ArticulatedOptions options;
  options.joint_forces.resize(tree.bodies.size());
  int nq = 0;
  for (size_t b = 0; b < tree.bodies.size(); ++b) {
    const TreeBody& body = tree.bodies[b];
    EXPECT_TRUE(body.type == JointType::kRevolute || body.type == JointType::kPrismatic) << body.joint;
    options.joint_forces[b] = JointForce{spring.stiffness, spring.rest, spring.damping};
    problem.joints.push_back(body.joint);
    problem.initial_q.push_back(q0);
    problem.initial_v.push_back(0.0);
    problem.stiffness.push_back(spring.stiffness);
    problem.rest.push_back(spring.rest);
    problem.damping.push_back(body.damping + spring.damping);
    ++nq;
  }
  options.initial_q = Eigen::VectorXd::Constant(nq, q0);
  options.initial_v = Eigen::VectorXd::Zero(nq);
  ArticulatedSystem sys(tree, options);
  for (size_t b = 0; b < tree.bodies.size(); ++b)
    EXPECT_EQ(sys.body_q_offset(static_cast<int>(b)), static_cast<int>(b));

  IntegratorSettings settings;
  settings.accuracy = 1e-10;
  RungeKutta45 rk(sys, settings);
  rk.initialize(sys.initial_state());
  rk.integrate_to(t_final);
  const Eigen::VectorXd& x = rk.state().x;

  const PeerRun run = run_mujoco(problem);
  EXPECT_FALSE(run.failed) << run.message;
  EXPECT_EQ(run.method, "mujoco-rk4");
  EXPECT_EQ(run.steps, std::lround(t_final / h));
  EXPECT_GT(run.rhs_evaluations, 0);
  EXPECT_NE(run.settings.find("RK4"), std::string::npos) << run.settings;
  EXPECT_EQ(run.times.size(), 2u);
  EXPECT_EQ(run.samples.size(), 2u);
  Comparison c;
  if (run.samples.size() != 2u) return c;
  const Eigen::VectorXd& y = run.samples.back();
  EXPECT_EQ(y.size(), 2 * nq);
  EXPECT_TRUE(run.samples.front().head(nq).isApprox(options.initial_q));
  c.max_dq = (x.head(nq) - y.head(nq)).cwiseAbs().maxCoeff();
  c.max_dv = (x.segment(nq, nq) - y.tail(nq)).cwiseAbs().maxCoeff();
  c.moved = (x.head(nq).array() - q0).abs().maxCoeff();
  std::printf("%s: q0 %.2f, k %.3g, c %.3g: max |dq| %.3e rad, max |dv| %.3e rad/s (moved by up to %.3f)\n",
              file.c_str(), q0, spring.stiffness, spring.damping, c.max_dq, c.max_dv, c.moved);
  return c;
}

TEST(MujocoPeer, Available) { EXPECT_TRUE(mujoco_available()); }

TEST(MujocoPeer, Chain2MatchesStiffsim) {
  const Comparison c = compare("chain_2.urdf", 0.3, Spring{2.0, 0.0, 0.01}, 1e-4, 0.5);
  EXPECT_GT(c.moved, 0.1);
  EXPECT_LT(c.max_dq, 1e-4);
  EXPECT_LT(c.max_dv, 1e-3);
}

TEST(MujocoPeer, Chain2WithoutSpringMatchesStiffsim) {
  const Comparison c = compare("chain_2.urdf", 0.3, Spring{}, 1e-4, 0.5);
  EXPECT_LT(c.max_dq, 1e-4);
}

// Ten links swing faster near the tip, and the chain is mildly chaotic, so
// the differences of two fourth/fifth-order integrations grow along it;
// measured ~1e-8 rad (see the printout): 1e-5 leaves room for both
// integrators' errors and still catches any modelling difference (a wrong
// inertia, axis, spring or damper changes the angles by 1e-2 or more here).
TEST(MujocoPeer, Chain10MatchesStiffsim) {
  const Comparison c = compare("chain_10.urdf", 0.3, Spring{2.0, 0.0, 0.01}, 1e-4, 0.5);
  EXPECT_GT(c.moved, 0.1);
  EXPECT_LT(c.max_dq, 1e-5);
}

// The branched tree: an off-axis torso with products of inertia and rotated
// inertial frames, fixed joints welded (a massive battery, a massless IMU
// frame, a gripper), a prismatic joint, URDF damping, and no mirror
// symmetry, so a sign or axis slip would show.
TEST(MujocoPeer, TreeMatchesStiffsim) {
  const Comparison c = compare("tree.urdf", 0.3, Spring{2.0, 0.0, 0.01}, 1e-4, 0.5);
  EXPECT_GT(c.moved, 0.1);
  EXPECT_LT(c.max_dq, 1e-5);
}

// A published robot with a spring of 100 N m/rad and a damper of 1 N m s/rad
// on every joint, joints bent and moving (no two alike), and on a floating
// base a turned and moving base, so that every term of the dynamics and every
// convention of the free joint shows.
ArticulatedSystem robot_system(const std::string& file, bool floating_base) {
  UrdfOptions urdf;
  urdf.floating_base = floating_base;
  const RigidTree tree = load_urdf(kRobots + file, urdf, nullptr);
  ArticulatedOptions options;
  options.joint_forces.resize(tree.bodies.size());
  int joints = 0;
  for (size_t b = 0; b < tree.bodies.size(); ++b) {
    if (joint_nv(tree.bodies[b].type) != 1) continue;
    options.joint_forces[b] = JointForce{100.0, 0.0, 1.0};
    ++joints;
  }
  const int base_q = floating_base ? 7 : 0, base_v = floating_base ? 6 : 0;
  options.initial_q.resize(base_q + joints);
  options.initial_v.resize(base_v + joints);
  if (floating_base) {
    const Eigen::Vector4d quat = Eigen::Vector4d(0.9, 0.1, -0.2, 0.3).normalized();
    options.initial_q.head<7>() << 0.1, -0.2, 0.5, quat;
    options.initial_v.head<6>() << 0.3, -0.1, 0.2, 0.5, -0.4, 0.8;
  }
  for (int i = 0; i < joints; ++i) {
    options.initial_q[base_q + i] = 0.3 * std::sin(1.7 * i + 0.5);
    options.initial_v[base_v + i] = 0.5 * std::cos(2.3 * i);
  }
  return ArticulatedSystem(tree, options);
}

struct StateDifference {
  double q = 0.0, v = 0.0;  // largest |difference| of positions, velocities
};

StateDifference difference(const ArticulatedSystem& sys, const Eigen::VectorXd& a,
                           const Eigen::VectorXd& b) {
  const int nq = sys.dimensions().nq, nv = sys.dimensions().nv;
  EXPECT_EQ(a.size(), nq + nv);
  EXPECT_EQ(b.size(), nq + nv);
  if (a.size() != b.size()) return {1e300, 1e300};
  return {(a.head(nq) - b.head(nq)).cwiseAbs().maxCoeff(),
          (a.tail(nv) - b.tail(nv)).cwiseAbs().maxCoeff()};
}

struct RobotComparison : StateDifference {
  std::string settings;  // MuJoCo's
};

// stiffsim RK45 (accuracy 1e-10) against MuJoCo RK4 at h = 1e-4, to t_final.
RobotComparison compare_robot(const std::string& file, bool floating_base, double t_final) {
  const ArticulatedSystem sys = robot_system(file, floating_base);
  MujocoProblem problem = mujoco_problem(sys, kRobots + file);
  EXPECT_EQ(problem.floating_base_link.empty(), !floating_base);
  problem.integrator = "RK4";
  problem.step = 1e-4;
  problem.t_final = t_final;
  problem.sample_times = {0.0, t_final};
  const PeerRun run = run_mujoco(problem);
  EXPECT_FALSE(run.failed) << run.message;
  EXPECT_EQ(run.samples.size(), 2u);
  if (run.samples.size() != 2u) return {{1e300, 1e300}, run.settings};
  // The samples are in stiffsim's coordinates from the start.
  EXPECT_EQ(run.samples.front(), sys.initial_state().x);

  IntegratorSettings settings;
  settings.accuracy = 1e-10;
  RungeKutta45 rk(sys, settings);
  rk.initialize(sys.initial_state());
  rk.integrate_to(t_final);
  const StateDifference d = difference(sys, rk.state().x, run.samples.back());
  const double moved = (rk.state().x - sys.initial_state().x).cwiseAbs().maxCoeff();
  std::printf("%s, %s base, t = %g: max |dq| %.3e, max |dv| %.3e (the state moved by up to %.3f)\n",
              file.c_str(), floating_base ? "floating" : "welded", t_final, d.q, d.v, moved);
  EXPECT_GT(moved, 0.1);
  return {d, run.settings};
}

// Two fourth/fifth-order integrations of the same model: measured
// differences of 9e-12 (welded) and 2e-10 (floating) on the humanoid. On the
// quadruped 6e-8 in q and 1e-6 in v, whatever MuJoCo's step (the same at
// h = 2.5e-5): MuJoCo balances the non-physical tensor of the dummy root
// (1e-6 kg, moments (3e-6, 0, 0) kg m^2; see mujoco_peer.cc), a model
// difference of 1e-6 kg m^2. Bounds of 1e-6 and 1e-5 leave room for that and
// still catch any real modelling difference: a wrong inertia, axis, spring or
// damper, or the base's angular velocity read in the world frame (measured:
// 1.8e-2 in q on both robots) moves the state by 1e-2 or more in 0.2 s.
TEST(MujocoPeer, HumanoidOnAWeldedBaseMatchesStiffsim) {
  const RobotComparison d = compare_robot("simple_humanoid.urdf", false, 0.2);
  EXPECT_EQ(d.settings.find("balanceinertia"), std::string::npos) << d.settings;
  EXPECT_EQ(d.settings.find("free joint"), std::string::npos) << d.settings;
  EXPECT_LT(d.q, 1e-6);
  EXPECT_LT(d.v, 1e-5);
}

TEST(MujocoPeer, HumanoidOnAFloatingBaseMatchesStiffsim) {
  const RobotComparison d = compare_robot("simple_humanoid.urdf", true, 0.2);
  EXPECT_NE(d.settings.find("free joint on 'base_link'"), std::string::npos) << d.settings;
  EXPECT_LT(d.q, 1e-6);
  EXPECT_LT(d.v, 1e-5);
}

TEST(MujocoPeer, QuadrupedOnAFloatingBaseMatchesStiffsim) {
  const RobotComparison d = compare_robot("anymal_b.urdf", true, 0.2);
  EXPECT_NE(d.settings.find("balanceinertia on, MuJoCo refused the moments of 'base'"),
            std::string::npos)
      << d.settings;
  EXPECT_LT(d.q, 1e-6);
  EXPECT_LT(d.v, 1e-5);
}

// MuJoCo's implicit integrator and stiffsim's VIE are both first order and
// differ in what they treat implicitly (springs explicit in MuJoCo), so
// their difference at a fixed time is O(h): halving h must about halve it
// (measured: 7.9e-3 and 4.0e-3 rad, ratio 1.98). A ratio within [1.6, 2.5]
// says first order; a modelling difference would leave a part that does
// not shrink with h (ratio towards 1).
TEST(MujocoPeer, ImplicitAndVieAgreeToFirstOrder) {
  const ArticulatedSystem sys = robot_system("anymal_b.urdf", true);
  const double t_final = 0.1;
  double previous = 0.0;
  for (double h : {1e-3, 5e-4}) {
    MujocoProblem problem = mujoco_problem(sys, kRobots + "anymal_b.urdf");
    problem.integrator = "implicit";
    problem.step = h;
    problem.t_final = t_final;
    problem.sample_times = {t_final};
    const PeerRun run = run_mujoco(problem);
    ASSERT_FALSE(run.failed) << run.message;
    ASSERT_EQ(run.samples.size(), 1u);

    IntegratorSettings settings;
    settings.fixed_step = true;
    settings.max_step = h;
    VelocityImplicitEuler vie(sys, settings, ImplicitSettings{});
    vie.initialize(sys.initial_state());
    vie.integrate_to(t_final);
    const StateDifference d = difference(sys, vie.state().x, run.samples.back());
    std::printf("anymal_b floating, implicit vs VIE, h = %g: max |dq| %.3e, max |dv| %.3e\n", h,
                d.q, d.v);
    if (previous > 0.0) {
      EXPECT_GT(previous / d.q, 1.6);
      EXPECT_LT(previous / d.q, 2.5);
    }
    previous = d.q;
  }
}

TEST(MujocoPeer, UnknownJointThrows) {
  MujocoProblem problem;
  problem.urdf_path = kModels + "chain_2.urdf";
  problem.joints = {"joint_1", "no_such_joint"};
  problem.initial_q = problem.initial_v = problem.stiffness = problem.rest = problem.damping = {0, 0};
  try {
    run_mujoco(problem);
    FAIL() << "no throw";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("no_such_joint"), std::string::npos) << e.what();
  }
}

TEST(MujocoPeer, MissingFileThrows) {
  MujocoProblem problem;
  problem.urdf_path = kModels + "no_such_file.urdf";
  try {
    run_mujoco(problem);
    FAIL() << "no throw";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("no_such_file.urdf"), std::string::npos) << e.what();
  }
}

// MuJoCo's implicit integrator is implicit in damping only: a stiff joint
// spring stays explicit (semi-implicit Euler in the spring: stable for
// h omega < 2 in a linear system). chain_10 with k = 1e4 N m/rad on every
// joint has modal frequencies sqrt(eig(M^-1 K)) from 123 to 2.04e4 rad/s at
// q = 0.3 (2.11e4 at q = 0; M from MuJoCo's mj_fullM), so h omega_max ~ 204
// at h = 1e-2, 20 at 1e-3, 2.04 at 1e-4 and 1.02 at 5e-5. Measured: failed
// (MuJoCo's bad-qacc warning) after 2, 3, 76 steps at 1e-2, 1e-3, 1e-4, and
// even at 5e-5 after 0.23 s (its Euler integrator completes at 5e-5);
// completes at 3e-5 and 2e-5. The joints exchange energy, so |q| reaches
// ~0.55 in an accurate run (RK4 at 1e-5) although every joint starts at 0.3.
// Asserted where clear-cut: failure for h >= 1e-3, completion at 2e-5.
TEST(MujocoPeer, ImplicitAtStiffSpring) {
  RigidTree tree = load_urdf(kModels + "chain_10.urdf", UrdfOptions{"chain", false}, nullptr);
  for (double h : {1e-2, 1e-3, 1e-4, 5e-5, 2e-5}) {
    MujocoProblem problem;
    problem.urdf_path = kModels + "chain_10.urdf";
    for (const TreeBody& b : tree.bodies) {
      problem.joints.push_back(b.joint);
      problem.initial_q.push_back(0.3);
      problem.initial_v.push_back(0.0);
      problem.stiffness.push_back(1e4);
      problem.rest.push_back(0.0);
      problem.damping.push_back(b.damping + 0.01);
    }
    problem.integrator = "implicit";
    problem.step = h;
    problem.t_final = 0.5;
    for (int k = 0; k <= 10; ++k) problem.sample_times.push_back(0.05 * k);
    const PeerRun run = run_mujoco(problem);
    EXPECT_EQ(run.method, "mujoco-implicit");
    EXPECT_NE(run.settings.find("joint springs explicit"), std::string::npos) << run.settings;
    double max_q = 0.0;
    for (const Eigen::VectorXd& x : run.samples)
      max_q = std::max(max_q, x.head(problem.joints.size()).cwiseAbs().maxCoeff());
    std::printf("implicit k = 1e4, h = %g: failed %d after %ld steps, %zu of 11 samples, max |q| %.3g%s%s\n",
                h, run.failed ? 1 : 0, run.steps, run.samples.size(), max_q,
                run.failed ? ": " : "", run.message.c_str());
    if (h >= 1e-3) {
      EXPECT_TRUE(run.failed);
      EXPECT_NE(run.message.find("t = "), std::string::npos) << run.message;
    }
    if (h == 2e-5) {
      EXPECT_FALSE(run.failed) << run.message;
      EXPECT_EQ(run.samples.size(), 11u);
      EXPECT_LT(max_q, 1.0);
    }
  }
}

#endif  // STIFFSIM_HAVE_MUJOCO

}  // namespace
}  // namespace stiffsim
