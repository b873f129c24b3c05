// What coupling a rope to a robot costs: models/arm_rope.yaml (a driven
// 4-joint arm, a 200-node rope tied to its gripper by an attachment)
// against the arm alone plus the rope alone, and against both in one scene
// with the attachment removed and the rope's top node pinned instead.
//
// BM_ArmRopeEvaluation: one evaluation of F and of K and D (what a Newton
// iteration that refreshes its Jacobian pays), at the scene's initial
// state: the attachment's share of the work.
// BM_ArmRopeStep: VIE at the scene's fixed h = 1 ms over its 5 s, time per
// step, with Newton iterations, factorizations and Jacobians per step and
// the split of the time (us per step: Jacobians, assembly, factorization,
// solves, force evaluations). scene: 0 both uncoupled in one scene, 1
// coupled, 2 the arm alone plus the rope alone (two runs, their times and
// counts summed per step). The coupled rope is carried (and whipped) by the
// arm; the uncoupled one hangs still, so the step counts also show what the
// motion costs.
//
//   build/bench/arm_rope_bench --benchmark_repetitions=3 --benchmark_report_aggregates_only=true

#include <benchmark/benchmark.h>
#include <yaml-cpp/yaml.h>

#include <chrono>
#include <memory>
#include <string>
#include <vector>

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

// The arm alone (the rope and the attachment dropped) or the rope alone
// (its top node pinned where the gripper holds it at t = 0).
SceneConfig arm_rope_part(const std::string& part) {
  const std::string path = std::string(STIFFSIM_SOURCE_DIR) + "/models/arm_rope.yaml";
  YAML::Node doc = YAML::LoadFile(path);
  YAML::Node kept(YAML::NodeType::Sequence);
  for (const YAML::Node& c : doc["components"]) {
    if (c["name"].as<std::string>() == part) kept.push_back(c);
  }
  if (part == "rope") kept[0]["pinned"] = YAML::Load("[0]");
  doc["components"] = kept;
  doc.remove("attachments");
  YAML::Emitter text;
  text << doc;
  return parse_scene(text.c_str(), path);
}

constexpr double kFinalTime = 5.0;

void BM_ArmRopeStep(benchmark::State& state) {
  std::vector<SceneConfig> scenes;
  if (state.range(0) == 2) {
    scenes.push_back(arm_rope_part("arm"));
    scenes.push_back(arm_rope_part("rope"));
  } else {
    scenes.push_back(arm_rope(state.range(0) != 0));
  }
  IntegratorStatistics total;
  long steps = 0;
  for (auto _ : state) {
    double seconds = 0.0;
    total = IntegratorStatistics{};
    for (const SceneConfig& config : scenes) {
      auto vie = make_integrator(config.integrator_name, *config.scene, config.integrator,
                                 config.implicit);
      vie->initialize(config.scene->initial_state());
      const auto start = std::chrono::steady_clock::now();
      vie->integrate_to(kFinalTime);
      seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      const IntegratorStatistics& s = vie->statistics();
      steps = s.steps_taken;  // every run takes the same fixed steps
      total.newton_raphson_iterations += s.newton_raphson_iterations;
      total.iteration_matrix_factorizations += s.iteration_matrix_factorizations;
      total.jacobian_evaluations += s.jacobian_evaluations;
      total.jacobian_seconds += s.jacobian_seconds;
      total.assembly_seconds += s.assembly_seconds;
      total.factorization_seconds += s.factorization_seconds;
      total.solve_seconds += s.solve_seconds;
      total.derivative_seconds += s.derivative_seconds;
    }
    state.SetIterationTime(seconds / static_cast<double>(steps));
  }
  const double n = static_cast<double>(steps);
  state.counters["newton_per_step"] = total.newton_raphson_iterations / n;
  state.counters["factorizations_per_step"] = total.iteration_matrix_factorizations / n;
  state.counters["jacobians_per_step"] = total.jacobian_evaluations / n;
  state.counters["jacobian_us"] = 1e6 * total.jacobian_seconds / n;
  state.counters["assembly_us"] = 1e6 * total.assembly_seconds / n;
  state.counters["factorization_us"] = 1e6 * total.factorization_seconds / n;
  state.counters["solve_us"] = 1e6 * total.solve_seconds / n;
  state.counters["forces_us"] = 1e6 * total.derivative_seconds / n;
}
BENCHMARK(BM_ArmRopeStep)
    ->ArgName("scene")
    ->Arg(0)
    ->Arg(1)
    ->Arg(2)
    ->UseManualTime()
    ->Iterations(1)
    ->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace stiffsim

BENCHMARK_MAIN();
