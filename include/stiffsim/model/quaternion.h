#pragma once
// Unit quaternions q = (w, x, y, z) for orientations (MODELS.md): the
// rotation they stand for and the kinematic map q_dot = 1/2 q (x) (0, w) for
// a body-frame angular velocity w. Templated on the scalar so that automatic
// differentiation passes through them.

#include <Eigen/Core>
#include <cmath>

namespace stiffsim {

// Rotation matrix of q / |q|: normalising here keeps forces defined (and
// their derivatives along |q| zero) for the non-unit iterates of Newton and
// of finite differences; the integrators project q after every step.
template <typename T, typename Q>
Eigen::Matrix<T, 3, 3> quaternion_rotation(const Q& q) {
  using std::sqrt;
  const T n2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3];
  const T s = T(2.0) / n2;
  const T w = q[0], x = q[1], y = q[2], z = q[3];
  Eigen::Matrix<T, 3, 3> R;
  R(0, 0) = T(1.0) - s * (y * y + z * z);
  R(0, 1) = s * (x * y - w * z);
  R(0, 2) = s * (x * z + w * y);
  R(1, 0) = s * (x * y + w * z);
  R(1, 1) = T(1.0) - s * (x * x + z * z);
  R(1, 2) = s * (y * z - w * x);
  R(2, 0) = s * (x * z - w * y);
  R(2, 1) = s * (y * z + w * x);
  R(2, 2) = T(1.0) - s * (x * x + y * y);
  return R;
}

// The 4x3 block of N(q): q_dot = quaternion_rate_map(q) * w, w in the body
// frame. Its columns are orthogonal to q, so q_dot keeps |q| to first order.
inline Eigen::Matrix<double, 4, 3> quaternion_rate_map(const Eigen::Vector4d& q) {
  const double w = q[0], x = q[1], y = q[2], z = q[3];
  Eigen::Matrix<double, 4, 3> N;
  N << -x, -y, -z,
        w, -z,  y,
        z,  w, -x,
       -y,  x,  w;
  return 0.5 * N;
}

// Unit quaternion of a rotation matrix (w >= 0).
Eigen::Vector4d quaternion_from_rotation(const Eigen::Matrix3d& R);

}  // namespace stiffsim
