#pragma once
// Analytic derivatives of the compliant formulation's forces (articulated.h,
// compliant.h): K = dF/dq and D = dF/dv of every Bushing's spring-damper
// forces and of the free bodies' own inverse-dynamics terms (gravity,
// gyroscopic forces, and -M(q) a when an acceleration is given).
//
// Each bushing's force f on the child (the parent takes -f at the same point)
// and its moments about the two body origins are differentiated with respect
// to small world-frame displacements and rotations of both bodies and to their
// world velocities; the chain rule then gives the raw coordinates:
// - position columns directly;
// - a quaternion's four columns through the world rotation it causes,
//   R 4 / |q|^2 N(q)^T dq (N the quaternion block of the velocity map; zero
//   along q, as differentiating q / |q| gives), with the body's world angular
//   velocity R w_body turning along;
// - generalized angular rows are R^T (moment), so a body's own rotation also
//   turns its rows.
// The free bodies' own terms are the recursive Newton-Euler derivatives
// (rnea_derivatives.h) of the bushing-free forest. O(bodies + bushings), one
// pass, no allocation.

#include <Eigen/Core>
#include <vector>

#include "stiffsim/linalg/sparse_pattern.h"
#include "stiffsim/model/articulated.h"
#include "stiffsim/model/bushing.h"
#include "stiffsim/model/rnea_derivatives.h"
#include "stiffsim/system.h"

namespace stiffsim {

class BushingDerivatives {
 public:
  // `system` must have bushings; its jacobian_pattern() is the one compute()
  // fills. Throws std::invalid_argument otherwise.
  explicit BushingDerivatives(const ArticulatedSystem& system);

  // K = dF/dq and D = dF/dv at (q, v) (with `acceleration`, nv values or
  // null: of F - M(q) a at that fixed a). K and D must have the system's
  // Jacobian patterns; all their values are overwritten. Allocates nothing.
  void compute(const ConstVectorRef& q, const ConstVectorRef& v, const double* acceleration,
               SparseMatrix* K, SparseMatrix* D);

 private:
  // Per bushing, the value slot of the first row of each column of the 6 x 7
  // (K) and 6 x 6 (D) blocks [row body][column body], parent 0 and child 1:
  // a block's rows are contiguous in each compressed column.
  struct BlockSlots {
    int k[2][2][7];
    int d[2][2][6];
  };

  void add_bushing(const Bushing& bu, const BlockSlots& slots, const ConstVectorRef& q,
                   const ConstVectorRef& v, SparseMatrix* K, SparseMatrix* D) const;

  std::vector<Bushing> bushings_;
  std::vector<BlockSlots> slots_;
  std::vector<int> q_offset_, v_offset_;
  // The forest without its bushings: its own derivatives, their pattern
  // (the tree's branch pattern) and where its entries sit in the full one.
  // (Declared before forest_, which is built on them.)
  SparseMatrix forest_K_, forest_D_;
  RneaDerivatives forest_;
  std::vector<int> forest_k_slots_, forest_d_slots_;
};

}  // namespace stiffsim
