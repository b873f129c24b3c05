#include "stiffsim/model/bushing.h"

namespace stiffsim {

BushingProjector bushing_projector(JointType type) {
  switch (type) {
    case JointType::kRevolute:
      return {1.0, 0.0, true};
    case JointType::kPrismatic:
      return {1.0, -1.0, false};
    case JointType::kPlanar:
      return {0.0, 1.0, true};
    case JointType::kFloating:
      break;
  }
  return {0.0, 0.0, true};
}

Eigen::Vector3d reference_direction(const Eigen::Vector3d& n) {
  Eigen::Vector3d e1, e2;
  planar_basis(n, &e1, &e2);
  return e1;
}

double bushing_energy(const Bushing& bu, const Eigen::VectorXd& q, const Eigen::VectorXd& rest,
                      const std::vector<int>& qo, const std::vector<int>& vo) {
  const BushingFrames<double> fr = bushing_frames<double>(bu, q, rest, qo, vo);
  const BushingProjector g = bushing_projector(bu.type);
  const Eigen::Vector3d d = fr.b.pose.p - fr.xJ;
  const double nd = fr.n.dot(d);
  double e = 0.5 * bu.k_lin * (g.alpha * d.squaredNorm() + g.beta * nd * nd);
  if (g.tilt_only) {
    e += bu.k_ang * (1.0 - fr.n.dot(fr.b.pose.R * bu.axis));
  } else {
    e += 0.5 * bu.k_ang * (3.0 - (fr.b.pose.R * fr.RJ.transpose()).trace());
  }
  if (bu.type == JointType::kRevolute) {
    const double theta = bushing_angle<double>(bu, fr, nullptr);
    e += 0.5 * bu.joint.stiffness * (theta - bu.joint.rest) * (theta - bu.joint.rest);
  } else if (bu.type == JointType::kPrismatic) {
    e += 0.5 * bu.joint.stiffness * (nd - bu.joint.rest) * (nd - bu.joint.rest);
  }
  return e;
}

}  // namespace stiffsim
