#pragma once
// Spatial vector algebra (Featherstone 2008) in the body's own frame, with
// the angular part first: a motion (w, v) is an angular velocity and the
// velocity of the frame's origin point, a force (n, f) a moment about the
// origin and a force. A frame's pose in its parent is (R, p): x_parent =
// R x_child + p. Templated on the scalar for automatic differentiation.

#include <Eigen/Core>

namespace stiffsim {

template <typename T>
using Vec3 = Eigen::Matrix<T, 3, 1>;
template <typename T>
using Mat3 = Eigen::Matrix<T, 3, 3>;
template <typename T>
using Vec6 = Eigen::Matrix<T, 6, 1>;

template <typename T>
struct Pose {
  Mat3<T> R = Mat3<T>::Identity();
  Vec3<T> p = Vec3<T>::Zero();
};

// The pose of c in a, given b in a and c in b.
template <typename T>
Pose<T> compose(const Pose<T>& ab, const Pose<T>& bc) {
  return {ab.R * bc.R, ab.R * bc.p + ab.p};
}

// A parent motion in the coordinates of a child at `pose`:
// w_c = R^T w_p, v_c = R^T (v_p + w_p x p).
template <typename T>
Vec6<T> motion_to_child(const Pose<T>& pose, const Vec6<T>& m) {
  Vec6<T> out;
  const Vec3<T> w = m.template head<3>();
  out.template head<3>() = pose.R.transpose() * w;
  out.template tail<3>() = pose.R.transpose() * (m.template tail<3>() + w.cross(pose.p));
  return out;
}

// A child force in the coordinates of its parent: f_p = R f_c,
// n_p = R n_c + p x f_p (the dual of motion_to_child).
template <typename T>
Vec6<T> force_to_parent(const Pose<T>& pose, const Vec6<T>& f) {
  Vec6<T> out;
  out.template tail<3>() = pose.R * f.template tail<3>();
  out.template head<3>() = pose.R * f.template head<3>() + pose.p.cross(Vec3<T>(out.template tail<3>()));
  return out;
}

// a x m for motions a and m.
template <typename T>
Vec6<T> cross_motion(const Vec6<T>& a, const Vec6<T>& m) {
  const Vec3<T> w = a.template head<3>(), v = a.template tail<3>();
  const Vec3<T> mw = m.template head<3>(), mv = m.template tail<3>();
  Vec6<T> out;
  out.template head<3>() = w.cross(mw);
  out.template tail<3>() = w.cross(mv) + v.cross(mw);
  return out;
}

// a x* f for a motion a and a force f.
template <typename T>
Vec6<T> cross_force(const Vec6<T>& a, const Vec6<T>& f) {
  const Vec3<T> w = a.template head<3>(), v = a.template tail<3>();
  const Vec3<T> n = f.template head<3>(), fl = f.template tail<3>();
  Vec6<T> out;
  out.template head<3>() = w.cross(n) + v.cross(fl);
  out.template tail<3>() = w.cross(fl);
  return out;
}

// Mass properties about a frame's origin: mass m, centre of mass c and
// rotational inertia about the centre of mass Ic, all in that frame.
struct SpatialInertia {
  double mass = 0.0;
  Eigen::Vector3d com = Eigen::Vector3d::Zero();
  Eigen::Matrix3d inertia_com = Eigen::Matrix3d::Zero();

  // The momentum I m of a motion m: h = m (v + w x c),
  // L = Ic w + c x h.
  template <typename T>
  Vec6<T> apply(const Vec6<T>& motion) const {
    const Vec3<T> w = motion.template head<3>(), v = motion.template tail<3>();
    const Vec3<T> c = com.cast<T>();
    const Vec3<T> h = T(mass) * (v + w.cross(c));
    Vec6<T> out;
    out.template head<3>() = inertia_com.cast<T>() * w + c.cross(h);
    out.template tail<3>() = h;
    return out;
  }

  // The 6x6 matrix of apply().
  Eigen::Matrix<double, 6, 6> matrix() const;
};

// The 6x6 matrix of motion_to_child for a double pose.
Eigen::Matrix<double, 6, 6> motion_transform_matrix(const Pose<double>& pose);

inline Eigen::Matrix3d skew(const Eigen::Vector3d& a) {
  Eigen::Matrix3d S;
  S << 0.0, -a.z(), a.y(), a.z(), 0.0, -a.x(), -a.y(), a.x(), 0.0;
  return S;
}

}  // namespace stiffsim
