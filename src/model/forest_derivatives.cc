#include "stiffsim/model/forest_derivatives.h"

#include <stdexcept>

#include "stiffsim/model/joints.h"

namespace stiffsim {
namespace {

// The pattern of the forest without bushings: each body with the bodies on
// its root path (rows of one, columns of the other, both ways).
SparseMatrix forest_pattern(const RigidTree& tree, const std::vector<int>& q_offset,
                            const std::vector<int>& v_offset, int nv, int nq, bool positions) {
  PatternBuilder B(nv, positions ? nq : nv);
  const int nb = static_cast<int>(tree.bodies.size());
  for (int i = 0; i < nb; ++i) {
    for (int j = i; j >= 0; j = tree.bodies[j].parent) {
      for (auto [r, c] : {std::pair{i, j}, std::pair{j, i}}) {
        const JointType rt = tree.bodies[r].type, ct = tree.bodies[c].type;
        B.add_block(v_offset[r], positions ? q_offset[c] : v_offset[c], joint_nv(rt),
                    positions ? joint_nq(ct) : joint_nv(ct));
      }
    }
  }
  return B.build();
}

}  // namespace

ForestDerivatives::ForestDerivatives(const ArticulatedSystem& system)
    : forest_K_(forest_pattern(system.tree(), system.model().q_offset, system.model().v_offset,
                               system.dimensions().nv, system.dimensions().nq, true)),
      forest_D_(forest_pattern(system.tree(), system.model().q_offset, system.model().v_offset,
                               system.dimensions().nv, system.dimensions().nq, false)),
      forest_(system.tree(), system.model().inertia, system.options().gravity, forest_K_,
              forest_D_) {
  if (system.options().bushings.empty()) {
    throw std::invalid_argument("ForestDerivatives: '" + system.name() +
                                "' has no bushings (an exact tree: make_rnea_derivatives)");
  }
  const ForceJacobians& pattern = system.jacobian_pattern();
  forest_k_slots_ = slots_in(pattern.dF_dq, forest_K_);
  forest_d_slots_ = slots_in(pattern.dF_dv, forest_D_);
}

void ForestDerivatives::compute(const ConstVectorRef& q, const ConstVectorRef& v,
                                const double* acceleration, SparseMatrix* K, SparseMatrix* D) {
  forest_.compute(q, v, acceleration, &forest_K_, &forest_D_);
  set_zero_keep_pattern(K);
  set_zero_keep_pattern(D);
  scatter_add(forest_K_, forest_k_slots_, 1.0, K);
  scatter_add(forest_D_, forest_d_slots_, 1.0, D);
}

}  // namespace stiffsim
