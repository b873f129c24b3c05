#include "stiffsim/model/quaternion.h"

#include <Eigen/Geometry>

namespace stiffsim {

Eigen::Vector4d quaternion_from_rotation(const Eigen::Matrix3d& R) {
  Eigen::Quaterniond q(R);
  q.normalize();
  Eigen::Vector4d out(q.w(), q.x(), q.y(), q.z());
  return out[0] < 0.0 ? Eigen::Vector4d(-out) : out;
}

}  // namespace stiffsim
