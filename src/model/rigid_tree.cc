#include "stiffsim/model/rigid_tree.h"

namespace stiffsim {

const char* joint_type_name(JointType type) {
  switch (type) {
    case JointType::kRevolute:
      return "revolute";
    case JointType::kPrismatic:
      return "prismatic";
    case JointType::kFloating:
      return "floating";
    case JointType::kPlanar:
      return "planar";
  }
  return "unknown";
}

int joint_nq(JointType type) {
  switch (type) {
    case JointType::kRevolute:
    case JointType::kPrismatic:
      return 1;
    case JointType::kFloating:
      return 7;  // translation, then a unit quaternion
    case JointType::kPlanar:
      return 3;
  }
  return 0;
}

int joint_nv(JointType type) {
  switch (type) {
    case JointType::kRevolute:
    case JointType::kPrismatic:
      return 1;
    case JointType::kFloating:
      return 6;
    case JointType::kPlanar:
      return 3;
  }
  return 0;
}

namespace {

// The parallel-axis term: the inertia of a unit point mass at `d` about the
// origin.
Eigen::Matrix3d point_inertia(const Eigen::Vector3d& d) {
  return d.squaredNorm() * Eigen::Matrix3d::Identity() - d * d.transpose();
}

}  // namespace

RigidInertia combine(const RigidInertia& a, const RigidInertia& b) {
  RigidInertia sum;
  sum.mass = a.mass + b.mass;
  // A massless part (a frame, a sensor) must change nothing, not even by
  // rounding: the union's COM is then exactly the other part's.
  if (b.mass == 0.0) {
    sum.com = a.com;
  } else if (a.mass == 0.0) {
    sum.com = b.com;
  } else {
    sum.com = (a.mass * a.com + b.mass * b.com) / sum.mass;
  }
  sum.inertia = a.inertia + a.mass * point_inertia(a.com - sum.com) + b.inertia +
                b.mass * point_inertia(b.com - sum.com);
  // Rounding in the parallel-axis terms must not make M slightly asymmetric.
  sum.inertia = 0.5 * (sum.inertia + sum.inertia.transpose()).eval();
  return sum;
}

RigidInertia transform(const RigidInertia& inertia, const Eigen::Isometry3d& pose) {
  RigidInertia out;
  out.mass = inertia.mass;
  out.com = pose * inertia.com;
  const Eigen::Matrix3d r = pose.linear();
  out.inertia = r * inertia.inertia * r.transpose();
  out.inertia = 0.5 * (out.inertia + out.inertia.transpose()).eval();
  return out;
}

RigidTree make_chain_tree(int links, const std::string& name) {
  RigidTree t;
  t.name = name;
  t.file = "chain_" + std::to_string(links) + " (built in code)";
  for (int i = 0; i < links; ++i) {
    TreeBody b;
    b.link = "link_" + std::to_string(i + 1);
    b.joint = "joint_" + std::to_string(i + 1);
    b.parent = i - 1;
    b.type = JointType::kRevolute;
    b.axis = Eigen::Vector3d::UnitY();
    if (i > 0) b.placement.translation() = Eigen::Vector3d(0.0, 0.0, -0.1);
    b.inertia.mass = 0.1;
    b.inertia.com = Eigen::Vector3d(0.0, 0.0, -0.05);
    b.inertia.inertia = Eigen::Vector3d(0.1 * 0.01 / 12.0, 0.1 * 0.01 / 12.0, 1e-6).asDiagonal();
    t.bodies.push_back(b);
  }
  return t;
}

}  // namespace stiffsim
