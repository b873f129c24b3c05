#pragma once
// Where a material point of a component is, how fast it moves, and how both
// depend on the component's coordinates: what a force acting between two
// components (an attachment, attachment.h) needs from each of them.
//
// The point moves with the velocity dofs listed in `dofs`, in order from the
// root of its kinematic chain to the point (a particle node: its x, y, z;
// a link of a tree: the joints from the root down to the link). For each,
// J[j] = dp/dq_j = dp_dot/dv_j (these components have q_dot = v), and
// axis[j] is the world axis the dof turns about (zero for a translation), so
// that a dof upstream of another turns the other's column:
//   dJ[i]/dq_m = axis[m] x J[i]  (m upstream of i or m == i),
//   dJ[i]/dq_m = axis[i] x J[m]  (m downstream of i).

#include <Eigen/Core>
#include <vector>

namespace stiffsim {

struct PointKinematics {
  Eigen::Vector3d p = Eigen::Vector3d::Zero(), p_dot = Eigen::Vector3d::Zero();
  std::vector<int> dofs;  // local velocity (= position) indices, root first
  std::vector<Eigen::Vector3d> J, axis;
};

}  // namespace stiffsim
