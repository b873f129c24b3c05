// Work-precision: the error of every method against a stated reference, and
// the wall time it took, over accuracy targets and fixed steps.

#include <cstdio>
#include <filesystem>
#include <limits>
#include <map>
#include <sstream>

#include "stiffsim/error.h"
#include "stiffsim/integrators/simulator.h"
#include "stiffsim/io/atomic_file.h"
#include "stiffsim/peers/cvode_peer.h"
#include "stiffsim/peers/mujoco_peer.h"
#include "stiffsim/reports/method_run.h"
#include "stiffsim/reports/reports.h"

namespace stiffsim {
namespace {

// The scene of the stiff-cloth goal: a stiff cloth over the window before the
// sheet folds, where first-order errors of 1e-3 and above still mean
// something. Named apart from the 1 s stiff cloth rows.
const char* const kGoalScene = "stiff-cloth 20x20 to 0.25 s";

struct Row {
  std::string scene;
  int dofs = 0;
  MethodRun run;
  double error = 0.0;
};

std::vector<MethodSpec> methods_for(const BenchScene& s, bool quick) {
  std::vector<MethodSpec> m;
  const std::vector<double> accuracies =
      quick ? std::vector<double>{1e-1, 1e-2, 1e-3, 1e-4, 1e-5}
            : std::vector<double>{1e-1, 1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7};
  const std::vector<double> steps = quick ? std::vector<double>{1e-2, 3e-3, 1e-3}
                                          : std::vector<double>{1e-2, 3e-3, 1e-3, 3e-4, 1e-4};
  for (const char* name : {"vie", "vie2", "ie"}) {
    for (double a : accuracies) m.push_back({name, false, a});
  }
  for (const char* name : {"vie", "ie"}) {
    for (double h : steps) m.push_back({name, true, h});
  }
  // The goal counts vie2 in either mode, so it runs at fixed steps there too.
  if (s.name == kGoalScene) {
    for (double h : steps) m.push_back({"vie2", true, h});
  }
  for (double a : quick ? std::vector<double>{1e-3, 1e-5, 1e-7} : std::vector<double>{1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8}) {
    m.push_back({"rk45", false, a});
  }
  if (!quick) {
    for (double a : {1e-3, 1e-5, 1e-7}) m.push_back({"rk3", false, a});
  }
  for (double h : steps) m.push_back({"semi-explicit-euler", true, h});
  for (double r : quick ? std::vector<double>{1e-2, 1e-3, 1e-4, 1e-5, 1e-6}
                        : std::vector<double>{1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8}) {
    m.push_back({"cvode", false, r});
  }
  return m;
}

MethodRun run_any(const BenchScene& s, const MethodSpec& spec, const BenchRunOptions& o) {
  if (spec.method == "cvode") return run_cvode_peer(s, spec, o);
  return run_stiffsim(s, spec, o);
}

// MuJoCo on the chain: the same URDF, joints and step.
MethodRun run_mujoco_chain(const BenchScene& s, const std::string& urdf, const MethodSpec& spec,
                           double angle) {
  MethodRun run;
  run.spec = spec;
  if (!mujoco_available()) {
    run.message = "stiffsim was built without MuJoCo";
    return run;
  }
  const int n = s.scene->dimensions().nq;
  MujocoProblem p;
  p.urdf_path = urdf;
  for (int i = 0; i < n; ++i) p.joints.push_back("joint_" + std::to_string(i + 1));
  p.initial_q.assign(n, angle);
  p.initial_v.assign(n, 0.0);
  p.stiffness.assign(n, 0.0);
  p.rest.assign(n, 0.0);
  p.damping.assign(n, 0.0);
  p.integrator = spec.method == "mujoco-rk4" ? "RK4" : "implicit";
  p.step = spec.parameter;
  p.t_final = s.t_final;
  p.sample_times = sample_times(0.0, s.t_final, s.sample_period);
  try {
    const PeerRun r = run_mujoco(p);
    run.times = r.times;
    run.samples = r.samples;
    run.wall_seconds = r.wall_seconds;
    run.steps = r.steps;
    run.settings = r.settings;
    run.finished = !r.failed;
    run.message = r.message;
  } catch (const std::exception& e) {
    run.message = e.what();
  }
  return run;
}

}  // namespace

int run_precision_report(const ReportOptions& options) {
  namespace fs = std::filesystem;
  create_report_directory(options.out_dir);
  auto say = [&](const std::string& line) {
    if (options.log) *options.log << line << std::endl;
  };
  const bool quick = options.quick;
  std::vector<BenchScene> scenes;
  scenes.push_back(cloth_scene(quick ? 8 : 16, 1e3, quick ? 0.5 : 1.0));
  scenes.push_back(cloth_scene(quick ? 8 : 16, 1e6, quick ? 0.5 : 1.0));
  scenes.push_back(rope_scene(quick ? 20 : 50, 1e5, quick ? 0.5 : 1.0));
  scenes.push_back(chain_scene(10, 0.3, 0.0, quick ? 0.5 : 1.0));
  // Full preset only: its CVODE rows alone (rtol 1e-2 to 1e-6) take minutes,
  // more than the quick preset's whole budget.
  if (!quick) {
    scenes.push_back(cloth_scene(20, 1e6, 0.25));
    scenes.back().name = kGoalScene;
  }
  const double budget = quick ? 10.0 : 60.0;

  std::vector<Row> rows;
  std::ostringstream md;
  md << "# Work-precision\n\nMachine: " << machine_description() << ".\n\n"
     << "Error: the largest position difference from the reference over the samples (every "
     << "0.05 s; metres for particles, radians for joints). Wall time: the integration alone, "
     << "one run each. Methods stopped after " << budget << " s are marked over budget.\n\n";
  for (const BenchScene& s : scenes) {
    say("precision: " + s.name + " (" + std::to_string(s.dofs()) + " DOFs): reference");
    // The reference and its own check: RK45 at 1e-11, against 1e-12.
    BenchRunOptions ro;
    ro.wall_budget_seconds = 600.0;
    const MethodRun reference = run_stiffsim(s, {"rk45", false, 1e-11}, ro);
    const MethodRun check = run_stiffsim(s, {"rk45", false, 1e-12}, ro);
    if (!reference.finished || !check.finished) {
      throw IntegrationError(s.name + ": the RK45 reference did not finish: " + reference.message +
                                 check.message,
                             0.0, 0.0);
    }
    const double uncertainty = max_position_error(*s.scene, reference, check);
    md << "## " << s.name << " (" << s.dofs() << " velocity DOFs, t = 0.." << s.t_final << " s)\n\n"
       << "Reference: RK45 (Dormand-Prince 5(4)) at accuracy 1e-11, which differs from RK45 at "
       << "1e-12 by " << format_number("%.1e", uncertainty) << " (errors below about ten times that are "
       << "not resolved).\n\n";
    BenchRunOptions o;
    o.wall_budget_seconds = budget;
    std::vector<MethodSpec> specs = methods_for(s, quick);
    if (s.kind == "chain" && mujoco_available()) {
      // MuJoCo has no dense output: its steps divide the sample period, so
      // that it lands on every sample time.
      for (double h : quick ? std::vector<double>{1e-2, 5e-3, 1e-3}
                            : std::vector<double>{1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4}) {
        specs.push_back({"mujoco-implicit", true, h});
        specs.push_back({"mujoco-rk4", true, h});
      }
    }
    md << "| method | mode | parameter | error | wall s | steps | Newton it. | factorizations | note |\n"
       << "|---|---|---|---|---|---|---|---|---|\n";
    std::string cvode_settings, mujoco_settings;
    for (const MethodSpec& spec : specs) {
      MethodRun run = spec.method.rfind("mujoco", 0) == 0
                          ? run_mujoco_chain(s, options.models_dir + "/chain_10.urdf", spec, 0.3)
                          : run_any(s, spec, o);
      const double error = run.finished ? max_position_error(*s.scene, run, reference)
                                        : std::numeric_limits<double>::infinity();
      if (spec.method == "cvode" && !run.settings.empty()) cvode_settings = run.settings;
      if (spec.method.rfind("mujoco", 0) == 0 && !run.settings.empty()) mujoco_settings = run.settings;
      say("  " + spec.label() + ": error " + format_number("%.3e", error) + ", " + format_number("%.3f", run.wall_seconds) +
          " s" + (run.finished ? "" : " (" + run.message + ")"));
      std::string note = run.finished ? "" : (run.over_budget ? "over budget" : "failed");
      if (!run.finished && !run.message.empty() && !run.over_budget) {
        note += ": " + run.message.substr(0, 80);
      }
      md << "| " << spec.method << " | " << (spec.fixed ? "fixed h" : "accuracy") << " | "
         << format_number("%.0e", spec.parameter) << " | " << (run.finished ? format_number("%.2e", error) : "-") << " | "
         << format_number("%.3f", run.wall_seconds) << " | " << run.steps << " | " << run.newton_iterations << " | "
         << run.factorizations << " | " << note << " |\n";
      rows.push_back({s.name, s.dofs(), run, error});
    }
    if (!cvode_settings.empty()) md << "\nCVODE: " << cvode_settings << ", atol = rtol x 1e-2.\n";
    if (!mujoco_settings.empty()) md << "\nMuJoCo: " << mujoco_settings << ".\n";
    md << "\n";
  }

  // Goal: on the goal scene, vie or vie2 (either mode) at or below CVODE's
  // curve at errors of 1e-3 and looser: the least wall time reaching each
  // error level, and the run that achieved it.
  md << "## Goal: VIE against CVODE on the stiff cloth\n\n";
  if (quick) {
    md << "The goal scene (" << kGoalScene << ") runs in the full preset only.\n";
  } else {
    md << "On " << kGoalScene << ": the least wall time of any run reaching each error level; "
       << "vie and vie2 in any mode (accuracy or fixed h) against CVODE.\n\n"
       << "| error at most | best of vie, vie2 wall s | by | CVODE best wall s | by | VIE at or below CVODE |\n"
       << "|---|---|---|---|---|---|\n";
    for (double level : {1e-1, 1e-2, 1e-3}) {
      const Row* vie = nullptr;
      const Row* cvode = nullptr;
      for (const Row& r : rows) {
        if (r.scene != kGoalScene || !(r.error <= level)) continue;
        const std::string& m = r.run.spec.method;
        const Row** best = m == "vie" || m == "vie2" ? &vie : m == "cvode" ? &cvode : nullptr;
        if (best && (!*best || r.run.wall_seconds < (*best)->run.wall_seconds)) *best = &r;
      }
      auto seconds = [](const Row* r) {
        return format_number("%.3f", r ? r->run.wall_seconds : std::numeric_limits<double>::infinity());
      };
      auto by = [](const Row* r) { return r ? r->run.spec.label() : std::string("-"); };
      const bool below = vie && (!cvode || vie->run.wall_seconds <= cvode->run.wall_seconds);
      md << "| " << format_number("%.0e", level) << " | " << seconds(vie) << " | " << by(vie) << " | "
         << seconds(cvode) << " | " << by(cvode) << " | " << (below ? "yes" : "no") << " |\n";
    }
  }

  std::ostringstream csv;
  csv << "scene,dofs,method,mode,parameter,error,wall_seconds,steps,newton_iterations,factorizations,finished,message\n";
  for (const Row& r : rows) {
    csv << csv_field(r.scene) << "," << r.dofs << "," << r.run.spec.method << ","
        << (r.run.spec.fixed ? "fixed" : "accuracy") << "," << format_number("%.3e", r.run.spec.parameter) << ","
        << format_number("%.6e", r.error) << "," << format_number("%.6f", r.run.wall_seconds) << "," << r.run.steps << ","
        << r.run.newton_iterations << "," << r.run.factorizations << "," << (r.run.finished ? 1 : 0) << ","
        << csv_field(r.run.message) << "\n";
  }
  // Each file appears whole or not at all, and a failed write is an error.
  write_file_atomically((fs::path(options.out_dir) / "precision.csv").string(), csv.str());
  write_file_atomically((fs::path(options.out_dir) / "precision.md").string(), md.str());
  say("precision: wrote " + (fs::path(options.out_dir) / "precision.csv").string() + " and precision.md");
  return 0;
}

}  // namespace stiffsim
