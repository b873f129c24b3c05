// What coupling a rope to a robot costs: models/arm_rope.yaml (a driven
// 4-joint arm, a 200-node rope tied to its gripper by an attachment)
// against the same scene with the attachment removed and the rope's top
// node pinned instead (the arm and the rope side by side, uncoupled).
//
// BM_ArmRopeEvaluation: one evaluation of F and of K and D (what a Newton
// iteration that refreshes its Jacobian pays), at the scene's initial
// state: the attachment's share of the work.
// BM_ArmRopeStep: VIE at the scene's fixed h = 1 ms over its first 0.5 s,
// time per step, with Newton iterations and factorizations per step. The
// coupled rope is carried (and whipped) by the arm; the uncoupled one
// hangs still, so the step counts also show what the motion costs.
//
//   build/bench/arm_rope_bench --benchmark_repetitions=5 --benchmark_report_aggregates_only=true

#include <benchmark/benchmark.h>

#include <chrono>
#include <string>

#include "stiffsim/integrators/integrator_factory.h"
#include "stiffsim/io/scene_yaml.h"
#include "stiffsim/scene.h"

namespace stiffsim {
namespace {

SceneConfig arm_rope(bool coupled) {
  std::vector<std::string> overrides;
  if (!coupled) overrides = {"attachments=[]", "rope.pinned=[0]"};
  return load_scene(std::string(STIFFSIM_SOURCE_DIR) + "/models/arm_rope.yaml", overrides);
}

void BM_ArmRopeEvaluation(benchmark::State& state) {
  const SceneConfig config = arm_rope(state.range(0) != 0);
  const Scene& s = *config.scene;
  const Dimensions d = s.dimensions();
  const State x = s.initial_state();
  const Eigen::VectorXd q = x.x.head(d.nq), v = x.x.segment(d.nq, d.nv), z;
  Eigen::VectorXd F(d.nv);
  ForceJacobians J = s.jacobian_pattern();
  const std::unique_ptr<SystemData> data = s.make_data();
  for (auto _ : state) {
    s.forces(*data, 0.1, q, v, z, F);
    s.force_jacobians(*data, 0.1, q, v, z, JacobianRequest{}, &J);
    benchmark::DoNotOptimize(F.data());
    benchmark::DoNotOptimize(J.dF_dq.valuePtr());
  }
}
BENCHMARK(BM_ArmRopeEvaluation)->ArgName("coupled")->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

void BM_ArmRopeStep(benchmark::State& state) {
  const SceneConfig config = arm_rope(state.range(0) != 0);
  IntegratorStatistics stats;
  for (auto _ : state) {
    auto vie =
        make_integrator(config.integrator_name, *config.scene, config.integrator, config.implicit);
    vie->initialize(config.scene->initial_state());
    const auto start = std::chrono::steady_clock::now();
    vie->integrate_to(0.5);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    stats = vie->statistics();
    state.SetIterationTime(seconds / static_cast<double>(stats.steps_taken));
  }
  const double steps = static_cast<double>(stats.steps_taken);
  state.counters["newton_per_step"] = stats.newton_raphson_iterations / steps;
  state.counters["factorizations_per_step"] = stats.iteration_matrix_factorizations / steps;
  state.counters["jacobians_per_step"] = stats.jacobian_evaluations / steps;
}
BENCHMARK(BM_ArmRopeStep)
    ->ArgName("coupled")
    ->Arg(0)
    ->Arg(1)
    ->UseManualTime()
    ->Iterations(1)
    ->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace stiffsim

BENCHMARK_MAIN();
