#pragma once
// Where a material point of a component is, how fast it moves, and how both
// depend on the component's coordinates: what a force acting between two
// components (an attachment, attachment.h) needs from each of them.
//
// The point moves with the velocity dofs listed in `dofs`, in order from the
// root of its kinematic chain to the point (a particle node: its x, y, z;
// a link of a tree: the joints from the root down to the link). For each,
// J[j] = dp_dot/dv_j, and axis[j] is the world axis the dof turns about
// (zero for a translation), so that a dof upstream of another turns the
// other's column.
//
// Most dofs have a position coordinate q_index[j] with q_dot = v_j; then
// dp/dq = J[j] and
//   dJ[i]/dq_m = axis[m] x J[i]  (m upstream of i or m == i),
//   dJ[i]/dq_m = axis[i] x J[m]  (m downstream of i).
// A floating joint's angular velocity (in its body frame) has none
// (q_index -1): its orientation is a quaternion, whose four coordinates are
// listed in `quaternion`. For each, dp/dq = dp, and with G = dR/dq R^T (R
// the joint's world rotation, so G maps any world vector fixed in the body
// to its derivative)
//   dJ[i]/dq = G J[i]            (i at or after `first`, the joint's first
//                                 angular dof: columns that turn with it),
//   dJ[i]/dq = axis[i] x dp      (i before `first`).

#include <Eigen/Core>
#include <vector>

namespace stiffsim {

struct QuaternionCoordinate {
  int q_index = 0;  // local position index
  Eigen::Vector3d dp = Eigen::Vector3d::Zero();
  Eigen::Matrix3d G = Eigen::Matrix3d::Zero();
  int first = 0;  // index into dofs of the joint's first angular dof
};

struct PointKinematics {
  Eigen::Vector3d p = Eigen::Vector3d::Zero(), p_dot = Eigen::Vector3d::Zero();
  std::vector<int> dofs;     // local velocity indices, root first
  std::vector<int> q_index;  // per dof: its position coordinate, or -1
  std::vector<Eigen::Vector3d> J, axis;
  std::vector<QuaternionCoordinate> quaternion;
};

}  // namespace stiffsim
