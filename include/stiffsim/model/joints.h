#pragma once
// Joint models (MODELS.md): the pose of a body in its parent as a function of
// its joint's positions, and the motion subspace S that maps the joint's
// velocities to the body's spatial velocity relative to the parent, in body
// coordinates. Templated on the scalar for automatic differentiation.
//
// Every joint here translates in the joint (parent-side) frame and rotates
// the body, so its velocity product term is c_J = (0, -w_J x u_J) for
// v_J = S v = (w_J, u_J): zero for revolute and prismatic joints.

#include <Eigen/Core>
#include <cmath>

#include "stiffsim/model/quaternion.h"
#include "stiffsim/model/rigid_tree.h"
#include "stiffsim/model/spatial.h"

namespace stiffsim {

// A joint spring tau = -stiffness (q - rest) and viscous damping
// tau = -damping q_dot on a 1-DOF joint (revolute, prismatic), beside the
// URDF's own <dynamics damping>.
struct JointForce {
  double stiffness = 0.0;
  double rest = 0.0;
  double damping = 0.0;
};

template <typename T>
using MotionSubspace = Eigen::Matrix<T, 6, Eigen::Dynamic, 0, 6, 6>;

template <typename T>
struct JointMotion {
  Pose<T> pose;       // the body in its parent (placement, then the joint's motion)
  MotionSubspace<T> S;  // 6 x nv, body coordinates
};

// In-plane unit directions (e1, e2) of a planar joint with normal n, with
// e1 x e2 = n (for n = z: x and y).
inline void planar_basis(const Eigen::Vector3d& n, Eigen::Vector3d* e1, Eigen::Vector3d* e2) {
  const Eigen::Vector3d ref = std::abs(n.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  *e1 = (ref - ref.dot(n) * n).normalized();
  *e2 = n.cross(*e1);
}

// Rotation by angle about the unit axis a (Rodrigues).
template <typename T>
Mat3<T> axis_rotation(const Eigen::Vector3d& a, const T& angle) {
  using std::cos;
  using std::sin;
  const Mat3<T> K = skew(a).cast<T>();
  return Mat3<T>::Identity() + sin(angle) * K + (T(1.0) - cos(angle)) * (K * K);
}

// `q` holds the joint's positions (joint_nq(body.type) of them).
template <typename T, typename Positions>
JointMotion<T> joint_motion(const TreeBody& body, const Positions& q) {
  Pose<T> joint;
  JointMotion<T> out;
  const int nv = joint_nv(body.type);
  out.S.setZero(6, nv);
  const Vec3<T> a = body.axis.cast<T>();
  switch (body.type) {
    case JointType::kRevolute:
      joint.R = axis_rotation<T>(body.axis, T(q[0]));
      out.S.col(0).template head<3>() = a;
      break;
    case JointType::kPrismatic:
      joint.p = T(q[0]) * a;
      out.S.col(0).template tail<3>() = a;
      break;
    case JointType::kFloating: {
      Eigen::Matrix<T, 4, 1> quat;
      quat << T(q[3]), T(q[4]), T(q[5]), T(q[6]);
      joint.p << T(q[0]), T(q[1]), T(q[2]);
      joint.R = quaternion_rotation<T>(quat);
      // v = (linear velocity of the body origin in the joint frame, angular
      // velocity in the body frame).
      out.S.template block<3, 3>(3, 0) = joint.R.transpose();
      out.S.template block<3, 3>(0, 3).setIdentity();
      break;
    }
    case JointType::kPlanar: {
      Eigen::Vector3d e1, e2;
      planar_basis(body.axis, &e1, &e2);
      joint.p = T(q[0]) * e1.cast<T>() + T(q[1]) * e2.cast<T>();
      joint.R = axis_rotation<T>(body.axis, T(q[2]));
      out.S.col(0).template tail<3>() = joint.R.transpose() * e1.cast<T>();
      out.S.col(1).template tail<3>() = joint.R.transpose() * e2.cast<T>();
      out.S.col(2).template head<3>() = a;
      break;
    }
  }
  Pose<T> placement;
  placement.R = body.placement.linear().cast<T>();
  placement.p = body.placement.translation().cast<T>();
  out.pose = compose(placement, joint);
  return out;
}

// c_J for a joint velocity v_J = S v (see the header comment).
template <typename T>
Vec6<T> joint_velocity_product(const Vec6<T>& vJ) {
  Vec6<T> c;
  c.template head<3>().setZero();
  c.template tail<3>() = -Vec3<T>(vJ.template head<3>()).cross(Vec3<T>(vJ.template tail<3>()));
  return c;
}

}  // namespace stiffsim
