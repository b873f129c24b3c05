#pragma once
// The composite rigid body algorithm (Featherstone 2008, table 6.2): the
// joint-space mass matrix M(q) of an ArticulatedModel, written into the
// value slots of a fixed sparse pattern. It visits only pairs of bodies on
// one branch (one lies on the other's path to the root), so M's pattern is
// the tree's branch sparsity and a long serial chain is the only dense case.

#include <Eigen/Core>
#include <vector>

#include "stiffsim/linalg/sparse_pattern.h"
#include "stiffsim/model/articulated_model.h"
#include "stiffsim/model/joints.h"

namespace stiffsim {

// The algorithm's workspace, sized once per model: the subtree inertias,
// each body's transform from its parent and its motion subspace.
struct CompositeRigidBodyData {
  explicit CompositeRigidBodyData(const ArticulatedModel& model);
  std::vector<Eigen::Matrix<double, 6, 6>> composite, transform;
  std::vector<MotionSubspace<double>> S;
};

// The value slots of `pattern` (which must hold every related pair's block,
// both triangles) in the order composite_rigid_body() writes them.
std::vector<int> composite_rigid_body_slots(const ArticulatedModel& model,
                                            const SparseMatrix& pattern);

// M(q) into the values of *M (the pattern `slots` were made for); q holds
// model.nq values. Allocates nothing.
void composite_rigid_body(const ArticulatedModel& model, const Eigen::Ref<const Eigen::VectorXd>& q,
                          const std::vector<int>& slots, CompositeRigidBodyData* data,
                          SparseMatrix* M);

}  // namespace stiffsim
