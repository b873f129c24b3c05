#include "stiffsim/model/spatial.h"

namespace stiffsim {

Eigen::Matrix<double, 6, 6> SpatialInertia::matrix() const {
  // [Ic + m [c]x [c]x^T, m [c]x; m [c]x^T, m I]
  const Eigen::Matrix3d C = skew(com);
  Eigen::Matrix<double, 6, 6> I;
  I.topLeftCorner<3, 3>() = inertia_com + mass * C * C.transpose();
  I.topRightCorner<3, 3>() = mass * C;
  I.bottomLeftCorner<3, 3>() = mass * C.transpose();
  I.bottomRightCorner<3, 3>() = mass * Eigen::Matrix3d::Identity();
  return I;
}

Eigen::Matrix<double, 6, 6> motion_transform_matrix(const Pose<double>& pose) {
  // [R^T, 0; -R^T [p]x, R^T]
  const Eigen::Matrix3d Rt = pose.R.transpose();
  Eigen::Matrix<double, 6, 6> X;
  X.topLeftCorner<3, 3>() = Rt;
  X.topRightCorner<3, 3>().setZero();
  X.bottomLeftCorner<3, 3>() = -Rt * skew(pose.p);
  X.bottomRightCorner<3, 3>() = Rt;
  return X;
}

}  // namespace stiffsim
