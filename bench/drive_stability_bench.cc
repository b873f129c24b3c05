// Stiff PD drives at a large step: the largest position gain kp (decades
// 1e1 .. 1e9) at which a driven robot holds its target at h = 5 ms, for
// stiffsim VIE (the drive's kp and kd in the Newton matrix) and MuJoCo's
// `implicit` integrator (a position servo's kp is explicit there; its kd
// acts as joint damping, which is implicit).
//
// Robots: chain_10 and the simple humanoid (tests/data/urdf, 29 revolute
// joints, root welded), under gravity, no contacts. Every joint is driven to
// the angle it starts at (0.3 sin(1.7 i + 0.5) rad), with kd = 2 sqrt(kp)
// 1e-2 N m s/rad (a tenth of critical damping on a link of 1e-4 kg m^2,
// a small share on the heavier links), at rest at t = 0; 1 s per run.
// A run holds when its state stays finite, its energy (kinetic, gravity
// and the drives' springs about their targets, evaluated in stiffsim's
// model for both simulators) never rises above its start by more than
// 1e-6 of its scale, and every joint ends within 0.05 rad of its target.
//
// Counters: largest_kp_held (0: none held), and the step time at kp = 1e5
// (us_per_step_kp1e5) where it held.
//
//   build/bench/drive_stability_bench

#include <benchmark/benchmark.h>

#include <chrono>
#include <cmath>
#include <memory>
#include <string>

#include "stiffsim/error.h"
#include "stiffsim/integrators/simulator.h"  // sample_times
#include "stiffsim/integrators/velocity_implicit_euler.h"
#include "stiffsim/model/articulated.h"
#include "stiffsim/model/urdf.h"
#include "stiffsim/peers/mujoco_peer.h"

namespace stiffsim {
namespace {

constexpr double kStep = 5e-3, kFinalTime = 1.0;

struct Robot {
  const char* name;
  std::string urdf;
};

const Robot kRobots[] = {
    {"chain_10", std::string(STIFFSIM_SOURCE_DIR) + "/models/chain_10.urdf"},
    {"humanoid_welded", std::string(STIFFSIM_SOURCE_DIR) + "/tests/data/urdf/simple_humanoid.urdf"},
};

std::unique_ptr<ArticulatedSystem> driven(const Robot& robot, double kp) {
  const RigidTree tree = load_urdf(robot.urdf, UrdfOptions{}, nullptr);
  ArticulatedOptions o;
  const int n = static_cast<int>(tree.bodies.size());
  o.initial_q = Eigen::VectorXd::Zero(n);
  for (int i = 0; i < n; ++i) {
    o.initial_q[i] = 0.3 * std::sin(1.7 * i + 0.5);
    o.drives.push_back(
        JointDrive{i, kp, 2e-2 * std::sqrt(kp), ScalarPath::constant(o.initial_q[i])});
  }
  return std::make_unique<ArticulatedSystem>(tree, o);
}

// Whether the states (at every step) held: finite, no energy rise, on target.
bool held(const ArticulatedSystem& sys, const std::vector<double>& times,
          const std::vector<Eigen::VectorXd>& states) {
  const State start = sys.initial_state();
  const std::unique_ptr<SystemData> data = sys.make_data();
  const double e0 = sys.energy(*data, start);
  double scale = std::abs(e0);
  for (size_t k = 0; k < states.size(); ++k) {
    if (!states[k].allFinite()) return false;
    const double e = sys.energy(*data, State(times[k], states[k]));
    scale = std::max(scale, std::abs(e));
    if (e > e0 + 1e-6 * std::max(scale, 1e-12)) return false;
  }
  if (states.empty() || times.back() < kFinalTime - 1e-9) return false;
  const Eigen::VectorXd& end = states.back();
  for (const JointDrive& d : sys.options().drives) {
    if (std::abs(end[d.body] - d.target.value(times.back())) > 0.05) return false;
  }
  return true;
}

// Runs one kp; returns whether it held and the wall time per step.
std::pair<bool, double> run_vie(const Robot& robot, double kp) {
  const auto sys = driven(robot, kp);
  IntegratorSettings settings;
  settings.fixed_step = true;
  settings.max_step = kStep;
  VelocityImplicitEuler vie(*sys, settings, ImplicitSettings{});
  vie.initialize(sys->initial_state());
  // Every step's end, as MuJoCo's run below samples; only the steps are
  // timed (this is the one loop not driven by simulate(), whose wall time
  // also holds the set-up and the samples' handling).
  std::vector<double> times;
  std::vector<Eigen::VectorXd> states;
  double seconds = 0.0;
  try {
    while (vie.state().t < kFinalTime - 1e-12) {
      const auto start = std::chrono::steady_clock::now();
      vie.step_at_most(kFinalTime);
      seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      times.push_back(vie.state().t);
      states.push_back(vie.state().x);
    }
  } catch (const IntegrationError&) {
    return {false, 0.0};
  }
  return {held(*sys, times, states), seconds / static_cast<double>(times.size())};
}

std::pair<bool, double> run_mujoco_implicit(const Robot& robot, double kp) {
  const auto sys = driven(robot, kp);
  MujocoProblem p = mujoco_problem(*sys, robot.urdf);
  p.integrator = "implicit";
  p.step = kStep;
  p.t_final = kFinalTime;
  p.sample_times = sample_times(0.0, kFinalTime, kStep);
  const PeerRun run = run_mujoco(p);
  if (run.failed) return {false, 0.0};
  return {held(*sys, run.times, run.samples), run.wall_seconds / static_cast<double>(run.steps)};
}

void BM_DriveStability(benchmark::State& state, int robot, bool mujoco) {
  if (mujoco && !mujoco_available()) {
    state.SkipWithError("stiffsim was built without MuJoCo");
    return;
  }
  double largest = 0.0, at_1e5 = 0.0;
  for (auto _ : state) {
    for (double kp = 1e1; kp <= 1e9 * 1.01; kp *= 10.0) {
      const auto [ok, per_step] =
          mujoco ? run_mujoco_implicit(kRobots[robot], kp) : run_vie(kRobots[robot], kp);
      if (ok) largest = kp;
      if (ok && std::abs(kp - 1e5) < 1.0) at_1e5 = per_step;
    }
  }
  state.counters["largest_kp_held"] = largest;
  if (at_1e5 > 0.0) state.counters["us_per_step_kp1e5"] = at_1e5 * 1e6;
}

void register_benchmarks() {
  for (int robot = 0; robot < 2; ++robot) {
    for (bool mujoco : {false, true}) {
      const std::string name = std::string("DriveStability/") + kRobots[robot].name + "/" +
                               (mujoco ? "mujoco-implicit" : "vie");
      benchmark::RegisterBenchmark(name.c_str(), BM_DriveStability, robot, mujoco)
          ->Iterations(1)
          ->Unit(benchmark::kMillisecond);
    }
  }
}

}  // namespace
}  // namespace stiffsim

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  stiffsim::register_benchmarks();
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
