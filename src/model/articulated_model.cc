#include "stiffsim/model/articulated_model.h"

namespace stiffsim {

std::vector<SpatialInertia> body_inertias(const RigidTree& tree) {
  std::vector<SpatialInertia> out;
  out.reserve(tree.bodies.size());
  for (const TreeBody& b : tree.bodies) {
    SpatialInertia I;
    I.mass = b.inertia.mass;
    I.com = b.inertia.com;
    I.inertia_com = b.inertia.inertia;
    out.push_back(I);
  }
  return out;
}

}  // namespace stiffsim
