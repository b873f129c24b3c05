#pragma once
// The workspace of the recursive algorithms on an ArticulatedModel: one per
// evaluating thread, sized once, so that an evaluation allocates nothing.
// Templated on the scalar: the automatic-differentiation path keeps its own
// (dual-number) workspace beside the double one.

#include <Eigen/Core>
#include <vector>

#include "stiffsim/model/articulated_model.h"
#include "stiffsim/model/joints.h"

namespace stiffsim {

template <typename T>
struct ArticulatedData {
  explicit ArticulatedData(const ArticulatedModel& model)
      : pose(model.bodies()),
        S(model.bodies()),
        V(model.bodies()),
        A(model.bodies()),
        f(model.bodies()),
        F(model.nv),
        world_acceleration(model.world_acceleration) {}

  // Inverse dynamics: each body's pose in its parent, motion subspace,
  // spatial velocity, acceleration and net force in its own frame.
  std::vector<Pose<T>> pose;
  std::vector<MotionSubspace<T>> S;
  std::vector<Vec6<T>> V, A, f;
  Eigen::Matrix<T, Eigen::Dynamic, 1> F;  // the generalized forces (nv)
  // The world's upward acceleration at the evaluation's time: the model's
  // (gravity) unless a prescribed root motion adds its own (ArticulatedSystem
  // sets it before each evaluation).
  Vec6<double> world_acceleration;
};

}  // namespace stiffsim
