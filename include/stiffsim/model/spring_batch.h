#pragma once

// The springs of a particle system whose two nodes are both free, laid out
// for the force loop: ParticleSystem::forces() adds their forces through
// add_forces(), four springs per vector operation where the CPU has AVX2
// with FMA, and the springs that touch a pinned node through their
// elements.
//
// Why: a Krylov product of the Newton iteration evaluates every force once
// (ImplicitIntegrator::newton_gmres), and on the 100x100 sheet the spring
// loop, a square root and three divisions per spring one spring at a time,
// was the largest single cost of a run (12% of its samples). The force is
// SpringElement::force()'s, written once more on lanes:
//   f_a = (k (l - L) + c (v_b - v_a).d / l) d / l,  f_b = -f_a,
// d = x_b - x_a, l = |d|; a collapsed spring (l <= kCollapsedSpringLength)
// exerts none, as there. The two agree to rounding (1/l is formed once per
// spring, where force() divides each component): spring_batch_test.

#include <vector>

#include "stiffsim/model/spring_element.h"

namespace stiffsim {

class SpringBatch {
 public:
  SpringBatch() = default;
  // The springs among elements whose nodes both have a DOF
  // (dof_of_node[node] >= 0, the first of its three), in elements' order,
  // each taken from its lower node (a) to its higher (b): the force is the
  // same either way, and springs in node order then share a in runs.
  SpringBatch(const std::vector<SpringElement>& elements, const std::vector<int>& dof_of_node);

  int size() const { return static_cast<int>(a_.size()); }
  // F[a..a+3) += f_a and F[b..b+3) += f_b for every spring, in order, at
  // positions q and velocities v (indexed by DOF).
  void add_forces(const double* q, const double* v, double* F) const;
  // The same through the portable loop, on every CPU (for the tests).
  void add_forces_portable(const double* q, const double* v, double* F) const;

 private:
  std::vector<int> a_, b_;  // first DOF of each spring's nodes
  std::vector<double> rest_, k_, c_;
};

}  // namespace stiffsim
