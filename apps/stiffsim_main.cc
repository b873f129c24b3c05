// The stiffsim command line: parse, load, run, write (DESIGN.md section 8).
// Everything substantial lives in the libraries; this file only wires them
// together and turns failures into messages and exit codes.

#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <iostream>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "stiffsim/error.h"
#include "stiffsim/integrators/integrator_factory.h"
#include "stiffsim/io/scene_run.h"
#include "stiffsim/io/scene_yaml.h"
#include "stiffsim/linalg/blas_threads.h"
#include "stiffsim/reports/reports.h"

namespace stiffsim {
namespace {

constexpr int kUsageExitCode = 2;  // same as InputError: the user's input is wrong

// SIGINT or SIGTERM during a run: the run stops after the step in progress
// and finishes its files as a failed run does (complete rows, marked as
// stopped early), exiting with 128 + the signal as shells expect.
volatile std::sig_atomic_t g_stop_signal = 0;
extern "C" void request_stop(int signal) { g_stop_signal = signal; }

std::string join(const std::vector<std::string>& items, const std::string& separator) {
  std::string out;
  for (size_t i = 0; i < items.size(); ++i) out += (i > 0 ? separator : "") + items[i];
  return out;
}

// CLI11 accepts "inf" and "nan" as doubles; none of our options means them.
CLI::Validator number_check(const std::string& name, bool allow_zero, bool at_most_one) {
  return CLI::Validator(
      [=](std::string& text) -> std::string {
        double value = 0.0;
        if (!CLI::detail::lexical_cast(text, value) || !std::isfinite(value)) {
          return "expected a finite number, got '" + text + "'";
        }
        if (value < 0.0 || (!allow_zero && value == 0.0)) {
          return std::string("expected a ") + (allow_zero ? "non-negative" : "positive") +
                 " number, got " + text;
        }
        if (at_most_one && value > 1.0) return "expected a number in (0, 1], got " + text;
        return std::string();
      },
      name);
}

struct RunOptions {
  std::string scene;
  std::string integrator;
  double t_final = 0.0, step = 0.0, accuracy = 0.0, sample_period = 0.0;
  bool fixed_step = false, error_estimate = false;
  std::string jacobian, linear_solver, newton_form, error_estimator, newton_solve, newton_tolerance,
      preconditioner_precision;
  bool full_newton = false, no_reuse = false, verify_roots = false;
  std::string output, stats, vtk;
  std::vector<std::string> sets;
  bool quiet = false, summary = false;
  int blas_threads = 1;
  // Options that override the scene only when given.
  CLI::Option *integrator_option = nullptr, *t_final_option = nullptr, *step_option = nullptr,
              *accuracy_option = nullptr, *sample_period_option = nullptr,
              *fixed_step_option = nullptr, *error_estimate_option = nullptr,
              *jacobian_option = nullptr, *linear_solver_option = nullptr,
              *newton_form_option = nullptr, *error_estimator_option = nullptr,
              *newton_solve_option = nullptr, *newton_tolerance_option = nullptr,
              *preconditioner_precision_option = nullptr;
};

void add_run_options(CLI::App* run, RunOptions* o) {
  run->add_option(
         "SCENE", o->scene,
         "Scene file: YAML with cloth, rope, mesh and URDF components (DESIGN.md section 9), "
         "or a bare .urdf file (one exact articulated body named after the file)")
      ->required();
  run->add_option("--set", o->sets,
                  "Override a scene value, PATH=VALUE with VALUE in YAML (repeatable): "
                  "cloth.stretch.k=1e6, cloth.nodes=[64,64], simulation.accuracy=1e-5, "
                  "gravity=[0,0,-1]")
      // One value per --set, so that `--set a=1 scene.yaml` does not take the
      // scene file for a second override.
      ->allow_extra_args(false)
      ->group("Scene");

  const std::string simulation = "Simulation (each overrides the scene's simulation block)";
  o->integrator_option = run->add_option("--integrator", o->integrator,
                                         "Integration method: vie (velocity-implicit Euler, "
                                         "default), vie2 (vie extrapolated, second order), ie "
                                         "(full-state implicit Euler), ie2 (ie extrapolated), "
                                         "semi-explicit-euler (fixed step), rk3, rk45")
                             ->check(CLI::IsMember(integrator_names()))
                             ->group(simulation);
  o->t_final_option = run->add_option("--t-final", o->t_final, "End time of the run, s")
                          ->check(number_check("POSITIVE", false, false))
                          ->group(simulation);
  o->step_option = run->add_option("--step", o->step,
                                   "Step size, s: the maximum (and initial) step, or the "
                                   "step itself with --fixed-step")
                       ->check(number_check("POSITIVE", false, false))
                       ->group(simulation);
  o->fixed_step_option =
      run->add_flag("--fixed-step,!--no-fixed-step", o->fixed_step,
                    "Take fixed steps of --step (no error control), or force error control")
          ->group(simulation);
  o->error_estimate_option =
      run->add_flag("--error-estimate,!--no-error-estimate", o->error_estimate,
                    "With --fixed-step: also compute the error estimate (VIE: two half steps) "
                    "and report it; error-controlled runs always estimate")
          ->group(simulation);
  o->accuracy_option =
      run->add_option("--accuracy", o->accuracy,
                      "Target accuracy: weighted infinity norm of the local error, in (0, 1]")
          ->check(number_check("(0,1]", false, true))
          ->group(simulation);
  o->sample_period_option =
      run->add_option("--sample-period", o->sample_period,
                      "Time between samples (CSV rows, VTK frames), s; 0: one per step")
          ->check(number_check("NON-NEGATIVE", true, false))
          ->group(simulation);

  const std::string newton = "Implicit integrators (override the scene)";
  o->jacobian_option = run->add_option("--jacobian", o->jacobian,
                                       "Force Jacobians of the implicit methods: analytic "
                                       "(default), forward or central (coloured finite "
                                       "differences), automatic (forward-mode AD per element)")
                           ->check(CLI::IsMember(jacobian_scheme_names()))
                           ->group(newton);
  o->linear_solver_option =
      run->add_option("--linear-solver", o->linear_solver,
                      "Newton linear solver: " + join(linear_solver_names(), ", ") +
                          " (auto picks by size, density and symmetry; the stats say why)")
          ->check(CLI::IsMember(linear_solver_names()))
          ->group(newton);
  o->newton_form_option =
      run->add_option("--newton-form", o->newton_form,
                      "Newton matrix: mass-matrix (W = M - hD - h^2 K N, sparse and symmetric) "
                      "or generic (Drake's I - h J)")
          ->check(CLI::IsMember(newton_form_names()))
          ->group(newton);
  o->error_estimator_option =
      run->add_option("--error-estimator", o->error_estimator,
                      "How ie estimates its local error: trapezoid (the implicit trapezoid rule "
                      "from the IE result, IE propagated; default) or doubling (two half steps "
                      "propagated, as vie does)")
          ->check(CLI::IsMember(error_estimator_names()))
          ->group(newton);
  o->newton_solve_option =
      run->add_option("--newton-solve", o->newton_solve,
                      "How Newton iterations solve: auto (default: where the iteration "
                      "matrix is sparse, each solve starts with the chord, krylov or, at "
                      "fixed steps where Krylov solves take many iterations, fresh, whichever "
                      "cost less lately; chord otherwise), krylov (GMRES on the exact Jacobian, "
                      "applied matrix-free, preconditioned by the last factorization, "
                      "refactored by measured cost), chord (the last "
                      "factorization as the Newton matrix, the reuse ladder), fresh (a new "
                      "Jacobian and factorization every iteration, a line search on the "
                      "incremental potential and, at fixed steps, the springs' tensions "
                      "estimated along the Newton path) or recursive (exact "
                      "articulated trees: the articulated-body recursion, O(n) per iteration; "
                      "auto's choice for VIE on trees of 250 or more joint velocities)")
          ->check(CLI::IsMember(newton_solve_names()))
          ->group(newton);
  o->newton_tolerance_option =
      run->add_option("--newton-tolerance", o->newton_tolerance,
                      "What sets the Newton tolerance of VIE's fixed steps without "
                      "--error-estimate: step-error (default: 0.1 times the step's own local "
                      "error, counted up to 100 times the accuracy, where it exceeds the "
                      "accuracy; 0.05 times the accuracy otherwise) or accuracy (0.05 times the "
                      "accuracy, as under error control)")
          ->check(CLI::IsMember(newton_tolerance_names()))
          ->group(newton);
  o->preconditioner_precision_option =
      run->add_option("--preconditioner-precision", o->preconditioner_precision,
                      "GMRES's preconditioner solves: single (default: a float copy of a "
                      "supernodal factor, where its first solve after each factorization "
                      "misses the matrix by at most 1e-3; double otherwise; full Newton's "
                      "factor without the covered couplings is made in float) or double")
          ->check(CLI::IsMember(preconditioner_precision_names()))
          ->group(newton);
  run->add_flag("--full-newton", o->full_newton,
                "Fresh Jacobian and factorization at every Newton iteration")
      ->group(newton);
  run->add_flag("--no-reuse", o->no_reuse,
                "Fresh Jacobian and factorization at every step attempt (no reuse ladder)")
      ->group(newton);
  run->add_flag("--verify-roots", o->verify_roots,
                "Diagnostic: run Newton on from every accepted iterate to the root and report "
                "the largest distance, in Newton tolerances, in the stats "
                "(largest_root_distance_ratio); the run is otherwise unchanged but slower")
      ->group(newton);

  const std::string outputs = "Output (files appear only when complete)";
  run->add_option("-o,--output", o->output,
                  "Trajectory CSV: t, q:<name>..., v:<name>...; one row per sample")
      ->group(outputs);
  run->add_option("--stats", o->stats,
                  "Statistics JSON: DOFs, method, linear solver and why, work counters, wall "
                  "time split, energy")
      ->group(outputs);
  run->add_option("--vtk", o->vtk,
                  "Directory for ParaView frames: <scene>_NNNNN.vtk per sample and "
                  "<scene>.vtk.series")
      ->group(outputs);
  run->add_flag("-q,--quiet", o->quiet, "No progress bar and no notices on stderr")->group(outputs);
  run->add_flag("--summary", o->summary,
                "Print a short summary to stdout: DOFs, method, steps, Newton work, linear "
                "solver, wall time, energy")
      ->group(outputs);

  run->add_option("--blas-threads", o->blas_threads,
                  "Threads of the OpenBLAS under CHOLMOD (default 1: on few cores its spinning "
                  "workers cost more than they gain)")
      ->check(CLI::Range(1, 256));

  run->footer(
      "Exit codes: 0 done; 2 bad input (scene, options); 3 integration failed (the CSV keeps "
      "the rows so far, marked '# stopped early'); 130 / 143 stopped by SIGINT / SIGTERM (the "
      "files are finished the same way); 1 other errors.\n"
      "Example: stiffsim run models/cloth.yaml --t-final 0.5 --set cloth.nodes=[16,16] "
      "--output cloth.csv --stats cloth.json --summary");
}

// The options the user gave, for run_settings() to apply on top of the scene.
RunOverrides overrides_from(const RunOptions& o) {
  RunOverrides r;
  if (o.integrator_option->count() > 0) r.integrator = o.integrator;
  if (o.t_final_option->count() > 0) r.t_final = o.t_final;
  if (o.step_option->count() > 0) r.step = o.step;
  if (o.fixed_step_option->count() > 0) r.fixed_step = o.fixed_step;
  if (o.error_estimate_option->count() > 0) r.error_estimate = o.error_estimate;
  if (o.accuracy_option->count() > 0) r.accuracy = o.accuracy;
  if (o.sample_period_option->count() > 0) r.sample_period = o.sample_period;
  if (o.jacobian_option->count() > 0) r.jacobian = o.jacobian;
  if (o.linear_solver_option->count() > 0) r.linear_solver = o.linear_solver;
  if (o.newton_form_option->count() > 0) r.newton_form = o.newton_form;
  if (o.error_estimator_option->count() > 0) r.error_estimator = o.error_estimator;
  if (o.newton_solve_option->count() > 0) r.newton_solve = o.newton_solve;
  if (o.newton_tolerance_option->count() > 0) r.newton_tolerance = o.newton_tolerance;
  if (o.preconditioner_precision_option->count() > 0) {
    r.preconditioner_precision = o.preconditioner_precision;
  }
  r.full_newton = o.full_newton;
  r.no_reuse = o.no_reuse;
  r.verify_roots = o.verify_roots;
  return r;
}

// A one-line progress bar on stderr, redrawn at most ten times a second so
// that drawing it never costs more than the steps it reports.
class ProgressBar {
 public:
  ProgressBar(bool enabled, double t_final) : enabled_(enabled), t_final_(t_final) {}

