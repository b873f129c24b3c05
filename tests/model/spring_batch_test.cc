// SpringBatch (the force loop of the springs between free nodes) against
// SpringElement::force(), the one definition it restates, through both of
// its loops: springs in any order and orientation, counts around its step
// of four, collapsed and rest-length-zero springs.

#include "stiffsim/model/spring_batch.h"

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace stiffsim {
namespace {

struct Scene {
  std::vector<int> dof_of_node;
  std::vector<SpringElement> springs;
  Eigen::VectorXd q, v;  // by DOF
};

// nodes nodes, every third pinned (no DOF), and springs random pairs of
// them. Spring 0 joins two free nodes placed at one point (collapsed);
// spring 1 has rest length 0.
Scene random_scene(int nodes, int springs, std::mt19937* rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::uniform_int_distribution<int> node(0, nodes - 1);
  Scene s;
  int free = 0;
  for (int i = 0; i < nodes; ++i) s.dof_of_node.push_back(i % 3 == 2 ? -1 : 3 * free++);
  s.q.resize(3 * free);
  s.v.resize(3 * free);
  for (int i = 0; i < 3 * free; ++i) {
    s.q[i] = u(*rng);
    s.v[i] = u(*rng);
  }
  s.q.segment<3>(s.dof_of_node[1]) = s.q.segment<3>(s.dof_of_node[0]);
  for (int k = 0; k < springs; ++k) {
    Spring spring;
    spring.a = k == 0 ? 1 : node(*rng);
    spring.b = k == 0 ? 0 : node(*rng);
    while (spring.b == spring.a) spring.b = node(*rng);
    spring.rest_length = k == 1 ? 0.0 : 0.5 + 0.5 * u(*rng);
    spring.k = 100.0 * (1.5 + u(*rng));
    spring.c = 2.0 * (1.0 + u(*rng));
    s.springs.emplace_back(spring, k, nodes, "test");
  }
  return s;
}

// Each free-free spring's force() added to its free nodes' DOFs.
Eigen::VectorXd element_forces(const Scene& s) {
  Eigen::VectorXd F = Eigen::VectorXd::Zero(s.q.size());
  for (const SpringElement& e : s.springs) {
    const auto [a, b] = e.nodes();
    const int da = s.dof_of_node[a], db = s.dof_of_node[b];
    if (da < 0 || db < 0) continue;
    const Eigen::Vector3d x[2] = {s.q.segment<3>(da), s.q.segment<3>(db)};
    const Eigen::Vector3d v[2] = {s.v.segment<3>(da), s.v.segment<3>(db)};
    Eigen::Vector3d f[2];
    e.force(x, v, f);
    F.segment<3>(da) += f[0];
    F.segment<3>(db) += f[1];
  }
  return F;
}

// Each spring's force is formed with one division by its length where
// force() divides each coordinate, and the sums run in another order: a
// few units of double's epsilon on forces of unit size; a wrong index or
// sign shows as O(1).
constexpr double kTolerance = 1e-12;

TEST(SpringBatch, BothLoopsAddTheElementsForces) {
  std::mt19937 rng(20261203);
  for (int springs : {2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 40, 97}) {
    const Scene s = random_scene(springs < 40 ? 12 : 30, springs, &rng);
    const SpringBatch batch(s.springs, s.dof_of_node);
    int free_free = 0;
    for (const SpringElement& e : s.springs) {
      const auto [a, b] = e.nodes();
      free_free += s.dof_of_node[a] >= 0 && s.dof_of_node[b] >= 0;
    }
    EXPECT_EQ(batch.size(), free_free);
    const Eigen::VectorXd expected = element_forces(s);
    const double scale = std::max(expected.lpNorm<Eigen::Infinity>(), 1.0);
    // Added to what F holds already.
    const Eigen::VectorXd F0 = Eigen::VectorXd::LinSpaced(s.q.size(), -1.0, 1.0);
    Eigen::VectorXd F = F0, F_portable = F0;
    batch.add_forces(s.q.data(), s.v.data(), F.data());
    batch.add_forces_portable(s.q.data(), s.v.data(), F_portable.data());
    EXPECT_LT((F - F0 - expected).lpNorm<Eigen::Infinity>(), kTolerance * scale) << springs;
    EXPECT_LT((F_portable - F0 - expected).lpNorm<Eigen::Infinity>(), kTolerance * scale)
        << springs;
  }
}

// The collapsed spring 0 is checked above, against force()'s zero. A
// state that is not finite gives forces that are not finite, in both loops
// (the integrators report the step then).
TEST(SpringBatch, NaNPositionsGiveNaNForces) {
  std::mt19937 rng(7);
  Scene s = random_scene(12, 9, &rng);
  s.q[0] = std::numeric_limits<double>::quiet_NaN();
  const SpringBatch batch(s.springs, s.dof_of_node);
  ASSERT_GE(batch.size(), 4);
  Eigen::VectorXd F = Eigen::VectorXd::Zero(s.q.size()), F_portable = F;
  batch.add_forces(s.q.data(), s.v.data(), F.data());
  batch.add_forces_portable(s.q.data(), s.v.data(), F_portable.data());
  EXPECT_TRUE(F.hasNaN());
  EXPECT_TRUE(F_portable.hasNaN());
}

}  // namespace
}  // namespace stiffsim
