#pragma once
// The immutable description of an exact (reduced-coordinate) articulated
// tree that the recursive algorithms read: the tree, each body's spatial
// inertia, where its joint's coordinates sit in q and v, and gravity (the
// joint springs, dampers and drives are the system's force elements,
// joint_elements.h). Every evaluation writes into a separate
// workspace (ArticulatedData, articulated_data.h), created once; the model
// never changes after construction (the split of a model and its data, as in
// MuJoCo's mjModel/mjData and Pinocchio's Model/Data).

#include <Eigen/Core>
#include <vector>

#include "stiffsim/model/joints.h"
#include "stiffsim/model/rigid_tree.h"
#include "stiffsim/model/spatial.h"

namespace stiffsim {

struct ArticulatedModel {
  RigidTree tree;
  std::vector<SpatialInertia> inertia;                      // per body, in its own frame
  std::vector<Eigen::Matrix<double, 6, 6>> inertia_matrix;  // the same as 6x6 matrices
  std::vector<int> q_offset, v_offset;                      // of each body's joint coordinates
  int nq = 0, nv = 0;
  // Gravity as an upward acceleration of the world (angular part first).
  Vec6<double> world_acceleration = Vec6<double>::Zero();
  bool has_floating = false;
  // Revolute joints: the body's rotation in its parent is
  // P (I + sin(q) K + (1 - cos(q)) K^2) for placement rotation P and the
  // axis' cross-product matrix K; P K and P K^2 are kept so that a pose
  // costs two scaled 3x3 sums (zero for other joints).
  std::vector<Eigen::Matrix3d> placement_K, placement_K2;

  int bodies() const { return static_cast<int>(tree.bodies.size()); }
};

// The spatial inertia of every body of `tree` in its own frame.
std::vector<SpatialInertia> body_inertias(const RigidTree& tree);

// joint_motion() of body i, a revolute joint's pose from placement_K and
// placement_K2 (two scaled 3x3 sums instead of the Rodrigues products,
// about a third of an inverse-dynamics pass): what every recursion on the
// model (inverse dynamics, the composite and articulated-body algorithms)
// calls. `q` holds the body's own joint positions.
template <typename T, typename Positions>
JointMotion<T> body_joint_motion(const ArticulatedModel& model, int i, const Positions& q) {
  const TreeBody& b = model.tree.bodies[i];
  if (b.type != JointType::kRevolute) return joint_motion<T>(b, q);
  using std::cos;
  using std::sin;
  const T angle = T(q[0]);
  const T s = sin(angle), c1 = T(1.0) - cos(angle);
  JointMotion<T> out;
  out.pose.R = b.placement.linear().cast<T>() + s * model.placement_K[i].cast<T>() +
               c1 * model.placement_K2[i].cast<T>();
  out.pose.p = b.placement.translation().cast<T>();
  out.S.setZero(6, 1);
  out.S.col(0).template head<3>() = b.axis.cast<T>();
  return out;
}

}  // namespace stiffsim
