#pragma once
// Forward kinematics of a RigidTree in exact (reduced) coordinates: the
// world pose of every body and its spatial velocity, for drawings, momenta
// and the compliant formulation's initial state.

#include <Eigen/Core>
#include <vector>

#include "stiffsim/model/rigid_tree.h"
#include "stiffsim/model/spatial.h"

namespace stiffsim {

// World poses of every body of `tree` at q (exact coordinates) and, when v is
// given, every body's spatial velocity in its own coordinates.
void forward_kinematics(const RigidTree& tree, const Eigen::VectorXd& q, const Eigen::VectorXd* v,
                        std::vector<Pose<double>>* world, std::vector<Vec6<double>>* velocities);

}  // namespace stiffsim
