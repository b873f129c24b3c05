// Published robots (tests/data/urdf) beside MuJoCo on the same URDF and the
// same fixed step: the simple humanoid (29 revolute joints) with its root
// welded and on a floating base, and the ANYmal B quadruped (12 joints) on a
// floating base. No contacts; gravity; a joint spring of 100 N m/rad and a
// damper of 1 N m s/rad on every joint; every joint bent (0.3 sin(1.7 i +
// 0.5) rad), everything at rest at t = 0; one run of 1 s per iteration.
//
// Time: the wall time of the integration loop per step (setup and model
// loading are left out on both sides), for stiffsim VIE with `recursive`
// (the articulated-body recursion) and with `chord` (the assembled dense
// Newton matrix and the reuse ladder: `auto`'s choice on trees of fewer
// than 250 velocities, these among them), and for MuJoCo's `implicit` integrator (velocity-implicit in
// damping and Coriolis terms, joint springs explicit; one linear solve per
// step). MuJoCo's `Euler` (semi-implicit, damping implicit) is timed beside
// it: MuJoCo 2.2's implicit step forms a dense nv x nv velocity derivative.
//
// Counters, at t = 1 s (angles in rad: every joint and the base's rotation;
// lengths in m: the base's position):
//   err_rad, err_m  distance from a reference (stiffsim RK45 at accuracy
//                   1e-10; MuJoCo RK4 agrees with it to 1e-7 on these
//                   robots, tests/peers/mujoco_peer_test.cc);
//   mj_rad, mj_m    distance between this VIE run and MuJoCo implicit at the
//                   same h (both first order: O(h));
//   newton_per_step, recursive_per_step (articulated-body factorizations),
//   factorizations_per_step (assembled matrices).
// MuJoCo rows are skipped with a message when it is not built in, or when
// it fails (its bad-acceleration warning).
//
//   build/bench/robot_peer_bench --benchmark_repetitions=45
//     --benchmark_enable_random_interleaving=true
//     --benchmark_report_aggregates_only=true
// (random order, so that load from other jobs on the machine spreads over
// every row rather than falling on a few).

#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iterator>
#include <map>
#include <memory>
#include <string>
#include <utility>

#include "stiffsim/integrators/runge_kutta45.h"
#include "stiffsim/integrators/velocity_implicit_euler.h"
#include "stiffsim/model/articulated.h"
#include "stiffsim/model/urdf.h"
#include "stiffsim/peers/mujoco_peer.h"

