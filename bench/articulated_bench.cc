// The kernels of an articulated step: F by recursive Newton-Euler, M by the
// composite rigid body algorithm, the exact K and D by seeded forward-mode
// differentiation, for chains in reduced coordinates (dense) and as free
// bodies with bushings (sparse), and one VIE step of each; and the exact
// chain's K and D by the analytic Newton-Euler derivatives, and the compliant
// chain's by the analytic bushing derivatives, against the automatic
// differentiation they replace.
//
//   build/bench/articulated_bench --benchmark_repetitions=5
//     --benchmark_report_aggregates_only=true

#include <benchmark/benchmark.h>

#include "stiffsim/integrators/velocity_implicit_euler.h"
#include "stiffsim/model/rnea_derivatives.h"
#include "stiffsim/reports/bench_scenes.h"

namespace stiffsim {
namespace {

std::unique_ptr<ArticulatedSystem> make_system(int links, bool compliant) {
  ArticulatedOptions o;
  o.initial_q = Eigen::VectorXd::Constant(links, 0.05);
  if (compliant) return make_compliant(make_chain_tree(links), o, BushingParameters{});
  return std::make_unique<ArticulatedSystem>(make_chain_tree(links), o);
}

void BM_Forces(benchmark::State& state) {
  const auto sys = make_system(static_cast<int>(state.range(0)), state.range(1) != 0);
  const std::unique_ptr<SystemData> data = sys->make_data();
  const State x = sys->initial_state();
  const Dimensions d = sys->dimensions();
  Eigen::VectorXd F(d.nv);
  for (auto _ : state) {
    sys->forces(*data, 0.0, x.q(d), x.v(d), x.z(d), F);
    benchmark::DoNotOptimize(F.data());
  }
}

void BM_MassMatrix(benchmark::State& state) {
  const auto sys = make_system(static_cast<int>(state.range(0)), state.range(1) != 0);
  const std::unique_ptr<SystemData> data = sys->make_data();
  const State x = sys->initial_state();
  const Dimensions d = sys->dimensions();
  SparseMatrix M = sys->mass_matrix_pattern();
  for (auto _ : state) {
    sys->mass_matrix(*data, x.q(d), &M);
    benchmark::DoNotOptimize(M.valuePtr());
  }
}

void BM_Jacobians(benchmark::State& state) {
  const auto sys = make_system(static_cast<int>(state.range(0)), state.range(1) != 0);
  const std::unique_ptr<SystemData> data = sys->make_data();
  const State x = sys->initial_state();
  const Dimensions d = sys->dimensions();
  ForceJacobians J = sys->jacobian_pattern();
  for (auto _ : state) {
    sys->force_jacobians(*data, 0.0, x.q(d), x.v(d), x.z(d), JacobianRequest{}, &J);
    benchmark::DoNotOptimize(J.dF_dq.valuePtr());
  }
  state.counters["passes"] = sys->jacobian_passes();
}

// Exact chain at a state where every term is nonzero (all joints bent and
// moving), with the acceleration term as Newton requests it.
void BM_ExactJacobians(benchmark::State& state) {
  const int links = static_cast<int>(state.range(0));
  const bool analytic = state.range(1) != 0;
  const auto sys = make_system(links, false);
  const std::unique_ptr<SystemData> data = sys->make_data();
  const Eigen::VectorXd q = Eigen::VectorXd::LinSpaced(links, 0.1, 0.4);
  const Eigen::VectorXd v = Eigen::VectorXd::LinSpaced(links, -1.0, 1.0);
  const Eigen::VectorXd a = Eigen::VectorXd::LinSpaced(links, 2.0, -3.0);
  RneaDerivatives rnea = make_rnea_derivatives(*sys);
  ForceJacobians J = sys->jacobian_pattern();
  JacobianRequest request;
  request.acceleration = a.data();
  for (auto _ : state) {
    if (analytic) {
      rnea.compute(q, v, a.data(), &J.dF_dq, &J.dF_dv);
    } else {
      sys->automatic_force_jacobians(*data, 0.0, q, v, Eigen::VectorXd(), request, &J);
    }
    benchmark::DoNotOptimize(J.dF_dq.valuePtr());
    benchmark::DoNotOptimize(J.dF_dv.valuePtr());
  }
}

// Compliant chain (free bodies and bushings) with joint springs and dampers,
// moving, with the acceleration term: every term of K and D is nonzero.
void BM_CompliantJacobians(benchmark::State& state) {
  const int links = static_cast<int>(state.range(0));
  const bool analytic = state.range(1) != 0;
  ArticulatedOptions o;
  o.initial_q = Eigen::VectorXd::LinSpaced(links, 0.1, 0.4);
  o.initial_v = Eigen::VectorXd::LinSpaced(links, -1.0, 1.0);
  o.joint_forces.assign(links, JointForce{10.0, 0.0, 0.1});
  const auto sys = make_compliant(make_chain_tree(links), o, BushingParameters{});
  const std::unique_ptr<SystemData> data = sys->make_data();
  const State x = sys->initial_state();
  const Dimensions d = sys->dimensions();
  const Eigen::VectorXd a = Eigen::VectorXd::LinSpaced(d.nv, 2.0, -3.0);
  ForceJacobians J = sys->jacobian_pattern();
  JacobianRequest request;
  request.acceleration = a.data();
  for (auto _ : state) {
    if (analytic) {
      sys->force_jacobians(*data, 0.0, x.q(d), x.v(d), x.z(d), request, &J);
    } else {
      sys->automatic_force_jacobians(*data, 0.0, x.q(d), x.v(d), x.z(d), request, &J);
    }
    benchmark::DoNotOptimize(J.dF_dq.valuePtr());
    benchmark::DoNotOptimize(J.dF_dv.valuePtr());
  }
}

void BM_VieStep(benchmark::State& state) {
  const auto sys = make_system(static_cast<int>(state.range(0)), state.range(1) != 0);
  IntegratorSettings s;
  s.fixed_step = true;
  s.max_step = 1e-3;
  VelocityImplicitEuler vie(*sys, s, ImplicitSettings{});
  vie.initialize(sys->initial_state());
  vie.integrate_to(2e-3);  // first factorization and symbolic analysis out of the loop
  for (auto _ : state) vie.integrate_to(vie.state().t + 1e-3);
}

// The issue-15 benchmark: an exact serial chain with joint springs of 1e4
// N m/rad bent 0.05 rad at every joint, VIE at a fixed h = 1 ms; `auto`
// takes the articulated-body recursion (O(n) per Newton iteration).
void BM_ExactChainStep(benchmark::State& state) {
  const int links = static_cast<int>(state.range(0));
  ImplicitSettings implicit;
  implicit.newton_solve = state.range(1) == 0 ? NewtonSolve::kRecursive : NewtonSolve::kChord;
  ArticulatedOptions o;
  o.initial_q = Eigen::VectorXd::Constant(links, 0.05);
  o.joint_forces.assign(links, JointForce{1e4, 0.0, 0.0});
  const ArticulatedSystem sys(make_chain_tree(links), o);
  IntegratorSettings s;
  s.fixed_step = true;
  s.max_step = 1e-3;
  VelocityImplicitEuler vie(sys, s, implicit);
  vie.initialize(sys.initial_state());
  vie.integrate_to(2e-3);
  const IntegratorStatistics before = vie.statistics();
  long steps = 0;
  for (auto _ : state) {
    vie.integrate_to(vie.state().t + 1e-3);
    ++steps;
  }
  const IntegratorStatistics& st = vie.statistics();
  state.counters["newton_per_step"] =
      double(st.newton_raphson_iterations - before.newton_raphson_iterations) / steps;
  state.counters["gmres_per_step"] =
      double(st.krylov_iterations - before.krylov_iterations) / steps;
}
// Args: links, assembled (0 the recursion, 1 the chord on the assembled
// dense matrix: where the two cross is auto's threshold).
BENCHMARK(BM_ExactChainStep)
    ->ArgNames({"links", "assembled"})
    ->Args({10, 0})->Args({10, 1})
    ->Args({30, 0})->Args({30, 1})
    ->Args({60, 0})->Args({60, 1})
    ->Args({100, 0})->Args({100, 1})
    ->Args({300, 0})->Args({300, 1})
    ->Args({1000, 0})->Args({1000, 1})
    ->Args({3000, 0})
    ->Args({10000, 0})
    ->Unit(benchmark::kMillisecond);

// Args: links, compliant (0 exact, 1 compliant).
BENCHMARK(BM_Forces)->Args({10, 0})->Args({100, 0})->Args({100, 1})->Args({1000, 1})->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_MassMatrix)->Args({10, 0})->Args({100, 0})->Args({100, 1})->Args({1000, 1})->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_Jacobians)->Args({10, 0})->Args({100, 0})->Args({100, 1})->Args({1000, 1})->Unit(benchmark::kMillisecond);
// Args: links, analytic (0 automatic differentiation, 1 analytic).
BENCHMARK(BM_ExactJacobians)
    ->ArgNames({"links", "analytic"})
    ->ArgsProduct({{10, 100, 1000}, {0, 1}})
    ->Unit(benchmark::kMillisecond);
// Args: links, analytic (0 automatic differentiation, 1 analytic).
BENCHMARK(BM_CompliantJacobians)
    ->ArgNames({"links", "analytic"})
    ->ArgsProduct({{100, 1000}, {0, 1}})
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_VieStep)->Args({10, 0})->Args({100, 1})->Args({1000, 1})->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace stiffsim

BENCHMARK_MAIN();