  void update(double fraction) {
    if (!enabled_) return;
    const auto now = std::chrono::steady_clock::now();
    if (drawn_ && now - last_draw_ < std::chrono::milliseconds(100) && fraction < 1.0) return;
    last_draw_ = now;
    drawn_ = true;
    constexpr int kWidth = 30;
    const int filled = static_cast<int>(std::clamp(fraction, 0.0, 1.0) * kWidth);
    const double elapsed = std::chrono::duration<double>(now - start_).count();
    char eta[32] = "";
    if (fraction > 0.01) {
      std::snprintf(eta, sizeof(eta), ", eta %.0f s", elapsed / fraction * (1.0 - fraction));
    }
    std::fprintf(stderr, "\r[%s%s] %3.0f%%  t = %.4g / %g s  (%.1f s%s)\033[K",
                 std::string(filled, '#').c_str(), std::string(kWidth - filled, '.').c_str(),
                 100.0 * fraction, fraction * t_final_, t_final_, elapsed, eta);
    std::fflush(stderr);
  }

  void clear() {
    if (enabled_ && drawn_) {
      std::fputs("\r\033[K", stderr);
      std::fflush(stderr);
    }
    drawn_ = false;
  }

 private:
  bool enabled_;
  double t_final_;
  bool drawn_ = false;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
  std::chrono::steady_clock::time_point last_draw_;
};

void print_summary(const RunSummary& s, const std::string& source) {
  const IntegratorStatistics& st = s.statistics;
  const IntegratorReport& r = s.report;
  std::printf("scene          %s (%s)\n", s.scene.c_str(), source.c_str());
  std::printf("dofs           nq %d, nv %d, nz %d\n", s.dofs.nq, s.dofs.nv, s.dofs.nz);
  std::printf("integrator     %s, %s, accuracy %g, step %g%s\n", r.method.c_str(), r.mode.c_str(),
              s.accuracy, s.step, r.error_estimate ? ", error estimate" : "");
  if (!r.jacobian_scheme.empty()) {
    std::printf("newton         %s form, %s Jacobian\n", r.newton_form.c_str(),
                r.jacobian_scheme.c_str());
  }
  std::printf("steps          %ld (largest %g", st.steps_taken, st.largest_step_size_taken);
  // Fixed-step runs adapt nothing: the smallest adapted step is undefined.
  if (std::isfinite(st.smallest_adapted_step_size_taken)) {
    std::printf(", smallest adapted %g", st.smallest_adapted_step_size_taken);
  }
  std::printf("), %ld shrinks from error control, %ld from Newton failures\n",
              st.step_shrinkages_from_error_control, st.step_shrinkages_from_substep_failures);
  std::printf(
      "work           %ld Newton iterations, %ld factorizations, %ld Jacobian "
      "evaluations, %ld derivative evaluations\n",
      st.newton_raphson_iterations, st.iteration_matrix_factorizations, st.jacobian_evaluations,
      st.derivative_evaluations);
  if (!r.linear_solver.empty()) {
    std::printf("linear solver  %s: %s%s%s\n", r.linear_solver.c_str(),
                r.linear_solver_reason.c_str(), r.linear_solver_fallback.empty() ? "" : "; ",
                r.linear_solver_fallback.c_str());
    std::printf("nonzeros       iteration matrix %ld, factor %ld\n", st.iteration_matrix_nonzeros,
                st.factor_nonzeros);
  }
  std::printf(
      "wall time      %.3f s (jacobian %.3f, assembly %.3f, factorization %.3f, "
      "solve %.3f, derivatives %.3f)\n",
      s.wall_seconds, st.jacobian_seconds, st.assembly_seconds, st.factorization_seconds,
      st.solve_seconds, st.derivative_seconds);
  std::printf("energy         start %.10g J, end %.10g J\n", s.energy_start, s.energy_end);
  std::printf("samples        %ld up to t = %g%s\n", s.samples, s.t_reached,
              s.stopped_early ? " (stopped early)" : "");
}

int run_command(const RunOptions& options) {
  SceneRunRequest request;
  request.scene = options.scene;
  request.sets = options.sets;
  request.overrides = overrides_from(options);
  request.output = options.output;
  request.stats = options.stats;
  request.vtk = options.vtk;

  std::unique_ptr<ProgressBar> bar;
  SceneRunHooks hooks;
  hooks.on_note = [&](const std::string& note) {
    if (!options.quiet) std::fprintf(stderr, "note: %s\n", note.c_str());
  };
  hooks.on_progress = [&](double fraction, double t_final) -> std::string {
    // The bar starts with the first step: only the loaded scene knows t_final.
    if (!bar) bar = std::make_unique<ProgressBar>(!options.quiet && isatty(STDERR_FILENO), t_final);
    bar->update(fraction);
    if (g_stop_signal == 0) return "";
    return g_stop_signal == SIGINT ? "SIGINT" : "SIGTERM";
  };
  std::signal(SIGINT, request_stop);
  std::signal(SIGTERM, request_stop);

  const SceneRunResult result = run_scene(request, hooks);
  if (bar) bar->clear();
  const RunSummary& summary = result.summary;
  int exit_code = 0;
  switch (result.failure) {
    case SceneRunFailure::kNone:
      break;
    case SceneRunFailure::kStopped:
      exit_code = 128 + g_stop_signal;
      break;
    case SceneRunFailure::kIntegration:
      exit_code = IntegrationError::kExitCode;
      break;
    case SceneRunFailure::kInput:
      exit_code = InputError::kExitCode;
      break;
    case SceneRunFailure::kOther:
      exit_code = 1;
      break;
  }

  if (options.summary) print_summary(summary, result.source);
  if (!result.message.empty()) {
    std::fprintf(stderr, "stiffsim: error: %s\n", result.message.c_str());
    if (!options.output.empty() && result.write_errors.empty()) {
      std::fprintf(stderr, "stiffsim: kept %ld sample(s) up to t = %g in %s\n",
                   result.trajectory_rows, summary.t_reached, options.output.c_str());
    }
  } else if (!options.quiet && !options.summary) {
    std::fprintf(stderr, "stiffsim: %s: %ld samples to t = %g in %.2f s (%ld steps)\n",
                 summary.scene.c_str(), summary.samples, summary.t_reached, summary.wall_seconds,
                 summary.statistics.steps_taken);
  }
  for (const std::string& e : result.write_errors)
    std::fprintf(stderr, "stiffsim: error: %s\n", e.c_str());
  if (exit_code == 0 && !result.write_errors.empty()) exit_code = 1;
  return exit_code;
}

}  // namespace
}  // namespace stiffsim

