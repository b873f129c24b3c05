#pragma once
// Analytic derivatives of the free bodies' own forces in the compliant
// formulation (articulated.h, compliant.h): gravity, gyroscopic forces and
// -M(q) a when an acceleration is given, by the recursive Newton-Euler
// derivatives (rnea_derivatives.h) of the bushing-free forest, written into
// the system's full Jacobian patterns (which also hold the bushings'
// blocks, which the bushing elements add: bushing_element.h). O(bodies),
// one pass, no allocation.

#include <Eigen/Core>
#include <vector>

#include "stiffsim/linalg/sparse_pattern.h"
#include "stiffsim/model/articulated.h"
#include "stiffsim/model/rnea_derivatives.h"
#include "stiffsim/system.h"

namespace stiffsim {

class ForestDerivatives {
 public:
  // `system` must have bushings; its jacobian_pattern() is the one compute()
  // fills. Throws std::invalid_argument otherwise.
  explicit ForestDerivatives(const ArticulatedSystem& system);

  // K = dF/dq and D = dF/dv of the free bodies' own forces at (q, v) (with
  // `acceleration`, nv values or null: of F - M(q) a at that fixed a). K
  // and D must have the system's Jacobian patterns; all their values are
  // overwritten (zero outside the forest's entries). Allocates nothing.
  void compute(const ConstVectorRef& q, const ConstVectorRef& v, const double* acceleration,
               SparseMatrix* K, SparseMatrix* D);

 private:
  // The forest's own pattern (the tree's branch pattern), its derivatives,
  // and where its entries sit in the full one. (Declared before forest_,
  // which is built on them.)
  SparseMatrix forest_K_, forest_D_;
  RneaDerivatives forest_;
  std::vector<int> forest_k_slots_, forest_d_slots_;
};

}  // namespace stiffsim
