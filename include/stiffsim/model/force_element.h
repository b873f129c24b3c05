#pragma once
// Force elements of a particle system (particles.h): a force that acts on a
// fixed list of nodes, its stencil, and adds its share of F, K = dF/dq,
// D = dF/dv and the energy. The system keeps per element the slots of its
// stencil's 3x3 blocks in the Jacobian patterns, computed once, so a new
// kind of force (a triangle membrane, a bending hinge) is a new element
// type with its kernel and nothing else: the system's loops over forces,
// analytic and automatic Jacobians, energy and patterns are generic.
//
// An element type E provides (static dispatch: no virtual call per element
// in the hot loops):
//   static constexpr int kNodes;               // stencil size
//   std::array<int, kNodes> nodes() const;     // node indices
//   template <typename S>                      // double or dual numbers
//   void force(const Vector3<S>* x, const Vector3<S>* v, Vector3<S>* f) const;
//       // f[i], the force on stencil node i, from positions and velocities
//   double energy(const Eigen::Vector3d* x) const;
// and its Jacobian blocks in one of two forms:
//   void jacobian_blocks(const Eigen::Vector3d* x, const Eigen::Vector3d* v,
//                        const Eigen::Vector3d* x_tension,
//                        const JacobianRequest& request, Eigen::Matrix3d* K,
//                        Eigen::Matrix3d* D, long* approximated) const;
//       // any stencil: K[i * kNodes + j] = df_i/dx_j, D likewise for
//       // velocities; x_tension: the stencil at request.tension_positions,
//       // or null
// or, for two nodes whose force depends on the differences x_1 - x_0 and
// v_1 - v_0 alone (a spring, a damper),
//   static constexpr bool kDifference = true;
//   void jacobian_difference(same arguments, Eigen::Matrix3d* S,
//                            Eigen::Matrix3d* C, long* approximated) const;
//       // S = df_0/dx_1 and C = df_0/dv_1: the blocks are -S, S, S, -S
//       // (and -C, C, C, -C), scattered with their signs, so the loops
//       // neither build nor copy the four blocks (a cloth's Jacobian in
//       // 0.82x the time at 32x32 and at 100x100, BM_ForceJacobians)

#include <Eigen/Core>
#include <array>
#include <type_traits>
#include <vector>

namespace stiffsim {

template <typename Scalar>
using Vector3 = Eigen::Matrix<Scalar, 3, 1>;

// Whether E gives its Jacobian in the difference form (above).
template <typename E, typename = void>
struct is_difference_element : std::false_type {};
template <typename E>
struct is_difference_element<E, std::void_t<decltype(E::kDifference)>>
    : std::bool_constant<E::kDifference && E::kNodes == 2> {};

// The elements of one type and, per element, the slots of its blocks in
// the Jacobian patterns: block (i, j) of element e at
// slots[e][9 * (i * kNodes + j)], column-major within the block, -1 where
// node i or node j is pinned.
template <typename E>
struct ElementSet {
  using Element = E;
  static constexpr int kNodes = E::kNodes;
  static constexpr int kBlockSlots = 9 * kNodes * kNodes;
  std::vector<E> elements;
  std::vector<std::array<int, kBlockSlots>> slots;
};

}  // namespace stiffsim
