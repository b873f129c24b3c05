// Attachments between components (attachment.h, Scene): a rope hung on a
// link of a chain, a link tied to another link of its own tree, a rope end
// tied to the world. The coupled Jacobians (off-diagonal blocks included)
// against central differences of the scene's forces, energy conserved
// without dampers, linear momentum conserved between two free ropes.

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <memory>

#include "stiffsim/error.h"
#include "stiffsim/integrators/runge_kutta45.h"
#include "stiffsim/integrators/velocity_implicit_euler.h"
#include "stiffsim/model/articulated.h"
#include "stiffsim/model/compliant.h"
#include "stiffsim/model/particle_meshes.h"
#include "stiffsim/model/particles.h"
#include "stiffsim/model/urdf.h"
#include "stiffsim/scene.h"

namespace stiffsim {
namespace {

using Eigen::MatrixXd;
using Eigen::Vector3d;
using Eigen::VectorXd;

std::unique_ptr<ParticleSystem> free_rope(const std::string& name, int nodes, double c,
                                          Vector3d gravity, Vector3d shift = Vector3d::Zero()) {
  RopeSpec spec;
  spec.name = name;
  spec.nodes = nodes;
  spec.length = 0.5;
  spec.total_mass = 0.05;
  spec.stretch = SpringParameters{2e3, c};
  spec.bend = SpringParameters{1.0, 0.1 * c};
  spec.pinned = std::vector<int>{};
  spec.gravity = gravity;
  ParticleDescription d = make_rope(spec);
  for (Vector3d& p : d.positions) p += shift;
  return std::make_unique<ParticleSystem>(d);
}

std::unique_ptr<ArticulatedSystem> chain(int links, double damping) {
  ArticulatedOptions o;
  o.initial_q = VectorXd::LinSpaced(links, 0.3, -0.2);
  o.joint_forces.assign(links, JointForce{0.0, 0.0, damping});
  return std::make_unique<ArticulatedSystem>(make_chain_tree(links), o);
}

// A chain of 3 links, then a rope whose node 0 hangs at a point of link 2
// (body index 2, 0.1 m down its axis and off to the side), whose last node
// is tied to a world point, and link 0 tied to link 2 within the chain.
std::unique_ptr<Scene> hung_rope(double c) {
  std::vector<std::unique_ptr<System>> parts;
  parts.push_back(chain(3, c));
  const Vector3d tip(0.02, 0.0, -0.1);
  parts.push_back(free_rope("rope", 5, c, Vector3d(0, 0, -9.81), Vector3d(0.05, 0.0, -0.3)));
  std::vector<Attachment> at(3);
  at[0] = {"grip", {0, 2, tip}, {1, 0, Vector3d::Zero()}, 1e3, 2.0 * c};
  at[1] = {"tail", {1, 4, Vector3d::Zero()}, {-1, 0, Vector3d(0.6, 0.1, -0.3)}, 50.0, c};
  at[2] = {"brace", {0, 0, Vector3d(0.0, 0.03, -0.05)}, {0, 2, Vector3d(0.01, 0, 0)}, 30.0, c};
  return std::make_unique<Scene>("hung", std::move(parts), std::move(at));
}

VectorXd scene_forces(const Scene& s, double t, const VectorXd& q, const VectorXd& v) {
  VectorXd F(s.dimensions().nv);
  s.forces(t, q, v, VectorXd(), F);
  return F;
}

// A state away from rest: positions moved, every velocity nonzero.
State moving_state(const Scene& s) {
  State x = s.initial_state();
  const Dimensions d = s.dimensions();
  for (int i = 0; i < d.nq; ++i) x.x[i] += 0.03 * std::sin(1.3 * i + 0.2);
  for (int i = 0; i < d.nv; ++i) x.x[d.nq + i] = 0.7 * std::cos(0.9 * i);
  return x;
}

void expect_jacobians_match_differences(const Scene& s, bool complete) {
  const Dimensions d = s.dimensions();
  const State x = moving_state(s);
  const VectorXd q = x.x.head(d.nq), v = x.x.segment(d.nq, d.nv);
  MatrixXd Kd(d.nv, d.nq), Dd(d.nv, d.nv);
  for (int j = 0; j < d.nq; ++j) {
    VectorXd qp = q, qm = q;
    qp[j] += 1e-6;
    qm[j] -= 1e-6;
    Kd.col(j) = (scene_forces(s, 0.2, qp, v) - scene_forces(s, 0.2, qm, v)) / 2e-6;
  }
  for (int j = 0; j < d.nv; ++j) {
    VectorXd vp = v, vm = v;
    vp[j] += 1e-3;
    vm[j] -= 1e-3;
    Dd.col(j) = (scene_forces(s, 0.2, q, vp) - scene_forces(s, 0.2, q, vm)) / 2e-3;
  }
  ForceJacobians J = s.jacobian_pattern();
  JacobianRequest request;
  request.complete = complete;
  s.force_jacobians(0.2, q, v, VectorXd(), request, &J);
  const MatrixXd K = MatrixXd(J.dF_dq), D = MatrixXd(J.dF_dv);
  // The chain's rows (0..2) against the rope's columns (3..17) and back:
  // the coupling blocks are there and right.
  EXPECT_GT(Kd.block(0, 3, 3, 15).norm(), 1.0);
  EXPECT_LT((K - Kd).norm(), 1e-6 * Kd.norm()) << "K\n" << K - Kd;
  EXPECT_LT((D - Dd).norm(), 1e-8 * std::max(Dd.norm(), 1.0)) << "D\n" << D - Dd;
  EXPECT_LT((K.block(0, 3, 3, 15) - Kd.block(0, 3, 3, 15)).norm(), 1e-6 * Kd.norm());
  EXPECT_LT((K.block(3, 0, 15, 3) - Kd.block(3, 0, 15, 3)).norm(), 1e-6 * Kd.norm());
}

// The attachments' share of K and D at (q, v) (the scene's minus the same
// scene's without them, so the components' own Jacobians, checked
// elsewhere, drop out) and the central differences of their forces.
struct AttachmentShare {
  MatrixXd K, D, Kd, Dd;
};

AttachmentShare attachment_share(const Scene& with, const Scene& without, const VectorXd& q,
                                 const VectorXd& v) {
  const Dimensions d = with.dimensions();
  auto forces = [&](const VectorXd& qq, const VectorXd& vv) -> VectorXd {
    return scene_forces(with, 0.1, qq, vv) - scene_forces(without, 0.1, qq, vv);
  };
  AttachmentShare out{MatrixXd(), MatrixXd(), MatrixXd(d.nv, d.nq), MatrixXd(d.nv, d.nv)};
  for (int j = 0; j < d.nq; ++j) {
    VectorXd qp = q, qm = q;
    qp[j] += 1e-6;
    qm[j] -= 1e-6;
    out.Kd.col(j) = (forces(qp, v) - forces(qm, v)) / 2e-6;
  }
  for (int j = 0; j < d.nv; ++j) {
    VectorXd vp = v, vm = v;
    vp[j] += 1e-3;
    vm[j] -= 1e-3;
    out.Dd.col(j) = (forces(q, vp) - forces(q, vm)) / 2e-3;
  }
  auto jacobians = [&](const Scene& s) {
    ForceJacobians J = s.jacobian_pattern();
    JacobianRequest complete;
    complete.complete = true;
    s.force_jacobians(0.1, q, v, VectorXd(), complete, &J);
    return std::make_pair(MatrixXd(J.dF_dq), MatrixXd(J.dF_dv));
  };
  const auto [Kw, Dw] = jacobians(with);
  const auto [Ko, Do] = jacobians(without);
  out.K = Kw - Ko;
  out.D = Dw - Do;
  return out;
}

TEST(Attachment, CompleteJacobiansMatchCentralDifferences) {
  expect_jacobians_match_differences(*hung_rope(0.5), true);
}

TEST(Attachment, JacobiansMatchDifferencesOnAnArmWithCrossedAxes) {
  // models/arm.urdf: a vertical axis, then three horizontal ones; the rope
  // hangs at a point off the gripper's axis.
  std::vector<std::unique_ptr<System>> parts;
  ArticulatedOptions o;
  o.initial_q = VectorXd::LinSpaced(4, 0.4, -0.3);
  parts.push_back(std::make_unique<ArticulatedSystem>(
      load_urdf(std::string(STIFFSIM_SOURCE_DIR) + "/models/arm.urdf", UrdfOptions{}, nullptr), o));
  parts.push_back(free_rope("rope", 5, 0.5, Vector3d(0, 0, -9.81), Vector3d(0.9, 0.0, 0.1)));
  std::vector<Attachment> at = {
      {"grip", {0, 3, Vector3d(0.1, 0.02, -0.01)}, {1, 0, Vector3d::Zero()}, 1e3, 4.0}};
  const Scene s("arm", std::move(parts), std::move(at));
  const Dimensions d = s.dimensions();
  const State x = moving_state(s);
  const VectorXd q = x.x.head(d.nq), v = x.x.segment(d.nq, d.nv);
  MatrixXd Kd(d.nv, d.nq), Dd(d.nv, d.nv);
  for (int j = 0; j < d.nq; ++j) {
    VectorXd qp = q, qm = q, vp = v, vm = v;
    qp[j] += 1e-6;
    qm[j] -= 1e-6;
    vp[j] += 1e-3;
    vm[j] -= 1e-3;
    Kd.col(j) = (scene_forces(s, 0.0, qp, v) - scene_forces(s, 0.0, qm, v)) / 2e-6;
    Dd.col(j) = (scene_forces(s, 0.0, q, vp) - scene_forces(s, 0.0, q, vm)) / 2e-3;
  }
  ForceJacobians J = s.jacobian_pattern();
  JacobianRequest complete;
  complete.complete = true;
  s.force_jacobians(0.0, q, v, VectorXd(), complete, &J);
  EXPECT_LT((MatrixXd(J.dF_dq) - Kd).norm(), 1e-6 * Kd.norm()) << MatrixXd(J.dF_dq) - Kd;
  EXPECT_LT((MatrixXd(J.dF_dv) - Dd).norm(), 1e-8 * Dd.norm());
}

TEST(Attachment, SymmetricJacobiansAreExactWithoutDampers) {
  // Without dampers nothing is dropped: K is exact, and the attachments'
  // share of it (the scene's less the same components' without them) is
  // symmetric (the chain's own K is not, at nonzero velocity).
  const auto s = hung_rope(0.0);
  expect_jacobians_match_differences(*s, false);
  std::vector<std::unique_ptr<System>> parts;
  parts.push_back(chain(3, 0.0));
  parts.push_back(free_rope("rope", 5, 0.0, Vector3d(0, 0, -9.81), Vector3d(0.05, 0.0, -0.3)));
  const Scene bare("bare", std::move(parts));
  const State x = moving_state(*s);
  const Dimensions d = s->dimensions();
  auto stiffness = [&](const Scene& scene) {
    ForceJacobians J = scene.jacobian_pattern();
    scene.force_jacobians(0.0, x.x.head(d.nq), x.x.segment(d.nq, d.nv), VectorXd(),
                          JacobianRequest{}, &J);
    return MatrixXd(J.dF_dq);
  };
  const MatrixXd share = stiffness(*s) - stiffness(bare);
  EXPECT_GT(share.norm(), 1.0);
  EXPECT_LT((share - share.transpose()).norm(), 1e-12 * share.norm());
}

// RK45 at 1e-10 from the scene's initial state to t_final: the largest
// drift of its total energy (the attachments' springs included) at samples
// every 0.05 s, and how far the state moved.
struct EnergyDrift {
  double worst = 0.0, moved = 0.0, e0 = 0.0;
};

EnergyDrift energy_drift(const Scene& s, double t_final) {
  IntegratorSettings tight;
  tight.accuracy = 1e-10;
  RungeKutta45 rk(s, tight);
  rk.initialize(s.initial_state());
  EnergyDrift out;
  out.e0 = s.energy(s.initial_state());
  for (double t = 0.05; t <= t_final + 1e-9; t += 0.05) {
    rk.integrate_to(t);
    out.worst = std::max(out.worst, std::abs(s.energy(rk.state()) - out.e0));
  }
  out.moved = (rk.state().x - s.initial_state().x).norm();
  return out;
}

TEST(Attachment, EnergyIsConservedWithoutDampers) {
  // Chain, rope and the three springs, no damper anywhere, under gravity:
  // RK45 at 1e-10 keeps the total energy to its own tolerance. Scale: the
  // energy that moves (the rope falls about 0.1 m).
  const EnergyDrift e = energy_drift(*hung_rope(0.0), 0.5);
  EXPECT_LT(e.worst, 1e-7) << "e0 = " << e.e0;
  EXPECT_GT(e.moved, 1e-2);  // and it did move
}

TEST(Attachment, FreeRopesKeepTheirLinearMomentum) {
  // Two free ropes without gravity, tied end to end by a damped spring and
  // started apart and moving: internal forces only, so sum m v is constant.
  // Implicit Euler keeps linear invariants exactly (up to the Newton
  // tolerance); RK45 to its accuracy.
  std::vector<std::unique_ptr<System>> parts;
  parts.push_back(free_rope("left", 4, 0.3, Vector3d::Zero()));
  parts.push_back(free_rope("right", 4, 0.3, Vector3d::Zero(), Vector3d(0.7, 0.1, 0.0)));
  std::vector<Attachment> at = {
      {"tie", {0, 3, Vector3d::Zero()}, {1, 0, Vector3d::Zero()}, 500.0, 1.0}};
  Scene s("ropes", std::move(parts), std::move(at));
  const Dimensions d = s.dimensions();
  State x0 = s.initial_state();
  for (int i = 0; i < d.nv; ++i) x0.x[d.nq + i] = 0.5 * std::sin(2.1 * i);
  auto momentum = [&](const Eigen::VectorXd& x) {
    Vector3d p = Vector3d::Zero();
    for (int c = 0; c < 2; ++c) {
      const auto& rope = dynamic_cast<const ParticleSystem&>(s.component(c));
      for (int n = 0; n < rope.node_count(); ++n) {
        p += rope.description().masses[n] *
             x.segment<3>(d.nq + s.offsets(c).nv + rope.dof_of_node(n));
      }
    }
    return p;
  };
  const Vector3d p0 = momentum(x0.x);
  IntegratorSettings fixed;
  fixed.fixed_step = true;
  fixed.max_step = 0.01;
  fixed.accuracy = 1e-10;
  VelocityImplicitEuler vie(s, fixed, ImplicitSettings{});
  vie.initialize(x0);
  vie.integrate_to(1.0);
  EXPECT_LT((momentum(vie.state().x) - p0).norm(), 1e-9 * (1.0 + p0.norm()));
  // The tie pulled: the ends met (the spring's rest length is zero).
  const Vector3d gap = vie.state().x.segment<3>(s.offsets(1).nq) - vie.state().x.segment<3>(9);
  EXPECT_LT(gap.norm(), 0.7);
}

// A sled on a tilted plane (a planar root whose frame is turned and moved),
// an arm turning on it, a slider on the arm; a rope hangs from the slider
// and a brace ties the sled to the world. The planar root's three dofs
// (two in-plane translations, then the turn about the normal through the
// moved origin) enter the coupled Jacobians like any other joint's.
std::unique_ptr<Scene> rope_on_a_sled(double c, bool attached = true) {
  RigidTree tree;
  tree.name = "sled";
  tree.file = "sled (built in code)";
  auto add = [&](const char* link, int parent, JointType type, Vector3d axis, Vector3d at) {
    TreeBody b;
    b.link = link;
    b.joint = std::string(link) + "_joint";
    b.parent = parent;
    b.type = type;
    b.axis = axis.normalized();
    b.placement.translation() = at;
    b.inertia.mass = 0.2;
    b.inertia.com = Vector3d(0.01, -0.02, -0.05);
    b.inertia.inertia = Vector3d(2e-4, 3e-4, 1e-4).asDiagonal();
    tree.bodies.push_back(b);
  };
  add("sled", -1, JointType::kPlanar, Vector3d(0.1, 0.3, 1.0), Vector3d(0.05, -0.02, 0.1));
  tree.bodies[0].placement.linear() =
      Eigen::AngleAxisd(0.4, Vector3d(1.0, -0.5, 0.2).normalized()).toRotationMatrix();
  add("arm", 0, JointType::kRevolute, Vector3d(0.2, 1.0, 0.0), Vector3d(0.0, 0.05, -0.1));
  add("slider", 1, JointType::kPrismatic, Vector3d(0.0, 0.3, -1.0), Vector3d(0.02, 0.0, -0.1));
  ArticulatedOptions o;
  o.initial_q = (VectorXd(5) << 0.1, -0.05, 0.7, 0.3, 0.02).finished();
  o.initial_v = VectorXd::Zero(5);
  std::vector<std::unique_ptr<System>> parts;
  parts.push_back(std::make_unique<ArticulatedSystem>(tree, o));
  parts.push_back(free_rope("rope", 5, c, Vector3d(0, 0, -9.81), Vector3d(0.1, 0.0, -0.2)));
  std::vector<Attachment> at;
  if (attached) {
    at = {{"grip", {0, 2, Vector3d(0.03, -0.01, -0.02)}, {1, 0, Vector3d::Zero()}, 1e3, 2.0 * c},
          {"brace", {0, 0, Vector3d(0.04, 0.02, 0.0)}, {-1, 0, Vector3d(0.3, -0.1, 0.2)}, 40.0, c},
          {"tie", {0, 0, Vector3d(-0.02, 0.05, 0.01)}, {0, 2, Vector3d(0.01, 0.0, 0.0)}, 25.0, c}};
  }
  return std::make_unique<Scene>("sled", std::move(parts), std::move(at));
}

TEST(Attachment, JacobiansMatchDifferencesOnAPlanarRoot) {
  const auto with = rope_on_a_sled(0.5), without = rope_on_a_sled(0.5, false);
  ASSERT_EQ(with->component(0).point_elements(), 3);
  EXPECT_EQ(with->component(0).point_dofs(2), 5);
  const Dimensions d = with->dimensions();
  const State x = moving_state(*with);
  const auto [K, D, Kd, Dd] =
      attachment_share(*with, *without, x.x.head(d.nq), x.x.segment(d.nq, d.nv));
  // The sled's rows against the rope's columns: the coupling is there.
  EXPECT_GT(Kd.block(0, 5, 5, 15).norm(), 1.0);
  EXPECT_LT((K - Kd).norm(), 1e-6 * Kd.norm()) << "K\n" << K - Kd;
  EXPECT_LT((D - Dd).norm(), 1e-8 * Dd.norm()) << "D\n" << D - Dd;
}

TEST(Attachment, PointVelocityOnAPlanarRootMatchesDifferences) {
  // p_dot from the point kinematics against the motion of p itself.
  const auto s = rope_on_a_sled(0.5);
  const System& sled = s->component(0);
  const State x = moving_state(*s);
  const Dimensions d = sled.dimensions();
  const VectorXd q = x.x.head(d.nq), v = x.x.segment(s->dimensions().nq, d.nv);
  PointKinematics k, kp, km;
  const Vector3d local(0.03, -0.01, -0.02);
  sled.point_kinematics(0.0, 2, local, q, v, &k);
  const double dt = 1e-6;
  sled.point_kinematics(0.0, 2, local, q + dt * v, v, &kp);
  sled.point_kinematics(0.0, 2, local, q - dt * v, v, &km);
  EXPECT_LT((k.p_dot - (kp.p - km.p) / (2 * dt)).norm(), 1e-8 * k.p_dot.norm());
  ASSERT_EQ(k.dofs.size(), 5u);
  for (int j = 0; j < 5; ++j) EXPECT_EQ(k.dofs[j], j);
}

TEST(Attachment, EnergyIsConservedOnAPlanarRootWithoutDampers) {
  // No dampers, no joint damping: the same bound as the chain's above (the
  // rope and the sled fall about 0.1 m, energies of order 0.1 J).
  const EnergyDrift e = energy_drift(*rope_on_a_sled(0.0), 0.3);
  EXPECT_LT(e.worst, 1e-7) << "e0 = " << e.e0;
  EXPECT_GT(e.moved, 1e-2);
}

// A free body (floating root, turned by a unit quaternion away from the
// identity) with an arm on a revolute joint below it: a drone with a boom.
// A rope hangs from the boom's tip, the body is tied to the world and the
// boom to the body. With `on_a_mast`, the floating joint sits on a mast
// turning about a revolute joint at the root, so a turn upstream of the
// quaternion moves its columns too.
std::unique_ptr<ArticulatedSystem> drone(bool on_a_mast = false, bool gravity = true) {
  RigidTree tree;
  tree.name = "drone";
  tree.file = "drone (built in code)";
  if (on_a_mast) {
    TreeBody mast;
    mast.link = "mast";
    mast.joint = "swivel";
    mast.axis = Vector3d(0.1, -0.2, 1.0).normalized();
    mast.placement.translation() = Vector3d(0.0, 0.05, 0.0);
    mast.inertia.mass = 0.5;
    mast.inertia.com = Vector3d(0.05, 0.0, 0.1);
    mast.inertia.inertia = Vector3d(1e-3, 2e-3, 1e-3).asDiagonal();
    tree.bodies.push_back(mast);
  }
  const int base = on_a_mast ? 1 : 0;
  TreeBody body;
  body.parent = base - 1;
  body.link = "body";
  body.joint = "floating_base";
  body.type = JointType::kFloating;
  body.placement.translation() = Vector3d(0.02, -0.01, 0.05);
  body.placement.linear() =
      Eigen::AngleAxisd(0.3, Vector3d(0.2, 1.0, -0.4).normalized()).toRotationMatrix();
  body.inertia.mass = 1.0;
  body.inertia.com = Vector3d(0.01, 0.0, -0.02);
  body.inertia.inertia = Vector3d(0.02, 0.015, 0.01).asDiagonal();
  tree.bodies.push_back(body);
  TreeBody boom;
  boom.link = "boom";
  boom.joint = "hinge";
  boom.parent = base;
  boom.axis = Vector3d(0.3, 1.0, 0.1).normalized();
  boom.placement.translation() = Vector3d(0.1, 0.0, -0.05);
  boom.inertia.mass = 0.1;
  boom.inertia.com = Vector3d(0.1, 0.0, 0.0);
  boom.inertia.inertia = Vector3d(1e-4, 1e-3, 1e-3).asDiagonal();
  tree.bodies.push_back(boom);
  ArticulatedOptions o;
  if (!gravity) o.gravity.setZero();
  const Eigen::Vector4d quat = Eigen::Vector4d(0.9, 0.2, -0.3, 0.25).normalized();
  o.initial_q = (VectorXd(8) << 0.1, -0.2, 0.3, quat, 0.4).finished();
  o.initial_v = (VectorXd(7) << 0.3, -0.1, 0.2, 0.5, -0.7, 0.4, 1.1).finished();
  if (on_a_mast) {
    o.initial_q = (VectorXd(9) << 0.6, o.initial_q).finished();
    o.initial_v = (VectorXd(8) << -0.8, o.initial_v).finished();
  }
  return std::make_unique<ArticulatedSystem>(tree, o);
}

std::unique_ptr<Scene> rope_on_a_drone(double c, bool attached, bool on_a_mast = false) {
  std::vector<std::unique_ptr<System>> parts;
  parts.push_back(drone(on_a_mast));
  const int base = on_a_mast ? 1 : 0;
  parts.push_back(free_rope("rope", 5, c, Vector3d(0, 0, -9.81), Vector3d(0.2, 0.0, -0.2)));
  std::vector<Attachment> at;
  if (attached) {
    at = {
        {"grip", {0, base + 1, Vector3d(0.2, 0.01, -0.02)}, {1, 0, Vector3d::Zero()}, 1e3, 2.0 * c},
        {"tether",
         {0, base, Vector3d(0.04, 0.02, 0.03)},
         {-1, 0, Vector3d(0.3, -0.1, 0.6)},
         40.0,
         c},
        {"brace",
         {0, base, Vector3d(-0.02, 0.05, 0.01)},
         {0, base + 1, Vector3d(0.05, 0.0, 0.01)},
         25.0,
         c}};
  }
  return std::make_unique<Scene>("drone", std::move(parts), std::move(at));
}

class FloatingAttachment : public ::testing::TestWithParam<bool> {};

TEST_P(FloatingAttachment, JacobiansMatchDifferences) {
  // The attachments' share of K and D (the scene's minus the same scene's
  // without them), quaternion columns included, against central
  // differences of their forces: q moves off the unit sphere, where R(q)
  // normalizes, so the differences are those of the same function.
  const bool mast = GetParam();
  const int base = mast ? 1 : 0;
  const auto with = rope_on_a_drone(0.5, true, mast);
  const auto without = rope_on_a_drone(0.5, false, mast);
  ASSERT_EQ(with->component(0).point_elements(), 2 + base);
  EXPECT_EQ(with->component(0).point_dofs(base + 1), 7 + base);
  const Dimensions d = with->dimensions();
  const State x = with->initial_state();
  const auto [K, D, Kd, Dd] =
      attachment_share(*with, *without, x.x.head(d.nq), x.x.segment(d.nq, d.nv));
  // The quaternion columns of the drone's rows and of the rope's are there.
  EXPECT_GT(Kd.block(0, base + 3, 7 + base, 4).norm(), 1.0);
  EXPECT_GT(Kd.block(7 + base, base + 3, 15, 4).norm(), 1.0);
  EXPECT_LT((K - Kd).norm(), 1e-6 * Kd.norm()) << "K\n" << K - Kd;
  EXPECT_LT((D - Dd).norm(), 1e-8 * Dd.norm()) << "D\n" << D - Dd;
}

INSTANTIATE_TEST_SUITE_P(RootOrOnAMast, FloatingAttachment, ::testing::Bool());

TEST(Attachment, PointVelocityOnAFloatingRootMatchesDifferences) {
  // p_dot against the motion of p along q_dot = N(q) v.
  const auto s = drone();
  const Dimensions d = s->dimensions();
  const State x = s->initial_state();
  const VectorXd q = x.x.head(d.nq), v = x.x.segment(d.nq, d.nv);
  VectorXd qdot(d.nq);
  s->map_velocity_to_qdot(q, v, qdot);
  const Vector3d local(0.2, 0.01, -0.02);
  PointKinematics k, kp, km;
  s->point_kinematics(0.0, 1, local, q, v, &k);
  const double dt = 1e-6;
  s->point_kinematics(0.0, 1, local, q + dt * qdot, v, &kp);
  s->point_kinematics(0.0, 1, local, q - dt * qdot, v, &km);
  EXPECT_LT((k.p_dot - (kp.p - km.p) / (2 * dt)).norm(), 1e-8 * k.p_dot.norm());
  // And each velocity column is dp_dot/dv_j.
  for (int j = 0; j < d.nv; ++j) {
    VectorXd vj = VectorXd::Zero(d.nv);
    vj[j] = 1.0;
    s->map_velocity_to_qdot(q, vj, qdot);
    s->point_kinematics(0.0, 1, local, q + dt * qdot, v, &kp);
    s->point_kinematics(0.0, 1, local, q - dt * qdot, v, &km);
    EXPECT_LT((k.J[j] - (kp.p - km.p) / (2 * dt)).norm(), 1e-8) << "column " << j;
  }
}

TEST(Attachment, ADroneAndItsRopeKeepTheirMomentum) {
  // A free-flying drone and the rope it carries, in no gravity, tied by
  // undamped springs (the rope to the boom, the boom to the body) and
  // nothing else: only internal forces, so the linear momentum and the
  // angular momentum about the origin of drone and rope together stay
  // what they were, while the two trade momentum through the attachment.
  // Runge-Kutta methods keep linear invariants to round-off and RK45 at
  // 1e-10 the angular momentum to its tolerance (measured: 3e-14 and 1e-12
  // against 1.8 traded).
  std::vector<std::unique_ptr<System>> parts;
  parts.push_back(drone(false, false));
  parts.push_back(free_rope("rope", 5, 0.0, Vector3d::Zero(), Vector3d(0.2, 0.0, -0.2)));
  std::vector<Attachment> at = {
      {"grip", {0, 1, Vector3d(0.2, 0.01, -0.02)}, {1, 0, Vector3d::Zero()}, 1e3, 0.0},
      {"brace", {0, 0, Vector3d(-0.02, 0.05, 0.01)}, {0, 1, Vector3d(0.05, 0.0, 0.01)}, 25.0, 0.0}};
  const Scene s("drone", std::move(parts), std::move(at));
  const auto& body = dynamic_cast<const ArticulatedSystem&>(s.component(0));
  const auto& rope = dynamic_cast<const ParticleSystem&>(s.component(1));
  const Dimensions d = s.dimensions(), db = body.dimensions();
  // Angular about the origin, then linear; the rope's alone beside.
  auto momenta = [&](const VectorXd& x) {
    const VectorXd q = x.head(d.nq), v = x.segment(d.nq, d.nv);
    Vec6<double> rope_part = Vec6<double>::Zero();
    for (int n = 0; n < rope.node_count(); ++n) {
      const Vector3d r = q.segment<3>(db.nq + rope.dof_of_node(n));
      const Vector3d p = rope.description().masses[n] * v.segment<3>(db.nv + rope.dof_of_node(n));
      rope_part.head<3>() += r.cross(p);
      rope_part.tail<3>() += p;
    }
    const Vec6<double> total = body.world_momentum(q.head(db.nq), v.head(db.nv)) + rope_part;
    return std::make_pair(total, rope_part);
  };
  State x0 = s.initial_state();
  const auto [total0, rope0] = momenta(x0.x);
  IntegratorSettings tight;
  tight.accuracy = 1e-10;
  RungeKutta45 rk(s, tight);
  rk.initialize(x0);
  rk.integrate_to(0.3);
  const auto [total, rope_now] = momenta(rk.state().x);
  // Scale: the momentum the rope gained from the drone.
  const double traded = (rope_now - rope0).norm();
  EXPECT_GT(traded, 1e-2);
  EXPECT_LT((total.tail<3>() - total0.tail<3>()).norm(), 1e-9 * traded)
      << "linear " << total0.tail<3>().transpose() << " -> " << total.tail<3>().transpose();
  EXPECT_LT((total.head<3>() - total0.head<3>()).norm(), 1e-9 * traded)
      << "angular " << total0.head<3>().transpose() << " -> " << total.head<3>().transpose();
}

TEST(Attachment, EnergyIsConservedOnAFloatingRootWithoutDampers) {
  const EnergyDrift e = energy_drift(*rope_on_a_drone(0.0, true), 0.3);
  EXPECT_LT(e.worst, 1e-7) << "e0 = " << e.e0;
  EXPECT_GT(e.moved, 1e-2);
}

TEST(Attachment, JacobiansMatchDifferencesOnACompliantChain) {
  // A rope on the last link of a compliant chain (three free bodies held by
  // bushings), the first link tied to the second: the attachments' share
  // of K and D against central differences, as for the floating root.
  auto scene = [](bool attached) {
    ArticulatedOptions o;
    o.initial_q = Eigen::Vector3d(0.3, -0.4, 0.5);
    std::vector<std::unique_ptr<System>> parts;
    parts.push_back(make_compliant(make_chain_tree(3), o, BushingParameters{}));
    parts.push_back(free_rope("rope", 5, 0.5, Vector3d(0, 0, -9.81), Vector3d(0.05, 0.0, -0.3)));
    std::vector<Attachment> at;
    if (attached) {
      at = {{"grip", {0, 2, Vector3d(0.02, 0.0, -0.1)}, {1, 0, Vector3d::Zero()}, 1e3, 1.0},
            {"brace", {0, 0, Vector3d(0.0, 0.03, -0.05)}, {0, 1, Vector3d(0.01, 0, 0)}, 30.0, 0.5}};
    }
    return std::make_unique<Scene>("compliant", std::move(parts), std::move(at));
  };
  const auto with = scene(true), without = scene(false);
  const Dimensions d = with->dimensions();
  const State x = moving_state(*with);
  const auto [K, D, Kd, Dd] =
      attachment_share(*with, *without, x.x.head(d.nq), x.x.segment(d.nq, d.nv));
  // The last link's quaternion columns (7 * 2 + 3..6) in the rope's rows.
  EXPECT_GT(Kd.block(18, 17, 15, 4).norm(), 1.0);
  EXPECT_LT((K - Kd).norm(), 1e-6 * Kd.norm()) << "K\n" << K - Kd;
  EXPECT_LT((D - Dd).norm(), 1e-8 * Dd.norm()) << "D\n" << D - Dd;
}

TEST(Attachment, RopeSwingsAlikeOnExactAndCompliantChains) {
  // Independent formulations of one arm: a rope held out sideways from the
  // tip of a hanging 2-link chain swings down and pulls the chain along.
  // With reduced coordinates and with free bodies held by stiff bushings
  // the rope's ends agree to the bushings' compliance (their deflection
  // under newton loads, ~1e-5 m) after 0.3 s in which the free end moves
  // about 0.5 m.
  auto run = [](bool compliant) {
    std::vector<std::unique_ptr<System>> parts;
    ArticulatedOptions o;
    o.initial_q = Eigen::Vector2d::Zero();
    if (compliant) {
      parts.push_back(make_compliant(make_chain_tree(2), o, BushingParameters{}));
    } else {
      parts.push_back(std::make_unique<ArticulatedSystem>(make_chain_tree(2), o));
    }
    RopeSpec spec;
    spec.name = "rope";
    spec.nodes = 10;
    spec.length = 0.5;
    spec.total_mass = 0.05;
    spec.stretch = SpringParameters{2e3, 0.5};
    spec.bend = SpringParameters{0.0, 0.0};
    spec.pinned = std::vector<int>{};
    spec.origin = Vector3d(0.0, 0.0, -0.2);
    spec.direction = Vector3d(1.0, 0.0, 0.0);
    parts.push_back(std::make_unique<ParticleSystem>(make_rope(spec)));
    std::vector<Attachment> grip = {
        {"grip", {0, 1, Vector3d(0.0, 0.0, -0.1)}, {1, 0, Vector3d::Zero()}, 1e4, 5.0}};
    const Scene s("arm", std::move(parts), std::move(grip));
    IntegratorSettings fixed;
    fixed.fixed_step = true;
    fixed.max_step = 1e-4;
    VelocityImplicitEuler vie(s, fixed, ImplicitSettings{});
    vie.initialize(s.initial_state());
    vie.integrate_to(0.3);
    const Dimensions d = s.dimensions();
    return VectorXd(vie.state().x.segment(s.offsets(1).nq, d.nq - s.offsets(1).nq));
  };
  const VectorXd exact = run(false), compliant = run(true);
  const Vector3d start(0.5, 0.0, -0.2);
  EXPECT_GT((exact.segment<3>(27) - start).norm(), 0.2);  // the free end swung
  // Measured: 1.0e-5 m; the bound leaves a factor of ten.
  EXPECT_LT((exact - compliant).lpNorm<Eigen::Infinity>(), 1e-4);
}

TEST(Attachment, BadPointsAreRejected) {
  auto scene_with = [](Attachment a) {
    std::vector<std::unique_ptr<System>> parts;
    parts.push_back(chain(2, 0.0));
    RigidTree tree = make_chain_tree(2);
    parts.push_back(make_compliant(tree, ArticulatedOptions{}, BushingParameters{}));
    Scene s("bad", std::move(parts), {a});
  };
  EXPECT_THROW(scene_with({"x", {0, 5, Vector3d::Zero()}, {-1, 0, Vector3d::Zero()}, 1.0, 0.0}),
               InputError);
  // The compliant chain offers its links too (every one a free body).
  EXPECT_NO_THROW(scene_with({"x", {1, 0, Vector3d::Zero()}, {-1, 0, Vector3d::Zero()}, 1.0, 0.0}));
  EXPECT_THROW(scene_with({"x", {1, 2, Vector3d::Zero()}, {-1, 0, Vector3d::Zero()}, 1.0, 0.0}),
               InputError);
  EXPECT_THROW(scene_with({"x", {0, 1, Vector3d::Zero()}, {-1, 0, Vector3d::Zero()}, -1.0, 0.0}),
               InputError);
  EXPECT_NO_THROW(scene_with({"x", {0, 1, Vector3d::Zero()}, {-1, 0, Vector3d::Zero()}, 1.0, 0.0}));
}

}  // namespace
}  // namespace stiffsim
