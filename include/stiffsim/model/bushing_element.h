#pragma once
// A bushing (bushing.h) as a force element of the compliant formulation
// (generalized_element.h): its stencil is the two free bodies it joins (one,
// for a bushing to the world), 6 velocities and 7 coordinates each.
//
// Its analytic K and D: the force f on the child (the parent takes -f at
// the same point) and its moments about the two body origins are
// differentiated with respect to small world-frame displacements and
// rotations of both bodies and to their world velocities; the chain rule
// then gives the raw coordinates:
// - position columns directly;
// - a quaternion's four columns through the world rotation it causes,
//   R 4 / |q|^2 N(q)^T dq (N the quaternion block of the velocity map; zero
//   along q, as differentiating q / |q| gives), with the body's world angular
//   velocity R w_body turning along;
// - generalized angular rows are R^T (moment), so a body's own rotation also
//   turns its rows.
// O(1) per bushing, no allocation.

#include <Eigen/Core>
#include <vector>

#include "stiffsim/model/bushing.h"
#include "stiffsim/model/generalized_element.h"
#include "stiffsim/system.h"

namespace stiffsim {

class BushingElement {
 public:
  static constexpr bool kJointLocal = false;
  // `at`: where the bodies' coordinates sit (bushing_offsets()).
  BushingElement(Bushing bushing, const BushingOffsets& at)
      : bushing_(std::move(bushing)), at_(at) {}

  Stencil velocity_stencil() const;  // (parent,) child: 6 each
  Stencil position_stencil() const;  // (parent,) child: 7 each
  template <typename T, typename Q, typename V>
  void add_force(double, const Q& q, const V& v, Eigen::Matrix<T, Eigen::Dynamic, 1>* F) const {
    add_bushing_forces<T>(bushing_, q, v, at_, F);
  }
  void add_jacobians(double t, const ConstVectorRef& q, const ConstVectorRef& v, const int* k_slots,
                     const int* d_slots, double* K, double* D) const;
  double energy(double, const ConstVectorRef& q) const { return bushing_energy(bushing_, q, at_); }

  const Bushing& bushing() const { return bushing_; }
  const BushingOffsets& offsets() const { return at_; }

 private:
  Bushing bushing_;
  BushingOffsets at_;
};

}  // namespace stiffsim
