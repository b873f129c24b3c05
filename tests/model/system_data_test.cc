// Model and data apart (system.h: SystemData): a System is immutable, and
// everything its evaluations write lives in the caller's data. Threads that
// share one scene, each with its own data, get bit for bit what one thread
// gets alone; a workspace shared behind the const interface would mix their
// intermediate results.

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <memory>
#include <thread>
#include <vector>

#include "stiffsim/model/articulated.h"
#include "stiffsim/model/compliant.h"
#include "stiffsim/model/particle_meshes.h"
#include "stiffsim/model/particles.h"
#include "stiffsim/scene.h"

namespace stiffsim {
namespace {

using Eigen::Vector3d;
using Eigen::VectorXd;

std::unique_ptr<ParticleSystem> rope(int nodes) {
  RopeSpec spec;
  spec.nodes = nodes;
  spec.length = 0.5;
  spec.total_mass = 0.05;
  spec.stretch = SpringParameters{2e3, 0.5};
  spec.bend = SpringParameters{1.0, 0.05};
  spec.pinned = std::vector<int>{};
  ParticleDescription d = make_rope(spec);
  for (Vector3d& p : d.positions) p += Vector3d(0.05, 0.0, -0.3);
  return std::make_unique<ParticleSystem>(d);
}

// Every kind of workspace at once: an exact chain (inverse dynamics, the
// composite rigid body algorithm, the recursive derivatives, dual numbers),
// a compliant chain (the bushings' derivatives), a rope, and attachments
// (the scene's own points) coupling them.
std::unique_ptr<Scene> coupled_scene() {
  ArticulatedOptions o;
  o.initial_q = Eigen::Vector3d(0.3, -0.4, 0.5);
  o.joint_forces.assign(3, JointForce{0.0, 0.0, 0.1});
  std::vector<std::unique_ptr<System>> parts;
  parts.push_back(std::make_unique<ArticulatedSystem>(make_chain_tree(3), o));
  parts.push_back(make_compliant(make_chain_tree(3, "compliant"), o, BushingParameters{}));
  parts.push_back(rope(6));
  const Vector3d tip(0.02, 0.0, -0.1);
  std::vector<Attachment> at = {
      {"grip", {0, 2, tip}, {2, 0, Vector3d::Zero()}, 1e3, 1.0},
      {"tail", {2, 5, Vector3d::Zero()}, {1, 2, tip}, 200.0, 0.5},
      {"brace", {1, 0, Vector3d(0.0, 0.03, -0.05)}, {-1, 0, Vector3d(0.1, 0.0, 0.0)}, 30.0, 0.5}};
  return std::make_unique<Scene>("coupled", std::move(parts), std::move(at));
}

// Everything the evaluations return at one state, side by side.
struct Evaluation {
  VectorXd F, r;
  Eigen::MatrixXd M, K, D, K_auto, D_auto;
  double energy = 0.0;
  bool operator==(const Evaluation& o) const {
    return F == o.F && r == o.r && M == o.M && K == o.K && D == o.D && K_auto == o.K_auto &&
           D_auto == o.D_auto && energy == o.energy;
  }
};

// The workspaces of one caller: the scene's data, the data of its exact
// chain (the rope has no momentum residual, so the scene has none; the
// chain's is evaluated on its own), and matrices the evaluations fill.
struct Caller {
  explicit Caller(const Scene& s)
      : scene(s.make_data()),
        chain(s.component(0).make_data()),
        F(s.dimensions().nv),
        r(s.component(0).dimensions().nv),
        M(s.mass_matrix_pattern()),
        J(s.jacobian_pattern()),
        J_auto(s.jacobian_pattern()) {}
  std::unique_ptr<SystemData> scene, chain;
  VectorXd F, r;
  SparseMatrix M;
  ForceJacobians J, J_auto;
};

Evaluation evaluate(const Scene& s, Caller* out, const State& x) {
  SystemData& data = *out->scene;
  const Dimensions d = s.dimensions();
  const auto q = x.q(d), v = x.v(d), z = x.z(d);
  s.forces(data, x.t, q, v, z, out->F);
  const System& chain = s.component(0);
  const Dimensions c = chain.dimensions();
  const VectorXd dv = 1e-3 * v.head(c.nv);
  chain.momentum_residual(*out->chain, x.t, q.head(c.nq), v.head(c.nv), z.head(0), dv, 1e-2,
                          out->r);
  s.mass_matrix(data, q, &out->M);
  JacobianRequest complete;
  complete.complete = true;
  s.force_jacobians(data, x.t, q, v, z, complete, &out->J);
  s.automatic_force_jacobians(data, x.t, q, v, z, complete, &out->J_auto);
  return Evaluation{out->F,
                    out->r,
                    Eigen::MatrixXd(out->M),
                    Eigen::MatrixXd(out->J.dF_dq),
                    Eigen::MatrixXd(out->J.dF_dv),
                    Eigen::MatrixXd(out->J_auto.dF_dq),
                    Eigen::MatrixXd(out->J_auto.dF_dv),
                    s.energy(data, x)};
}

std::vector<State> states(const Scene& s, int count) {
  const Dimensions d = s.dimensions();
  std::vector<State> all;
  for (int k = 0; k < count; ++k) {
    State x = s.initial_state();
    x.t = 0.1 * k;
    for (int i = 0; i < d.nq; ++i) x.x[i] += 0.05 * std::sin(1.3 * i + 0.7 * k);
    s.project_positions(x.x.head(d.nq));
    for (int i = 0; i < d.nv; ++i) x.x[d.nq + i] = 0.8 * std::cos(0.9 * i + 1.1 * k);
    all.push_back(x);
  }
  return all;
}

TEST(SystemData, ThreadsSharingASceneGetWhatOneThreadGets) {
  // The reference comes from a scene of its own, so the threads also race
  // to build the shared one's patterns (on first use, once).
  const std::unique_ptr<Scene> scene = coupled_scene(), alone = coupled_scene();
  ASSERT_TRUE(scene->component(0).capabilities().momentum_residual);
  const std::vector<State> xs = states(*alone, 6);
  // One thread, one data: the reference.
  std::vector<Evaluation> reference;
  {
    Caller one(*alone);
    for (const State& x : xs) reference.push_back(evaluate(*alone, &one, x));
  }
  // The states differ, so a thread that read another's intermediate result
  // would see it.
  ASSERT_FALSE(reference[0].F.isApprox(reference[1].F, 1e-3));
  ASSERT_FALSE(reference[0].K.isApprox(reference[1].K, 1e-3));

  // Each thread walks the states in its own order, so at any instant the
  // threads are evaluating different states.
  constexpr int kThreads = 4, kRounds = 40;
  std::vector<int> mismatches(kThreads, 0);
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      Caller own(*scene);
      for (int round = 0; round < kRounds; ++round) {
        for (size_t k = 0; k < xs.size(); ++k) {
          const size_t i = (k * (t + 1) + t + round) % xs.size();
          if (!(evaluate(*scene, &own, xs[i]) == reference[i])) ++mismatches[t];
        }
      }
    });
  }
  for (std::thread& th : threads) th.join();
  for (int t = 0; t < kThreads; ++t) EXPECT_EQ(mismatches[t], 0) << "thread " << t;
}

TEST(SystemData, ADataServesEvaluationsInAnyOrder) {
  // Two data of one scene, used in turn at different states: each gives
  // what a fresh data gives (nothing an evaluation keeps leaks into the
  // next one, whichever data or state came before).
  const std::unique_ptr<Scene> scene = coupled_scene();
  const std::vector<State> xs = states(*scene, 3);
  Caller a(*scene), b(*scene);
  for (int k : {0, 2, 1, 0, 2}) {
    Caller fresh(*scene);
    const Evaluation expected = evaluate(*scene, &fresh, xs[k]);
    Caller fresh_next(*scene);
    const Evaluation expected_next = evaluate(*scene, &fresh_next, xs[(k + 1) % 3]);
    EXPECT_TRUE(evaluate(*scene, &a, xs[k]) == expected) << k;
    EXPECT_TRUE(evaluate(*scene, &b, xs[(k + 1) % 3]) == expected_next) << k;
  }
}

}  // namespace
}  // namespace stiffsim
