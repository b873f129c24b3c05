// What one VIE step of a cloth costs against one sparse factorization and one
// solve of its iteration matrix: with reuse a step should cost a few solves,
// not a factorization.
//
//   build/bench/cloth_step_bench --benchmark_repetitions=5
//     --benchmark_report_aggregates_only=true

#include <benchmark/benchmark.h>

#include "stiffsim/integrators/velocity_implicit_euler.h"
#include "stiffsim/linalg/linear_solver.h"
#include "stiffsim/model/particle_meshes.h"
#include "stiffsim/model/particles.h"

namespace stiffsim {
namespace {

constexpr double kStep = 1.0 / 60;

ParticleSystem make_scene(int n) {
  ClothSpec spec;
  spec.nx = spec.ny = n;
  spec.total_mass = 0.4;
  spec.stretch = SpringParameters{1e3, 0.5};
  spec.shear = SpringParameters{1e2, 0.1};
  spec.bend = SpringParameters{10.0, 0.05};
  return ParticleSystem(make_cloth(spec));
}

// The iteration matrix W = M - h D - h^2 K at the initial state.
SparseMatrix iteration_matrix(const ParticleSystem& sys) {
  const State s = sys.initial_state();
  const Dimensions d = sys.dimensions();
  SparseMatrix M = sys.mass_matrix_pattern();
  sys.mass_matrix(s.q(d), &M);
  ForceJacobians J = sys.jacobian_pattern();
  sys.force_jacobians(0.0, s.q(d), s.v(d), s.z(d), JacobianRequest{true}, &J);
  SparseMatrix W = M - kStep * J.dF_dv - kStep * kStep * J.dF_dq;
  W.makeCompressed();
  return W;
}

void BM_Factorize(benchmark::State& state) {
  const ParticleSystem sys = make_scene(state.range(0));
  const SparseMatrix W = iteration_matrix(sys);
  auto choice = make_linear_solver(LinearSolverKind::kAuto, W, true);
  choice.solver->analyze(W);
  for (auto _ : state) benchmark::DoNotOptimize(choice.solver->factorize(W));
  state.counters["dofs"] = W.rows();
  state.SetLabel(choice.solver->method());
}

// The same factorization as a preconditioner's (factorize_preconditioner:
// single precision where the factor is supernodal).
void BM_FactorizePreconditioner(benchmark::State& state) {
  const ParticleSystem sys = make_scene(state.range(0));
  const SparseMatrix W = iteration_matrix(sys);
  auto choice = make_linear_solver(LinearSolverKind::kAuto, W, true);
  choice.solver->analyze(W);
  for (auto _ : state) {
    benchmark::DoNotOptimize(choice.solver->factorize_preconditioner(W, false));
  }
  state.counters["dofs"] = W.rows();
  state.counters["single"] =
      static_cast<double>(choice.solver->counters().single_precision_factorizations);
}

// One solve with a factorization of W: in double (BM_Solve) or as GMRES's
// preconditioner (BM_SolvePreconditioner: single precision where the
// factor is supernodal), with the latter's relative distance from the
// double solve.
void solve_with_factor(benchmark::State& state, bool preconditioner) {
  const ParticleSystem sys = make_scene(state.range(0));
  const SparseMatrix W = iteration_matrix(sys);
  auto choice = make_linear_solver(LinearSolverKind::kAuto, W, true);
  choice.solver->analyze(W);
  choice.solver->factorize(W);
  Eigen::VectorXd b = Eigen::VectorXd::Ones(W.rows()), x(W.rows()), x_double(W.rows());
  choice.solver->solve(b, &x_double);
  for (auto _ : state) {
    if (preconditioner) {
      choice.solver->solve_preconditioner(b, &x);
    } else {
      choice.solver->solve(b, &x);
    }
  }
  state.counters["dofs"] = W.rows();
  if (preconditioner) state.counters["rel_diff"] = (x - x_double).norm() / x_double.norm();
}

void BM_Solve(benchmark::State& state) { solve_with_factor(state, false); }
void BM_SolvePreconditioner(benchmark::State& state) { solve_with_factor(state, true); }

// One evaluation of the force Jacobians K and D (the iteration matrix's
// definite request, as full Newton asks for it) on a cloth lying in its rest
// plane with every spring slightly stretched, so no branch is skipped.
void BM_ForceJacobians(benchmark::State& state) {
  const ParticleSystem sys = make_scene(state.range(0));
  State s = sys.initial_state();
  const Dimensions d = sys.dimensions();
  s.x.segment(0, d.nq) *= 1.001;
  s.x.segment(d.nq, d.nv).setConstant(0.1);
  ForceJacobians J = sys.jacobian_pattern();
  JacobianRequest request;
  request.definite = true;
  for (auto _ : state) {
    sys.force_jacobians(0.0, s.q(d), s.v(d), s.z(d), request, &J);
    benchmark::DoNotOptimize(J.dF_dq.valuePtr());
  }
  state.counters["springs/s"] =
      benchmark::Counter(static_cast<double>(sys.description().springs.size()),
                         benchmark::Counter::kIsIterationInvariantRate);
}

// Fixed-step VIE (1 Newton solve per step, or 3 with the estimate) during
// the cloth's fall, after a warm-up of 0.1 s so the reuse ladder has a
// factorization to reuse.
void BM_VieStep(benchmark::State& state) {
  const ParticleSystem sys = make_scene(state.range(0));
  IntegratorSettings settings;
  settings.fixed_step = true;
  settings.max_step = kStep;
  settings.error_estimate = state.range(1) != 0;
  settings.accuracy = 1e-3;
  VelocityImplicitEuler vie(sys, settings, ImplicitSettings{});
  vie.initialize(sys.initial_state());
  vie.integrate_to(0.1);
  const IntegratorStatistics before = vie.statistics();
  double t = vie.state().t;
  for (auto _ : state) {
    t += kStep;
    vie.step_at_most(t);
  }
  const IntegratorStatistics& after = vie.statistics();
  const double steps = after.steps_taken - before.steps_taken;
  state.counters["dofs"] = sys.dimensions().nv;
  state.counters["newton_its/step"] =
      (after.newton_raphson_iterations - before.newton_raphson_iterations) / steps;
  state.counters["factorizations/step"] =
      (after.iteration_matrix_factorizations - before.iteration_matrix_factorizations) / steps;
}

BENCHMARK(BM_Factorize)->Arg(32)->Arg(100)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_FactorizePreconditioner)->Arg(32)->Arg(100)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Solve)->Arg(32)->Arg(100)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_SolvePreconditioner)->Arg(32)->Arg(100)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ForceJacobians)->Arg(32)->Arg(100)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_VieStep)->Args({32, 0})->Args({32, 1})->Unit(benchmark::kMillisecond);
BENCHMARK(BM_VieStep)->Args({100, 0})->Iterations(12)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace stiffsim

int main(int argc, char** argv) {
  // No set_blas_threads call: the first sparse solver applies the default of
  // one thread (OpenBLAS and CHOLMOD's OpenMP regions), as in every entry
  // point; see linalg/blas_threads.h.
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
