#pragma once
// A force element between components of a scene: a zero-rest-length
// spring-damper joining a point of one component to a point of another (or
// of the same one, or a fixed point of the world),
//   f = k (p_b - p_a) + c (p_dot_b - p_dot_a)  on point a, -f on point b.
// A particle node hung on a link this way is held without a constraint: the
// stiffness k enters the Newton matrix with the coupling blocks, so the step
// stays implicit in it, and the node sits within |f| / k of the link point.

#include <Eigen/Core>
#include <string>

namespace stiffsim {

struct AttachmentPoint {
  int component = -1;  // index in the scene; -1: a fixed point of the world
  int element = 0;     // a particle node, or a body of a tree
  // In the body's frame (a link); ignored for a particle node; the world
  // point itself for component -1.
  Eigen::Vector3d local = Eigen::Vector3d::Zero();
};

struct Attachment {
  std::string name;  // for messages
  AttachmentPoint a, b;
  double k = 0.0, c = 0.0;
};

}  // namespace stiffsim
