#pragma once
// Force elements of an articulated system (articulated.h): the counterpart,
// on generalized coordinates, of a particle system's elements
// (force_element.h). An element acts on a fixed stencil of velocity
// coordinates (the rows of its force, the columns of its D) and of position
// coordinates (the columns of its K), and adds its share of F, K = dF/dq,
// D = dF/dv and the energy. The system keeps per element the slots of its
// stencil's blocks in the Jacobian patterns, computed once, so the loops over
// forces, analytic and automatic Jacobians, energy and patterns are written
// once for every element type (joint springs, drives, bushings).
//
// An element type E provides (static dispatch: no virtual call per element
// in the recursions' loops):
//   std::vector<int> velocity_stencil() const;
//   std::vector<int> position_stencil() const;
//   template <typename T, typename Q, typename V>      // double or dual numbers
//   void add_force(double t, const Q& q, const V& v,
//                  Eigen::Matrix<T, Eigen::Dynamic, 1>* F) const;
//   void add_jacobians(double t, const ConstVectorRef& q, const ConstVectorRef& v,
//                      const int* k_slots, const int* d_slots,
//                      double* K, double* D) const;
//       // adds dF/dq of its stencil at K[k_slots[c * rows + r]] (r over the
//       // velocity stencil, c over the position stencil), D likewise
//   double energy(double t, const ConstVectorRef& q) const;
//   static constexpr bool kJointLocal;
// A joint-local element (a joint's spring, damper or drive) acts on the one
// coordinate of a 1-DOF joint with constant K and D; it also provides
//   int body() const; double stiffness() const; double damping() const;
// (-K and -D), which the articulated-body recursion folds into its pivots
// (articulated_body_solver.h): the only elements an O(n) Newton matrix of a
// tree can hold.

#include <Eigen/Core>
#include <vector>

#include "stiffsim/linalg/sparse_pattern.h"
#include "stiffsim/system.h"

namespace stiffsim {

// Per element of a set, the value slots of its K block (velocity stencil x
// position stencil) and D block (velocity stencil squared), column-major.
// Kept with the system's lazily built patterns, apart from the elements: a
// run that never assembles a Jacobian never builds them.
struct ElementSlots {
  std::vector<std::vector<int>> k, d;
};

// The elements of one type.
template <typename E>
struct GeneralizedElementSet {
  std::vector<E> elements;

  // Every element's blocks' positions (for the patterns).
  template <typename AddK, typename AddD>
  void add_to_patterns(AddK&& add_k, AddD&& add_d) const {
    for (const E& e : elements) {
      const std::vector<int> rows = e.velocity_stencil(), q_cols = e.position_stencil();
      for (int r : rows) {
        for (int c : q_cols) add_k(r, c);
        for (int c : rows) add_d(r, c);
      }
    }
  }

  // The slots in the finished patterns; throws std::out_of_range (slot_of)
  // where an element's block is missing from them.
  ElementSlots find_slots(const SparseMatrix& K, const SparseMatrix& D) const {
    ElementSlots slots;
    for (const E& e : elements) {
      const std::vector<int> rows = e.velocity_stencil(), q_cols = e.position_stencil();
      std::vector<int>& ks = slots.k.emplace_back();
      std::vector<int>& ds = slots.d.emplace_back();
      for (int c : q_cols)
        for (int r : rows) ks.push_back(slot_of(K, r, c));
      for (int c : rows)
        for (int r : rows) ds.push_back(slot_of(D, r, c));
    }
    return slots;
  }

  template <typename T, typename Q, typename V>
  void add_forces(double t, const Q& q, const V& v, Eigen::Matrix<T, Eigen::Dynamic, 1>* F) const {
    for (const E& e : elements) e.template add_force<T>(t, q, v, F);
  }

  void add_jacobians(double t, const ConstVectorRef& q, const ConstVectorRef& v,
                     const ElementSlots& slots, ForceJacobians* J) const {
    double* K = J->dF_dq.valuePtr();
    double* D = J->dF_dv.valuePtr();
    for (std::size_t i = 0; i < elements.size(); ++i) {
      elements[i].add_jacobians(t, q, v, slots.k[i].data(), slots.d[i].data(), K, D);
    }
  }

  double energy(double t, const ConstVectorRef& q) const {
    double e = 0.0;
    for (const E& element : elements) e += element.energy(t, q);
    return e;
  }
};

}  // namespace stiffsim
