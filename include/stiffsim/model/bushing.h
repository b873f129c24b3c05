#pragma once
// A bushing: the stiff spring-damper that replaces a URDF joint in the
// compliant formulation (compliant.h), between two free bodies or a free body
// and the world. Its parameters, its generalized forces on the two bodies'
// (q, v) slices and its potential; templated on the scalar, so the same code
// gives F and, with dual numbers, the derivatives that check the analytic
// ones (bushing_element.h).

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>
#include <string>
#include <vector>

#include "stiffsim/model/joints.h"
#include "stiffsim/model/quaternion.h"
#include "stiffsim/model/rigid_tree.h"
#include "stiffsim/model/spatial.h"

namespace stiffsim {

// A stiff spring-damper that replaces a URDF joint in the compliant
// formulation. It pulls the frame of body `child` onto the joint frame
// (`placement` on body `parent`, -1 the world) in every direction the joint
// forbids and leaves the joint's own motion free:
//   linear:  E = k_lin/2 d^T P d, d the child origin relative to the joint
//            origin, P = I (revolute), I - n n^T (prismatic), n n^T (planar);
//   angular: E = k_ang (1 - n_joint . n_child) (revolute, planar: the axis
//            may not tilt), E = k_ang/2 (3 - tr(R_child R_joint^T))
//            (prismatic: no relative rotation);
// damping c_lin P and c_ang on the relative velocities at the joint, so it
// only dissipates. `joint` adds the joint spring and damping on the free
// coordinate of a 1-DOF joint: the angle atan2 between the joint frame's and
// the child's reference directions (in (-pi, pi]) or the offset n . d.
struct Bushing {
  std::string name;  // the URDF joint
  int parent = -1;
  int child = 0;
  JointType type = JointType::kRevolute;
  Eigen::Isometry3d placement = Eigen::Isometry3d::Identity();
  Eigen::Vector3d axis = Eigen::Vector3d::UnitX();
  double k_lin = 0.0, c_lin = 0.0, k_ang = 0.0, c_ang = 0.0;
  JointForce joint;  // damping: the URDF's plus the scene's
};

// A bushing's linear projector P = alpha I + beta n n^T and its angular
// constraint: only the axis may not tilt (revolute, planar) or no relative
// rotation at all (prismatic).
struct BushingProjector {
  double alpha = 1.0, beta = 0.0;
  bool tilt_only = true;
};
BushingProjector bushing_projector(JointType type);

// A unit direction perpendicular to the unit axis n, for joint angles.
Eigen::Vector3d reference_direction(const Eigen::Vector3d& n);

// World pose and world velocities (of the origin, and angular) of a free root
// body from its q and v slices.
template <typename T>
struct FreeBodyState {
  Pose<T> pose;
  Vec3<T> velocity, omega;  // world frame
};

template <typename T, typename Q, typename V>
FreeBodyState<T> free_body_state(const Q& q, const V& v, int qo, int vo) {
  FreeBodyState<T> s;
  Eigen::Matrix<T, 4, 1> quat = q.template segment<4>(qo + 3).template cast<T>();
  s.pose.R = quaternion_rotation<T>(quat);
  s.pose.p = q.template segment<3>(qo).template cast<T>();
  s.velocity = v.template segment<3>(vo).template cast<T>();
  s.omega = s.pose.R * Vec3<T>(v.template segment<3>(vo + 3).template cast<T>());
  return s;
}

// Adds a world force f at world point x and a world moment m on a free root
// body to its generalized forces (linear velocity in the world, angular in
// the body frame).
template <typename T>
void apply_wrench(const FreeBodyState<T>& s, const Vec3<T>& x, const Vec3<T>& f, const Vec3<T>& m,
                  int vo, Eigen::Matrix<T, Eigen::Dynamic, 1>* F) {
  F->template segment<3>(vo) += f;
  const Vec3<T> arm = x - s.pose.p;
  F->template segment<3>(vo + 3) += s.pose.R.transpose() * (arm.cross(f) + m);
}

// The relative state of a bushing's two frames.
template <typename T>
struct BushingFrames {
  FreeBodyState<T> a, b;  // a: the parent (the world at rest when parent < 0)
  Mat3<T> RJ;             // joint frame orientation in the world
  Vec3<T> xJ;             // joint frame origin in the world
  Vec3<T> n;              // joint axis in the world (fixed to the parent)
};

// Where a bushing's two bodies' coordinates sit in q and v (the parent's -1
// for the world).
struct BushingOffsets {
  int parent_q = -1, parent_v = -1, child_q = 0, child_v = 0;
};
// The offsets of `bu`'s bodies, from each body's q and v offsets.
BushingOffsets bushing_offsets(const Bushing& bu, const std::vector<int>& q_offset,
                               const std::vector<int>& v_offset);

template <typename T, typename Q, typename V>
BushingFrames<T> bushing_frames(const Bushing& bu, const Q& q, const V& v,
                                const BushingOffsets& at) {
  BushingFrames<T> fr;
  if (bu.parent >= 0) {
    fr.a = free_body_state<T>(q, v, at.parent_q, at.parent_v);
  } else {
    fr.a.velocity.setZero();
    fr.a.omega.setZero();
  }
  fr.b = free_body_state<T>(q, v, at.child_q, at.child_v);
  fr.RJ = fr.a.pose.R * bu.placement.linear().cast<T>();
  fr.xJ = fr.a.pose.p + fr.a.pose.R * bu.placement.translation().cast<T>();
  fr.n = fr.RJ * bu.axis.cast<T>();
  return fr;
}

template <typename T>
T bushing_angle(const Bushing& bu, const BushingFrames<T>& fr, Vec3<T>* gradient_child) {
  using std::atan2;
  const Eigen::Vector3d e = reference_direction(bu.axis);
  const Vec3<T> ea = fr.RJ * e.cast<T>();
  const Vec3<T> eb = fr.b.pose.R * e.cast<T>();
  const T x = ea.dot(eb);
  const T y = fr.n.dot(ea.cross(eb));
  if (gradient_child) {
    // d theta / d phi_child for a small world rotation phi of the child; the
    // parent's is its negative (theta is invariant under a common rotation).
    const Vec3<T> dx = eb.cross(ea);
    const Vec3<T> dy = eb.cross(Vec3<T>(fr.n.cross(ea)));
    *gradient_child = (x * dy - y * dx) / (x * x + y * y);
  }
  return atan2(y, x);
}

// Adds bushing `bu`'s generalized forces to F.
template <typename T, typename Q, typename V>
void add_bushing_forces(const Bushing& bu, const Q& q, const V& v, const BushingOffsets& at,
                        Eigen::Matrix<T, Eigen::Dynamic, 1>* F) {
  const BushingFrames<T> fr = bushing_frames<T>(bu, q, v, at);
  const BushingProjector g = bushing_projector(bu.type);
  const Vec3<T>& n = fr.n;
  const Vec3<T> d = fr.b.pose.p - fr.xJ;
  const T nd = n.dot(d);
  // Relative velocities at the joint: of the child origin against the parent
  // point under it, and angular.
  const Vec3<T> dv =
      fr.b.velocity - (fr.a.velocity + fr.a.omega.cross(Vec3<T>(fr.b.pose.p - fr.a.pose.p)));
  const Vec3<T> dw = fr.b.omega - fr.a.omega;

  // Linear: the child's force at its origin (the parent takes the opposite
  // at the same point, which lies on both bodies' lines of action, plus the
  // moment from the axis it carries).
  Vec3<T> f = -T(bu.k_lin) * (T(g.alpha) * d + T(g.beta) * nd * n) -
              T(bu.c_lin) * (T(g.alpha) * dv + T(g.beta) * n.dot(dv) * n);
  Vec3<T> m_parent = -T(bu.k_lin * g.beta) * nd * n.cross(d);
  Vec3<T> m_child = Vec3<T>::Zero();

  // Angular.
  if (g.tilt_only) {
    const Vec3<T> nb = fr.b.pose.R * bu.axis.cast<T>();
    m_child += T(bu.k_ang) * nb.cross(n);
    m_parent += T(bu.k_ang) * n.cross(nb);
    const Vec3<T> dw_perp = dw - n.dot(dw) * n;
    m_child -= T(bu.c_ang) * dw_perp;
    m_parent += T(bu.c_ang) * dw_perp;
  } else {
    const Mat3<T> S = fr.b.pose.R * fr.RJ.transpose();
    Vec3<T> axial;
    axial << S(2, 1) - S(1, 2), S(0, 2) - S(2, 0), S(1, 0) - S(0, 1);
    m_child -= T(0.5 * bu.k_ang) * axial;
    m_parent += T(0.5 * bu.k_ang) * axial;
    m_child -= T(bu.c_ang) * dw;
    m_parent += T(bu.c_ang) * dw;
  }

  // The free coordinate's spring and damper.
  const JointForce& jf = bu.joint;
  if (bu.type == JointType::kRevolute && (jf.stiffness != 0.0 || jf.damping != 0.0)) {
    Vec3<T> grad;
    const T theta = bushing_angle<T>(bu, fr, &grad);
    const T torque = -T(jf.stiffness) * (theta - T(jf.rest));
    m_child += torque * grad;
    m_parent -= torque * grad;
    const Vec3<T> damp = -T(jf.damping) * n.dot(dw) * n;
    m_child += damp;
    m_parent -= damp;
  } else if (bu.type == JointType::kPrismatic && (jf.stiffness != 0.0 || jf.damping != 0.0)) {
    const T s_force = -T(jf.stiffness) * (nd - T(jf.rest));
    f += s_force * n - T(jf.damping) * n.dot(dv) * n;
    // E = k/2 (n.d - rest)^2 also turns with the parent's axis.
    m_parent += s_force * n.cross(d);
  }

  apply_wrench<T>(fr.b, fr.b.pose.p, f, m_child, at.child_v, F);
  if (bu.parent >= 0) {
    apply_wrench<T>(fr.a, fr.b.pose.p, Vec3<T>(-f), m_parent, at.parent_v, F);
  }
}

// The potential of bushing `bu`.
double bushing_energy(const Bushing& bu, const Eigen::Ref<const Eigen::VectorXd>& q,
                      const BushingOffsets& at);

}  // namespace stiffsim
