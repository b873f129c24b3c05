#pragma once
// A Newton matrix that a system factors and solves by its own structure,
// with no assembled sparse matrix: an exact articulated tree's
//   W = M(q) + h D_J + h^2 K_J
// (D_J, K_J the joint-space dampers and springs) by the articulated-body
// recursion in O(n), where the assembled W of a chain is dense and costs
// O(n^3) to factor. It leaves out the remaining terms of the exact Newton
// matrix (the configuration dependence of gravity and of the velocity
// products, the joint coupling of K and D): the residual stays exact, so it
// changes how fast Newton converges, never what it converges to.

#include <string>

#include "stiffsim/system.h"

namespace stiffsim {

class StructuredNewtonMatrix {
 public:
  virtual ~StructuredNewtonMatrix() = default;
  // Forms and factors the matrix of a step of size h at positions q. False
  // when it is not (numerically) positive definite. Allocates nothing.
  virtual bool factor(const ConstVectorRef& q, double h) = 0;
  // x = W^-1 rhs with the last factorization (nv values each). Allocates
  // nothing; x may not alias rhs.
  virtual void solve(const ConstVectorRef& rhs, VectorRef x) = 0;
  // For the stats ("articulated-body recursion").
  virtual std::string method() const = 0;
};

}  // namespace stiffsim
