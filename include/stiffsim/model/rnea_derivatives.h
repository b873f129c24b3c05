#pragma once
// Analytic derivatives of the recursive Newton-Euler algorithm for an exact
// (reduced-coordinate) tree: K = dF/dq and D = dF/dv of the rigid bodies'
// share F = -tau(q, v, a) of ArticulatedSystem's forces (its force elements,
// generalized_element.h, add their own), by one forward and one
// backward sweep and then one dot product (or two) per entry, O(n d) for n
// bodies of depth d (Carpentier & Mansard, "Analytical Derivatives of Rigid
// Body Dynamics Algorithms", RSS 2018).
//
// The sweeps work in world coordinates, where a perturbation of joint j moves
// its whole subtree rigidly by the twist J_j dq_j and every quantity attached
// to that subtree changes by J_j x (.) (motions) or J_j x* (.) (forces); the
// non-covariant remainder is what the sweep carries. Conventions that differ
// from the paper's:
// - Floating and planar joints translate along directions fixed in the
//   joint (parent-side) frame and rotate the body (joints.h), so their motion
//   subspace depends on their own q. They are treated as a translation joint
//   followed by a rotation joint through a massless intermediate frame, each
//   part with columns fixed in its own child frame, as the paper assumes.
// - K is taken with respect to the raw coordinates q, a quaternion's four
//   components included: the rotation uses q / |q|, so a change dq turns the
//   body by w = 4 / |q|^2 N(q)^T dq (body frame; N the quaternion block of the
//   velocity map), and K's quaternion columns are the tangent columns times
//   that 3x4 map (zero along q itself), exactly what differentiating F gives.
// Bushings (compliant formulation) are force elements (bushing_element.h);
// the free bodies between them are covered by forest_derivatives.h.

#include <Eigen/Core>
#include <vector>

#include "stiffsim/linalg/sparse_pattern.h"
#include "stiffsim/model/articulated.h"
#include "stiffsim/model/articulated_model.h"
#include "stiffsim/model/rigid_tree.h"
#include "stiffsim/model/spatial.h"
#include "stiffsim/system.h"

namespace stiffsim {

class RneaDerivatives {
 public:
  // `inertias` per body (body frame).
  // K_pattern (nv x nq) and D_pattern (nv x nv) must be compressed and hold
  // exactly the entries of bodies on one root path, as
  // ArticulatedSystem::jacobian_pattern() of a tree without bushings does:
  // compute() then writes their values in storage order, without a slot
  // table. Throws std::invalid_argument otherwise.
  RneaDerivatives(const RigidTree& tree, std::vector<SpatialInertia> inertias,
                  const Eigen::Vector3d& gravity, const SparseMatrix& K_pattern,
                  const SparseMatrix& D_pattern);

  // K = dF/dq and D = dF/dv at (q, v), F = -tau; with
  // `acceleration` (nv values, may be null) the derivatives of F - M(q) a at
  // that fixed a. K and D must have the constructor's patterns; only their
  // values are written. Allocates nothing.
  // `world_acceleration`, if given, replaces gravity's upward acceleration
  // of the world for this evaluation (a root that moves).
  void compute(const ConstVectorRef& q, const ConstVectorRef& v, const double* acceleration,
               SparseMatrix* K, SparseMatrix* D, const Vec6<double>* world_acceleration = nullptr);

  int nq() const { return nq_; }
  int nv() const { return nv_; }

 private:
  // The rows of one column of K or D that belong to consecutive bodies on
  // one side of the column's body: rows of ancestors take the transported
  // force derivative (J_k . dF), rows of the body itself and of descendants
  // the composite-inertia products; contiguous bodies merge into one run.
  enum class RunKind { kAncestor, kOwn, kDescendant };
  struct Run {
    int first_row, rows;
    RunKind kind;
  };

  void forward_sweep(const ConstVectorRef& q, const ConstVectorRef& v, const double* acceleration,
                     const Vec6<double>& world_acceleration);
  void backward_sweep();
  void write_values(SparseMatrix* K, SparseMatrix* D) const;

  // --- Model (fixed at construction). ---
  std::vector<TreeBody> bodies_;
  std::vector<SpatialInertia> inertia_;
  Vec6<double> world_acceleration_;  // gravity as an upward acceleration of the world
  int nq_ = 0, nv_ = 0;
  std::vector<int> q_offset_, v_offset_;
  // Columns (per coordinate) of the translation part of a joint: they follow
  // the parent's motion; the others turn with the body.
  std::vector<char> v_translates_, q_translates_;
  std::vector<Run> runs_;
  std::vector<int> run_begin_;  // per body, into runs_ (size bodies + 1)
  long k_nonzeros_ = 0, d_nonzeros_ = 0;

  // --- Workspace (values of the last compute()). ---
  std::vector<Pose<double>> world_;
  std::vector<Vec6<double>> velocity_, acceleration_, force_;  // world; force: of the subtree
  // Composite inertia of each subtree and its variation dY/dv-like matrix
  // (the derivative of its bodies' forces along a change of their velocity
  // that is not a rigid transport).
  std::vector<Eigen::Matrix<double, 6, 6>> inertia_crb_, variation_crb_;
  // Per velocity coordinate l (columns): the world motion subspace J_l; the
  // stack (dA/dv_l; J_l); the subtree force derivative dF/dv_l. Per row k:
  // (Y_crb J_k; B_crb^T J_k).
  Eigen::Matrix<double, 6, Eigen::Dynamic> J_, force_dv_;
  Eigen::Matrix<double, 12, Eigen::Dynamic> motion_dv_, row_products_;
  // Per position coordinate c: the world twist of a unit dq_c; the stack
  // (dA/dq_c; dV/dq_c); dF/dq_c.
  Eigen::Matrix<double, 6, Eigen::Dynamic> twist_dq_, force_dq_;
  Eigen::Matrix<double, 12, Eigen::Dynamic> motion_dq_;
};

// The derivatives of the rigid bodies' share of `system`'s forces in the
// exact formulation (its tree, inertias, gravity and Jacobian patterns). Throws
// std::invalid_argument for a system with bushings.
RneaDerivatives make_rnea_derivatives(const ArticulatedSystem& system);

}  // namespace stiffsim