namespace stiffsim {
namespace {

const std::string kRobots = std::string(STIFFSIM_SOURCE_DIR) + "/tests/data/urdf/";
constexpr double kFinalTime = 1.0;

struct RobotCase {
  const char* name;
  const char* file;
  bool floating_base;
};

const RobotCase kCases[] = {
    {"humanoid_welded", "simple_humanoid.urdf", false},
    {"humanoid_floating", "simple_humanoid.urdf", true},
    {"anymal_floating", "anymal_b.urdf", true},
};

std::unique_ptr<ArticulatedSystem> robot_system(const RobotCase& robot) {
  UrdfOptions urdf;
  urdf.floating_base = robot.floating_base;
  const RigidTree tree = load_urdf(kRobots + robot.file, urdf, nullptr);
  ArticulatedOptions options;
  options.joint_forces.resize(tree.bodies.size());
  int joints = 0;
  for (size_t b = 0; b < tree.bodies.size(); ++b) {
    if (joint_nv(tree.bodies[b].type) != 1) continue;
    options.joint_forces[b] = JointForce{100.0, 0.0, 1.0};
    ++joints;
  }
  const int base_q = robot.floating_base ? 7 : 0, base_v = robot.floating_base ? 6 : 0;
  options.initial_q = Eigen::VectorXd::Zero(base_q + joints);
  options.initial_v = Eigen::VectorXd::Zero(base_v + joints);
  if (robot.floating_base) options.initial_q[3] = 1.0;  // identity quaternion
  for (int i = 0; i < joints; ++i) options.initial_q[base_q + i] = 0.3 * std::sin(1.7 * i + 0.5);
  return std::make_unique<ArticulatedSystem>(tree, options);
}

// The largest angle (rad: joint angles and the base's rotation) and length
// (m: the base's position) between two states of `sys`.
std::pair<double, double> distance(const ArticulatedSystem& sys, const Eigen::VectorXd& a,
                                   const Eigen::VectorXd& b) {
  double angle = 0.0, length = 0.0;
  for (int i = 0; i < sys.model().bodies(); ++i) {
    const int qo = sys.body_q_offset(i);
    if (sys.tree().bodies[i].type == JointType::kFloating) {
      length = std::max(length, (a.segment<3>(qo) - b.segment<3>(qo)).norm());
      // The rotation between the two orientations; |dot| as q and -q are one.
      const double dot = std::abs(a.segment<4>(qo + 3).dot(b.segment<4>(qo + 3)));
      angle = std::max(angle, 2.0 * std::acos(std::min(1.0, dot)));
    } else {
      angle = std::max(angle, std::abs(a[qo] - b[qo]));
    }
  }
  return {angle, length};
}

// The reference state at kFinalTime, once per robot.
const Eigen::VectorXd& reference(int robot, const ArticulatedSystem& sys) {
  static std::map<int, Eigen::VectorXd> cache;
  auto it = cache.find(robot);
  if (it != cache.end()) return it->second;
  IntegratorSettings settings;
  settings.accuracy = 1e-10;
  RungeKutta45 rk(sys, settings);
  rk.initialize(sys.initial_state());
  rk.integrate_to(kFinalTime);
  return cache[robot] = rk.state().x;
}

MujocoProblem mujoco_run(const RobotCase& robot, const ArticulatedSystem& sys, double h,
                         const std::string& integrator) {
  MujocoProblem problem = mujoco_problem(sys, kRobots + robot.file);
  problem.integrator = integrator;
  problem.step = h;
  problem.t_final = kFinalTime;
  problem.sample_times = {kFinalTime};
  return problem;
}

// MuJoCo implicit's state at kFinalTime, once per robot and step; empty when
// MuJoCo is absent or failed.
const Eigen::VectorXd& mujoco_final(int robot, const ArticulatedSystem& sys, double h) {
  static std::map<std::pair<int, double>, Eigen::VectorXd> cache;
  const auto key = std::make_pair(robot, h);
  auto it = cache.find(key);
  if (it != cache.end()) return it->second;
  Eigen::VectorXd x;
  if (mujoco_available()) {
    const PeerRun run = run_mujoco(mujoco_run(kCases[robot], sys, h, "implicit"));
    if (!run.failed && run.samples.size() == 1) x = run.samples.back();
  }
  return cache[key] = x;
}

void set_errors(benchmark::State& state, const ArticulatedSystem& sys, int robot,
                const Eigen::VectorXd& x) {
  const auto [angle, length] = distance(sys, x, reference(robot, sys));
  state.counters["err_rad"] = angle;
  if (sys.tree().bodies[0].type == JointType::kFloating) state.counters["err_m"] = length;
}

void BM_VieRobot(benchmark::State& state, int robot, double h, NewtonSolve solve) {
  const auto sys = robot_system(kCases[robot]);
  IntegratorSettings settings;
  settings.fixed_step = true;
  settings.max_step = h;
  ImplicitSettings implicit;
  implicit.newton_solve = solve;
  Eigen::VectorXd x;
  IntegratorStatistics stats;
  std::string path;
  for (auto _ : state) {
    VelocityImplicitEuler vie(*sys, settings, implicit);
    vie.initialize(sys->initial_state());
    const auto start = std::chrono::steady_clock::now();
    vie.integrate_to(kFinalTime);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    stats = vie.statistics();
    state.SetIterationTime(seconds / static_cast<double>(stats.steps_taken));
    x = vie.state().x;
    path = vie.report().newton_solve;
  }
  const double steps = static_cast<double>(stats.steps_taken);
  state.SetLabel(path);
  state.counters["newton_per_step"] = stats.newton_raphson_iterations / steps;
  state.counters["recursive_per_step"] = stats.recursive_factorizations / steps;
  state.counters["factorizations_per_step"] = stats.iteration_matrix_factorizations / steps;
  set_errors(state, *sys, robot, x);
  const Eigen::VectorXd& peer = mujoco_final(robot, *sys, h);
  if (peer.size() == x.size()) {
    const auto [angle, length] = distance(*sys, x, peer);
    state.counters["mj_rad"] = angle;
    if (kCases[robot].floating_base) state.counters["mj_m"] = length;
  }
}

void BM_MujocoRobot(benchmark::State& state, int robot, double h, const std::string& integrator) {
  if (!mujoco_available()) {
    state.SkipWithError("stiffsim was built without MuJoCo");
    return;
  }
  const auto sys = robot_system(kCases[robot]);
  const MujocoProblem problem = mujoco_run(kCases[robot], *sys, h, integrator);
  Eigen::VectorXd x;
  std::string label;
  for (auto _ : state) {
    const PeerRun run = run_mujoco(problem);
    if (run.failed || run.samples.size() != 1) {
      state.SkipWithError(("MuJoCo failed: " + run.message).c_str());
      return;
    }
    state.SetIterationTime(run.wall_seconds / static_cast<double>(run.steps));
    x = run.samples.back();
    label = run.method;
  }
  state.SetLabel(label);
  set_errors(state, *sys, robot, x);
}

void register_benchmarks() {
  for (int robot = 0; robot < static_cast<int>(std::size(kCases)); ++robot) {
    for (double h : {1e-3, 1e-2}) {
      const std::string name = std::string("RobotStep/") + kCases[robot].name +
                               "/h=" + (h == 1e-3 ? "1ms" : "10ms") + "/";
      // One iteration is one run of 1 s (1000 or 100 steps); the reported
      // time is per step, so the iteration count is fixed rather than
      // grown to a minimum time of steps.
      for (auto [solver, solve] : {std::make_pair("vie-recursive", NewtonSolve::kRecursive),
                                   std::make_pair("vie-chord", NewtonSolve::kChord)}) {
        benchmark::RegisterBenchmark((name + solver).c_str(), BM_VieRobot, robot, h, solve)
            ->UseManualTime()
            ->Iterations(1)
            ->Unit(benchmark::kMicrosecond);
      }
      for (const char* integrator : {"implicit", "euler"}) {
        benchmark::RegisterBenchmark((name + "mujoco-" + integrator).c_str(), BM_MujocoRobot, robot,
                                     h, std::string(integrator))
            ->UseManualTime()
            ->Iterations(1)
            ->Unit(benchmark::kMicrosecond);
      }
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
