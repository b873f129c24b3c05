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
//   Stencil velocity_stencil() const;   // runs of consecutive coordinates
//   Stencil position_stencil() const;
//   template <typename T, typename Q, typename V>      // double or dual numbers
//   void add_force(double t, const Q& q, const V& v,
//                  Eigen::Matrix<T, Eigen::Dynamic, 1>* F) const;
//   void add_jacobians(double t, const ConstVectorRef& q, const ConstVectorRef& v,
//                      const int* k_slots, const int* d_slots,
//                      double* K, double* D) const;
//       // adds dF/dq of velocity run r's k-th coordinate (row) and position
//       // coordinate c of the stencil (column, counted over the runs) at
//       // K[k_slots[c * runs + r] + k], D likewise: the rows of a run are
//       // consecutive in each compressed column, so one slot per run and
//       // column serves them all
//   double energy(double t, const ConstVectorRef& q) const;
//   static constexpr bool kJointLocal;
// A joint-local element (a joint's spring, damper or drive) acts on the one
// coordinate of a 1-DOF joint with constant K and D; it also provides
//   int body() const; double stiffness() const; double damping() const;
// (-K and -D), which the articulated-body recursion folds into its pivots
// (articulated_body_solver.h): the only elements an O(n) Newton matrix of a
// tree can hold.

#include <Eigen/Core>
#include <stdexcept>
#include <vector>

#include "stiffsim/linalg/sparse_pattern.h"
#include "stiffsim/system.h"

namespace stiffsim {

// Consecutive coordinates first, first + 1, ..., first + count - 1.
struct CoordinateRun {
  int first = 0, count = 0;
};
using Stencil = std::vector<CoordinateRun>;

// Per element of a set, the value slots of the first row of each velocity
// run in each column of its stencil: K's columns are its position
// coordinates, D's its velocity coordinates.
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
      const Stencil rows = e.velocity_stencil(), q_cols = e.position_stencil();
      for (const CoordinateRun& rr : rows) {
        for (int r = rr.first; r < rr.first + rr.count; ++r) {
          for (const CoordinateRun& cr : q_cols)
            for (int c = cr.first; c < cr.first + cr.count; ++c) add_k(r, c);
          for (const CoordinateRun& cr : rows)
            for (int c = cr.first; c < cr.first + cr.count; ++c) add_d(r, c);
        }
      }
    }
  }

  // The slots in the finished patterns; throws std::out_of_range (slot_of)
  // where an element's block is missing from them, std::logic_error where a
  // run's rows are not consecutive in a column.
  ElementSlots find_slots(const SparseMatrix& K, const SparseMatrix& D) const {
    ElementSlots slots;
    auto add = [](const SparseMatrix& A, const Stencil& rows, const Stencil& cols,
                  std::vector<int>* out) {
      for (const CoordinateRun& cr : cols) {
        for (int c = cr.first; c < cr.first + cr.count; ++c) {
          for (const CoordinateRun& rr : rows) {
            const int first = slot_of(A, rr.first, c);
            if (slot_of(A, rr.first + rr.count - 1, c) != first + rr.count - 1) {
              throw std::logic_error("GeneralizedElementSet: a run's rows are not consecutive");
            }
            out->push_back(first);
          }
        }
      }
    };
    for (const E& e : elements) {
      const Stencil rows = e.velocity_stencil(), q_cols = e.position_stencil();
      add(K, rows, q_cols, &slots.k.emplace_back());
      add(D, rows, rows, &slots.d.emplace_back());
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
