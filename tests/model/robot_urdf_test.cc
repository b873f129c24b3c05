// Published robot descriptions (tests/data/urdf; sources and licences in its
// README.md), kept verbatim: each loads, on a welded and on a floating base,
// into an ArticulatedSystem whose forces are finite, whose mass matrix is
// symmetric positive definite, and whose force Jacobians match central
// differences of the forces. Between them they carry what made the loader
// stricter than Drake and MuJoCo: point masses welded by fixed joints, a
// dummy root link with a singular tensor, and a moving link whose own tensor
// is singular but whose welded tip is not.

#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "stiffsim/model/articulated.h"
#include "stiffsim/model/compliant.h"
#include "stiffsim/model/rigid_tree.h"
#include "stiffsim/model/urdf.h"

namespace stiffsim {
namespace {

namespace fs = std::filesystem;

const fs::path kRobots = fs::path(STIFFSIM_SOURCE_DIR) / "tests" / "data" / "urdf";

struct Robot {
  const char* file;
  int dofs;           // 1-DOF joints, the nv of the welded base
  double total_mass;  // the sum of every <mass> in the file, kg
};

const Robot kRobotList[] = {
    {"simple_humanoid.urdf", 29, 130.8},  // 29 revolute joints
    {"anymal_b.urdf", 12, 30.475397462},  // quadruped, dummy root 'base'
    {"tsid_quadruped.urdf", 8, 2.772},    // point-mass feet on fixed joints
    {"finger_edu.urdf", 3, 2.33778},      // the lower link leans on its tip
};

RigidTree load(const Robot& robot, bool floating_base, std::vector<std::string>* notes = nullptr) {
  UrdfOptions options;
  options.floating_base = floating_base;
  return load_urdf((kRobots / robot.file).string(), options, notes);
}

// Joints from -1 to 1 rad (and a random unit quaternion), velocities from
// -2 to 2: a generic state, away from the all-zero one where terms vanish.
void random_state(const ArticulatedSystem& sys, unsigned seed, Eigen::VectorXd* q,
                  Eigen::VectorXd* v) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  *q = Eigen::VectorXd::NullaryExpr(sys.dimensions().nq, [&] { return u(rng); });
  sys.project_positions(*q);
  *v = Eigen::VectorXd::NullaryExpr(sys.dimensions().nv, [&] { return 2.0 * u(rng); });
}

Eigen::VectorXd forces_at(const ArticulatedSystem& sys, const Eigen::VectorXd& q,
                          const Eigen::VectorXd& v) {
  Eigen::VectorXd F(sys.dimensions().nv);
  sys.forces(0.0, q, v, Eigen::VectorXd(), F);
  return F;
}

// A joint spring and damper on every 1-DOF joint, so that K and D carry
// joint terms beside the rigid-body ones.
ArticulatedOptions with_joint_forces(const RigidTree& tree) {
  ArticulatedOptions options;
  options.joint_forces.resize(tree.bodies.size());
  for (size_t i = 0; i < tree.bodies.size(); ++i) {
    if (joint_nv(tree.bodies[i].type) == 1) options.joint_forces[i] = JointForce{5.0, 0.1, 0.2};
  }
  return options;
}

TEST(RobotUrdf, EveryModelLoadsWithItsWholeMass) {
  for (const Robot& robot : kRobotList) {
    SCOPED_TRACE(robot.file);
    std::vector<std::string> notes;
    const RigidTree welded = load(robot, false, &notes);
    EXPECT_EQ(static_cast<int>(welded.bodies.size()), robot.dofs);
    // Geometry at least is always there, and said once.
    EXPECT_EQ(notes.size(), 1u);
    const RigidTree floating = load(robot, true);
    ASSERT_EQ(static_cast<int>(floating.bodies.size()), robot.dofs + 1);
    EXPECT_EQ(floating.bodies[0].type, JointType::kFloating);
    // On a floating base nothing is welded to the world: every link's mass,
    // point masses included, ends up in some body.
    double mass = 0.0;
    for (const TreeBody& body : floating.bodies) mass += body.inertia.mass;
    EXPECT_NEAR(mass, robot.total_mass, 1e-12 * robot.total_mass);
  }
}

void expect_sound_dynamics(const ArticulatedSystem& sys, unsigned seed) {
  const int nq = sys.dimensions().nq, nv = sys.dimensions().nv;
  const State initial = sys.initial_state();
  const Eigen::VectorXd F0 = forces_at(sys, initial.x.head(nq), initial.x.segment(nq, nv));
  EXPECT_TRUE(F0.allFinite()) << F0.transpose();

  Eigen::VectorXd q, v;
  random_state(sys, seed, &q, &v);
  const Eigen::VectorXd F = forces_at(sys, q, v);
  EXPECT_TRUE(F.allFinite()) << F.transpose();

  SparseMatrix sparse_M = sys.mass_matrix_pattern();
  sys.mass_matrix(q, &sparse_M);
  const Eigen::MatrixXd M(sparse_M);
  const double m_scale = M.cwiseAbs().maxCoeff();
  // Both triangles come from the same composite inertia products.
  EXPECT_LE((M - M.transpose()).cwiseAbs().maxCoeff(), 1e-14 * m_scale);
  EXPECT_EQ(Eigen::LLT<Eigen::MatrixXd>(M).info(), Eigen::Success);
  // The condition of M stays below 2e4 on these models (a light lower leg
  // or finger link beside a floating base); a singular M would show a
  // smallest eigenvalue of rounding size, ~1e-16 of the largest.
  const Eigen::VectorXd eig = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(M).eigenvalues();
  EXPECT_GT(eig.minCoeff(), 1e-9 * eig.maxCoeff()) << "eigenvalues " << eig.transpose();

  // K = dF/dq and D = dF/dv against central differences over every column
  // (quaternion components perturbed one at a time, as F reads them). With
  // eps = 1e-6 on coordinates of order 1 (rad, m, unit quaternion) the
  // truncation error is ~eps^2 |F'''| ~ 1e-12 and the rounding error
  // ~1e-16 |F| / eps ~ 1e-10 times the ratio of |F| to the largest entry;
  // measured at most 7e-9 of the largest entry here. 1e-6 keeps a margin of
  // 100 and is still far below any missing or wrong term.
  ForceJacobians J = sys.jacobian_pattern();
  sys.force_jacobians(0.0, q, v, Eigen::VectorXd(), JacobianRequest{}, &J);
  const Eigen::MatrixXd K(J.dF_dq), D(J.dF_dv);
  const double eps = 1e-6;
  double worst = 0.0, scale = 1.0;
  for (int j = 0; j < nq + nv; ++j) {
    Eigen::VectorXd qp = q, qm = q, vp = v, vm = v;
    if (j < nq) {
      qp[j] += eps, qm[j] -= eps;
    } else {
      vp[j - nq] += eps, vm[j - nq] -= eps;
    }
    const Eigen::VectorXd column = (forces_at(sys, qp, vp) - forces_at(sys, qm, vm)) / (2.0 * eps);
    const Eigen::VectorXd mine =
        j < nq ? Eigen::VectorXd(K.col(j)) : Eigen::VectorXd(D.col(j - nq));
    worst = std::max(worst, (column - mine).cwiseAbs().maxCoeff());
    scale = std::max(scale, column.cwiseAbs().maxCoeff());
  }
  EXPECT_LT(worst, 1e-6 * scale) << "largest entry " << scale;

  // The analytic derivatives (force_jacobians) against the forward-mode
  // differentiation of F (automatic_force_jacobians), with the inertial term
  // of an acceleration: both exact, so they agree to rounding.
  const Eigen::VectorXd a = Eigen::VectorXd::LinSpaced(nv, -1.0, 1.5);
  JacobianRequest request;
  request.acceleration = a.data();
  ForceJacobians analytic = sys.jacobian_pattern(), automatic = sys.jacobian_pattern();
  sys.force_jacobians(0.0, q, v, Eigen::VectorXd(), request, &analytic);
  sys.automatic_force_jacobians(0.0, q, v, Eigen::VectorXd(), request, &automatic);
  for (auto m : {&ForceJacobians::dF_dq, &ForceJacobians::dF_dv}) {
    const Eigen::MatrixXd A(analytic.*m), B(automatic.*m);
    EXPECT_LE((A - B).cwiseAbs().maxCoeff(), 1e-10 * B.cwiseAbs().maxCoeff());
  }
}

TEST(RobotUrdf, ExactSystemsOnAWeldedBaseAreSound) {
  unsigned seed = 100;
  for (const Robot& robot : kRobotList) {
    SCOPED_TRACE(robot.file);
    const RigidTree tree = load(robot, false);
    const ArticulatedSystem sys(tree, with_joint_forces(tree));
    EXPECT_EQ(sys.dimensions().nv, robot.dofs);
    expect_sound_dynamics(sys, ++seed);
  }
}

TEST(RobotUrdf, ExactSystemsOnAFloatingBaseAreSound) {
  unsigned seed = 200;
  for (const Robot& robot : kRobotList) {
    SCOPED_TRACE(robot.file);
    const RigidTree tree = load(robot, true);
    const ArticulatedSystem sys(tree, with_joint_forces(tree));
    EXPECT_EQ(sys.dimensions().nv, robot.dofs + 6);
    EXPECT_EQ(sys.dimensions().nq, robot.dofs + 7);
    expect_sound_dynamics(sys, ++seed);
  }
}

// The same trees as free bodies held by bushings: every body needs its own
// mass and inertia there, which the welded point masses and the dummy root
// must not take away.
TEST(RobotUrdf, CompliantSystemsBuildWithFiniteForces) {
  for (const Robot& robot : kRobotList) {
    SCOPED_TRACE(robot.file);
    const RigidTree tree = load(robot, true);
    const auto sys = make_compliant(tree, with_joint_forces(tree), BushingParameters{});
    const int nq = sys->dimensions().nq, nv = sys->dimensions().nv;
    const State initial = sys->initial_state();
    EXPECT_TRUE(forces_at(*sys, initial.x.head(nq), initial.x.segment(nq, nv)).allFinite());
    EXPECT_EQ(nv, 6 * (robot.dofs + 1));
  }
}

}  // namespace
}  // namespace stiffsim
