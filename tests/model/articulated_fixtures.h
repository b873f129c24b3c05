#pragma once
// Trees built in code for the articulated-body tests, so that the dynamics are
// checked independently of the URDF loader.

#include <Eigen/Geometry>

#include "stiffsim/model/articulated.h"
#include "stiffsim/model/rigid_tree.h"

namespace stiffsim {

// MODELS.md's shipped chain: n rods of 0.1 m and 0.1 kg hanging along -z,
// revolute about y.
inline RigidTree serial_chain(int n) { return make_chain_tree(n); }

// A Y-shaped tree with joints about different axes (one prismatic, one
// planar), rotated joint frames, off-centre masses and inertia tensors with
// products of inertia; optionally on a floating base.
inline RigidTree branched_tree(bool floating_base = false) {
  RigidTree t;
  t.name = "tree";
  auto inertia = [](double m, Eigen::Vector3d com, double a, double b, double c, double roll) {
    RigidInertia I;
    I.mass = m;
    I.com = com;
    const Eigen::Matrix3d R = Eigen::AngleAxisd(roll, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
    I.inertia = R * Eigen::Vector3d(a, b, c).asDiagonal() * R.transpose();
    return I;
  };
  auto pose = [](Eigen::Vector3d p, double angle, Eigen::Vector3d axis) {
    Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
    X.linear() = Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix();
    X.translation() = p;
    return X;
  };
  auto add = [&](std::string name, int parent, JointType type, Eigen::Vector3d axis,
                 Eigen::Isometry3d placement, RigidInertia I) {
    TreeBody b;
    b.link = name;
    b.joint = name + "_joint";
    b.parent = parent;
    b.type = type;
    b.axis = axis.normalized();
    b.placement = placement;
    b.inertia = I;
    t.bodies.push_back(b);
    return static_cast<int>(t.bodies.size()) - 1;
  };
  int root = -1;
  if (floating_base) {
    root = add("base", -1, JointType::kFloating, Eigen::Vector3d::UnitX(), Eigen::Isometry3d::Identity(),
               inertia(2.0, {0.01, -0.02, 0.03}, 0.02, 0.03, 0.04, 0.4));
  }
  const int torso = add("torso", root, JointType::kRevolute, {0, 0, 1}, pose({0, 0, 0.1}, 0.2, {1, 0, 0}),
                        inertia(1.5, {0.0, 0.02, 0.2}, 0.02, 0.015, 0.01, 0.7));
  int arm = torso;
  for (int k = 0; k < 3; ++k) {
    arm = add("left_" + std::to_string(k), arm, k == 1 ? JointType::kPrismatic : JointType::kRevolute,
              k == 0 ? Eigen::Vector3d(0, 1, 0) : Eigen::Vector3d(1, 0.5, 0),
              pose({0.1, 0.15, 0.3 - 0.1 * k}, 0.3 * k, {0, 0, 1}),
              inertia(0.3, {0.05, 0.0, -0.02}, 0.001, 0.002, 0.0015, 0.3 * k));
  }
  arm = torso;
  for (int k = 0; k < 3; ++k) {
    arm = add("right_" + std::to_string(k), arm, JointType::kRevolute,
              k == 2 ? Eigen::Vector3d(0, 0, 1) : Eigen::Vector3d(1, 0, 0),
              pose({-0.1, 0.15, 0.3 - 0.1 * k}, -0.2, {1, 1, 0}),
              inertia(0.25, {-0.05, 0.01, -0.03}, 0.0012, 0.001, 0.002, -0.5 * k));
  }
  add("head", torso, JointType::kPlanar, {0, 1, 1}, pose({0, 0, 0.45}, 0.1, {0, 1, 0}),
      inertia(0.8, {0.0, 0.0, 0.08}, 0.004, 0.005, 0.003, 1.1));
  return t;
}

// A joint spring (stiffness k, rest `rest`) on every 1-DOF joint.
inline std::vector<JointForce> springs_for(const RigidTree& tree, double k, double rest) {
  std::vector<JointForce> f(tree.bodies.size());
  for (std::size_t i = 0; i < f.size(); ++i) {
    if (joint_nv(tree.bodies[i].type) == 1) f[i] = JointForce{k, rest, 0.0};
  }
  return f;
}

}  // namespace stiffsim
