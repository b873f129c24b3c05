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

BushingOffsets bushing_offsets(const Bushing& bu, const std::vector<int>& q_offset,
                               const std::vector<int>& v_offset) {
  BushingOffsets at;
  if (bu.parent >= 0) {
    at.parent_q = q_offset[bu.parent];
    at.parent_v = v_offset[bu.parent];
  }
  at.child_q = q_offset[bu.child];
  at.child_v = v_offset[bu.child];
  return at;
}

double bushing_energy(const Bushing& bu, const Eigen::Ref<const Eigen::VectorXd>& q,
                      const BushingOffsets& at) {
  // Velocities do not enter the potential: the frames read a zero 12-vector.
  const Eigen::Matrix<double, 12, 1> rest = Eigen::Matrix<double, 12, 1>::Zero();
  BushingOffsets positions = at;
  positions.parent_v = bu.parent >= 0 ? 0 : -1;
  positions.child_v = 6;
  const BushingFrames<double> fr = bushing_frames<double>(bu, q, rest, positions);
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