int main(int argc, char** argv) {
  using namespace stiffsim;
  CLI::App app{
      "stiffsim: sparse multibody simulation with the velocity-implicit Euler integrator.\n"
      "Scenes are YAML files (models/*.yaml) of cloth, rope and triangle-mesh mass-spring "
      "components and URDF articulated bodies, or a bare URDF file."};
  app.set_version_flag("--version", "stiffsim 0.1.0");
  app.require_subcommand(1);
  app.footer(
      "Run 'stiffsim run --help' for the options of a run, 'stiffsim bench --help' for the "
      "reports.");
  RunOptions options;
  CLI::App* run = app.add_subcommand(
      "run", "Simulate a scene and write its trajectory (CSV), statistics (JSON) and frames (VTK)");
  add_run_options(run, &options);

  ReportOptions bench_options;
  std::string report;
  CLI::App* bench =
      app.add_subcommand("bench",
                         "Run a report: work-precision, scaling or stability (CSV and Markdown; "
                         "bench/plot_reports.py draws the plots)");
  bench->add_option("report", report, "precision | scaling | stability")
      ->required()
      ->check(CLI::IsMember({"precision", "scaling", "stability"}));
  bench->add_flag("--quick", bench_options.quick,
                  "The small preset (minutes on 2 cores; CI runs it)");
  bench->add_option("--out", bench_options.out_dir, "Directory for the CSV and Markdown files")
      ->capture_default_str();
  bench_options.models_dir = STIFFSIM_MODELS_DIR;
  bench
      ->add_option("--models", bench_options.models_dir,
                   "Directory with chain_N.urdf (for MuJoCo, which loads the file)")
      ->capture_default_str();

  try {
    app.parse(argc, argv);
  } catch (const CLI::Success& e) {
    return app.exit(e);  // --help, --version
  } catch (const CLI::ParseError& e) {
    std::fprintf(stderr, "stiffsim: error: %s\nRun 'stiffsim %s--help' for the options.\n",
                 e.what(),
                 run->parsed()     ? "run "
                 : bench->parsed() ? "bench "
                                   : "");
    return kUsageExitCode;
  }

  set_blas_threads(options.blas_threads);
  try {
    if (bench->parsed()) {
      bench_options.log = &std::cerr;
      if (report == "precision") return run_precision_report(bench_options);
      if (report == "scaling") return run_scaling_report(bench_options);
      return run_stability_report(bench_options);
    }
    return run_command(options);
  } catch (const InputError& e) {
    std::fprintf(stderr, "stiffsim: error: %s\n", e.what());
    return InputError::kExitCode;
  } catch (const IntegrationError& e) {
    std::fprintf(stderr, "stiffsim: error: %s\n", e.what());
    return IntegrationError::kExitCode;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "stiffsim: error: %s\n", e.what());
    return 1;
  }
}
