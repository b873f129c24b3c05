#pragma once
// The compliant formulation of a RigidTree (MODELS.md): every body becomes a
// free body (a floating joint to the world: q = position and orientation
// quaternion of its link frame, v = its origin's world velocity and its
// body-frame angular velocity) and every joint a Bushing (articulated.h) with
// the joint's spring and damping on the free coordinate. M is block diagonal
// (6 x 6 per body) and K, D are block tridiagonal for a chain, so the cost of
// a step grows linearly with the number of links; the motion converges to the
// exact formulation's as the bushing stiffness grows.

#include <memory>

#include "stiffsim/model/articulated.h"

namespace stiffsim {

struct BushingParameters {
  double k_lin = 1e6;  // N/m
  double c_lin = 10.0;  // N s/m
  double k_ang = 1e4;  // N m/rad
  double c_ang = 0.1;  // N m s/rad
};

// `exact` gives the gravity, the joint springs and dampers per body of
// `tree` and the initial state in the exact formulation's coordinates: the
// free bodies start where the exact tree's bodies are, with their
// velocities. Floating joints of the tree stay free (no bushing). Throws
// InputError for bad parameters (negative or non-finite) and for drives or
// a root motion, which act on the exact formulation only.
std::unique_ptr<ArticulatedSystem> make_compliant(const RigidTree& tree, const ArticulatedOptions& exact,
                                                  const BushingParameters& bushing);

}  // namespace stiffsim
