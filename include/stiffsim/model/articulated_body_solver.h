#pragma once
// The articulated-body algorithm as a linear solver (Featherstone 2008,
// chapter 7): the backward sweep folds each subtree into an articulated
// inertia and a joint-space pivot D_i = S_i^T I^A_i S_i + d_i, the forward
// sweep recovers x. With zero velocities and gravity it solves
// (M(q) + diag(d)) x = b in O(n) for any tree, and its pivots are those of an
// LDL^T factorization of that matrix (leaves first), so they also say whether
// it is positive definite. The diagonal d is where joint-space terms enter,
// as a rotor's armature does: here h c_i + h^2 k_i of the joint dampers and
// springs, giving the Newton matrix of a velocity-implicit step.

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <vector>

#include "stiffsim/model/articulated_model.h"
#include "stiffsim/model/joints.h"
#include "stiffsim/structured_newton_matrix.h"

namespace stiffsim {

class ArticulatedBodySolver : public StructuredNewtonMatrix {
 public:
  // The model must outlive the solver. `stiffness` and `damping` per body:
  // the joint-local force elements' (ArticulatedSystem::pivot_stiffness()).
  ArticulatedBodySolver(const ArticulatedModel& model, std::vector<double> stiffness,
                        std::vector<double> damping);

  // (M(q) + h D_J + h^2 K_J): d_i = h damping_i + h^2 stiffness_i.
  bool factor(const ConstVectorRef& q, double h) override;
  void solve(const ConstVectorRef& rhs, VectorRef x) override;
  std::string method() const override { return "articulated-body recursion"; }

  // Smallest pivot over the largest of the last factorization (the
  // eigenvalues of each joint's pivot block): how close to singular.
  double pivot_ratio() const { return pivot_ratio_; }

 private:
  using Block = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, 6, 6>;
  using Column = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, 6, 1>;
  const ArticulatedModel& model_;
  std::vector<double> stiffness_, damping_;
  std::vector<Eigen::Matrix<double, 6, 6>> X_, IA_;  // parent-to-body motion transform; I^A
  std::vector<MotionSubspace<double>> S_, U_, UD_;   // S; U = I^A S; U D^-1
  std::vector<Block> Dinv_;                          // inverse pivot blocks (at most 6 x 6)
  Eigen::LLT<Block> llt_;                            // for pivot blocks of multi-DOF joints
  std::vector<Vec6<double>> p_, a_;                  // solve: bias forces, accelerations
  std::vector<Column> u_;
  double pivot_ratio_ = 0.0;
};

}  // namespace stiffsim
