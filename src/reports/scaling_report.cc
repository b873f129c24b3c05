// Time per step against the number of degrees of freedom: particle ropes,
// cloth, compliant chains (sparse) and exact chains (the recursion), VIE against IE,
// with the split of a step's time, the fitted exponent and each run's peak
// memory (each run in a process of its own, child_process_run.h).

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <limits>
#include <map>
#include <sstream>
#include <stdexcept>

#include "stiffsim/error.h"
#include "stiffsim/io/atomic_file.h"
#include "stiffsim/reports/child_process_run.h"
#include "stiffsim/reports/method_run.h"
#include "stiffsim/reports/reports.h"

namespace stiffsim {
namespace {

struct Family {
  std::string name;
  std::vector<int> sizes;  // the builder's size parameter
  std::function<BenchScene(int)> build;
  // The DOFs of the scene `build` makes, without building it: the scene is
  // built in each run's own process, and a row needs its size even when
  // that process never returns.
  std::function<int(int)> dofs;
  double step;
  int ie_max_dofs;  // IE only up to this size (it is the slow one)
};

// Steps after the first: the first pays the symbolic analysis and the
// first Jacobian and factorization once per run.
bool measured(const MethodRun& r) { return r.steps >= 2; }
double per_step(const MethodRun& r) {
  return (r.wall_seconds - r.first_step_wall_seconds) / std::max(1L, r.steps - 1);
}

// 0: the run was not made (its process never started).
std::string peak_text(const MethodRun& r) {
  return r.peak_resident_mb > 0.0 ? format_number("%.0f", r.peak_resident_mb) : "-";
}

struct Point {
  std::string family, method;
  int dofs = 0;
  MethodRun run;
};

}  // namespace

int run_scaling_report(const ReportOptions& options) {
  namespace fs = std::filesystem;
  create_report_directory(options.out_dir);
  auto say = [&](const std::string& line) {
    if (options.log) *options.log << line << std::endl;
  };
  const bool quick = options.quick;
  const int steps = quick ? 5 : 10;
  std::vector<Family> families;
  families.push_back(
      {"particle rope",
       quick ? std::vector<int>{34, 334, 3334} : std::vector<int>{34, 334, 3334, 33334},
       [](int n) { return rope_scene_at_shipped_spacing(n, 1e5, 1.0); },
       [](int n) { return 3 * (n - 1); },  // node 0 pinned
       1e-3, quick ? 10000 : 100000});
  families.push_back({"cloth",
                      quick ? std::vector<int>{6, 18, 58} : std::vector<int>{6, 18, 58, 100, 183},
                      [](int n) { return cloth_scene_at_shipped_spacing(n, 1e3, 1.0); },
                      [](int n) { return 3 * (n * n - 2); },  // two corners pinned
                      1.0 / 60.0, quick ? 10000 : 31000});
  families.push_back(
      {"compliant chain",
       quick ? std::vector<int>{17, 167, 1667} : std::vector<int>{17, 167, 1667, 16667},
       [](int n) { return compliant_chain_scene(n, 0.05, 1e6, 1e4, 1.0); },
       [](int n) { return 6 * n; },  // a free body per link
       1e-3, quick ? 10000 : 10000});
  families.push_back({"exact chain",
                      quick ? std::vector<int>{10, 30, 100}
                            : std::vector<int>{10, 30, 100, 300, 1000, 3000, 10000},
                      [](int n) { return chain_scene(n, 0.05, 1e4, 1.0); },  // joint springs of 1e4 N m/rad
                      [](int n) { return n; },  // a revolute joint per link
                      1e-3, quick ? 100 : 300});

  const double budget = quick ? 30.0 : 300.0;
  // A run checks its budget between steps; its process is killed when one
  // step, or building the scene, runs far past it: the budget, half of it
  // again, and 10 s.
  ChildProcessOptions child;
  child.kill_after_seconds = 1.5 * budget + 10.0;
  // Part of every row's peak: the program and the report's pages that a
  // child shares from the fork.
  const double floor_mb = run_in_child_process([] { return MethodRun{}; }, child).peak_resident_mb;

  std::vector<Point> points;
  for (const Family& f : families) {
    // A method over its budget at one size would be at every larger one:
    // those rows say so instead of waiting out the limit again.
    std::map<std::string, int> over_budget_dofs;
    for (int size : f.sizes) {
      const int dofs = f.dofs(size);
      for (const std::string method : {"vie", "ie"}) {
        if (method == "ie" && dofs > f.ie_max_dofs) continue;
        MethodRun run;
        const MethodSpec spec{method, true, f.step};
        if (over_budget_dofs.count(method)) {
          run.spec = spec;
          run.message =
              "not run: over the budget at " + std::to_string(over_budget_dofs[method]) + " DOFs";
        } else {
          BenchRunOptions o;
          o.wall_budget_seconds = budget;
          // The scene is built in the child: its time and memory are the
          // run's, and one too large for the machine ends only that process.
          run = run_in_child_process(
              [&] {
                BenchScene s = f.build(size);
                if (s.dofs() != dofs) {
                  throw std::logic_error("the scene has " + std::to_string(s.dofs()) +
                                         " DOFs; the report expected " + std::to_string(dofs));
                }
                s.t_final = steps * f.step;
                s.sample_period = s.t_final;
                return run_stiffsim(s, spec, o);
              },
              child);
          if (run.over_budget) over_budget_dofs[method] = dofs;
        }
        say("scaling: " + f.name + " " + std::to_string(dofs) + " DOFs, " + method + ": " +
            (measured(run) ? format_number("%.3f", 1e3 * per_step(run)) : std::string("-")) +
            " ms/step after the first, peak MB " + peak_text(run) +
            (run.finished ? "" : " (" + run.message + ")"));
        points.push_back({f.name, method, dofs, run});
      }
    }
  }

  std::ostringstream md;
  char limits[320];
  std::snprintf(
      limits, sizeof limits,
      " A run stops after its first step that ends past %.0f s; a process still building"
      " its scene or inside a step at %.0f s is killed. Either is unfinished, and its method"
      " is then not run at the larger sizes of its family.",
      budget, child.kill_after_seconds);
  md << "# Scaling\n\nMachine: " << machine_description() << ".\n\n"
     << "Each point: the mean of steps 2.." << steps << " of a run of fixed steps (h = 1 ms for "
     << "ropes and chains, 1/60 s for cloth) from the scene's initial state, time per step split "
     << "as the statistics count it. Ropes and cloth keep the node spacing and node mass of "
     << "models/rope.yaml and models/cloth.yaml at every size (a longer rope, a larger sheet), so "
     << "that a node's dynamics do not change with size. Exact chains have joint springs of "
     << "1e4 N m/rad and start bent 0.05 rad at every joint; VIE solves them by the "
     << "articulated-body recursion (O(n) per Newton iteration: its time is in the factorization "
     << "column, while factorizations/step counts assembled matrices only), IE by the assembled "
     << "dense matrix." << limits << "\n\n"
     << "peak MB: the peak resident set (ru_maxrss, 1 MB = 2^20 bytes) of a process forked from "
     << "the report that built the scene and made that one run: the scene, the integrator with "
     << "its matrices and factors, and all else the run allocated, from malloc or not; plus the "
     << "pages it shares with the report from the fork (program, libraries, report data: a child "
     << "that does nothing peaks at " << format_number("%.0f", floor_mb) << " MB).\n\n"
     << "| family | method | DOFs | ms/step | jacobian | assembly | factorization | solve "
     << "| derivatives | factorizations/step | nnz matrix | nnz factor | peak MB | solver |\n"
     << "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  std::ostringstream csv;
  csv << "family,method,dofs,steps,ms_per_step,jacobian_ms,assembly_ms,factorization_ms,solve_ms,"
         "derivative_ms,factorizations_per_step,nnz_matrix,nnz_factor,peak_resident_mb,"
         "linear_solver,finished\n";
  for (const Point& p : points) {
    IntegratorStatistics st = p.run.stats;
    const IntegratorStatistics& f = p.run.first_step_stats;
    st.jacobian_seconds -= f.jacobian_seconds;
    st.assembly_seconds -= f.assembly_seconds;
    st.factorization_seconds -= f.factorization_seconds;
    st.solve_seconds -= f.solve_seconds;
    st.derivative_seconds -= f.derivative_seconds;
    st.iteration_matrix_factorizations -= f.iteration_matrix_factorizations;
    const double n = std::max(1L, p.run.steps - 1);
    // A run with fewer than two steps has no time per step to show.
    // A run with fewer than two steps has no time per step, one not made no
    // peak: an empty CSV field, "-" in the table.
    auto ms = [&](double seconds) {
      return measured(p.run) ? format_number("%.4f", 1e3 * seconds / n) : std::string();
    };
    auto cell = [](const std::string& text) { return text.empty() ? std::string("-") : text; };
    const double wall = p.run.wall_seconds - p.run.first_step_wall_seconds;
    csv << csv_field(p.family) << "," << p.method << "," << p.dofs << "," << p.run.steps << ","
        << ms(wall) << "," << ms(st.jacobian_seconds) << "," << ms(st.assembly_seconds) << ","
        << ms(st.factorization_seconds) << "," << ms(st.solve_seconds) << ","
        << ms(st.derivative_seconds) << ","
        << format_number("%.2f", st.iteration_matrix_factorizations / n) << ","
        << st.iteration_matrix_nonzeros << "," << st.factor_nonzeros << ","
        << (p.run.peak_resident_mb > 0.0 ? format_number("%.1f", p.run.peak_resident_mb) : "")
        << "," << csv_field(p.run.linear_solver) << "," << (p.run.finished ? 1 : 0) << "\n";
    md << "| " << p.family << " | " << p.method << " | " << p.dofs << " | " << cell(ms(wall))
       << " | " << cell(ms(st.jacobian_seconds)) << " | " << cell(ms(st.assembly_seconds)) << " | "
       << cell(ms(st.factorization_seconds)) << " | " << cell(ms(st.solve_seconds)) << " | "
       << cell(ms(st.derivative_seconds)) << " | "
       << format_number("%.2f", st.iteration_matrix_factorizations / n) << " | "
       << st.iteration_matrix_nonzeros << " | " << st.factor_nonzeros << " | " << peak_text(p.run)
       << " | " << p.run.linear_solver << (p.run.finished ? "" : " (" + p.run.message + ")")
       << " |\n";
  }
  md << "\n## Fitted exponents (time per step ~ DOFs^p, VIE, sizes >= 1000 DOFs)\n\n| family | p | points |\n|---|---|---|\n";
  for (const Family& f : families) {
    std::vector<double> x, y;
    for (const Point& p : points) {
      if (p.family == f.name && p.method == "vie" && p.dofs >= 900 && p.run.finished) {
        x.push_back(p.dofs);
        y.push_back(per_step(p.run));
      }
    }
    md << "| " << f.name << " | " << (x.size() >= 2 ? format_number("%.2f", fitted_exponent(x, y)) : "-") << " | "
       << x.size() << " |\n";
  }
  md << "\nGoals: particle ropes and compliant chains at an exponent of at most 1.1 between 10^3 and 10^5 DOFs"
     << (quick ? " (the quick preset stops at 10^4)" : "")
     << "; exact chains at most 5 ms per step at 1,000 links, at an exponent of at most 1.2 "
     << "from 100 to 10,000 links (the full preset).\n\n## VIE against IE, time per step\n\n"
     << "| family | DOFs | VIE ms | IE ms | IE / VIE |\n|---|---|---|---|---|\n";
  for (const Point& p : points) {
    if (p.method != "vie") continue;
    for (const Point& q : points) {
      if (q.method == "ie" && q.family == p.family && q.dofs == p.dofs && measured(p.run) &&
          measured(q.run)) {
        const double a = per_step(p.run);
        const double b = per_step(q.run);
        md << "| " << p.family << " | " << p.dofs << " | " << format_number("%.3f", 1e3 * a) << " | "
           << format_number("%.3f", 1e3 * b) << " | " << format_number("%.1f", b / a) << " |\n";
      }
    }
  }
  // Goal: VIE at least 5x faster than IE at equal error on a cloth of about
  // 30k DOFs, the gap growing with size. Both error-controlled over the
  // same accuracy targets for 0.1 s of the fall; error against RK45 at
  // 1e-10; the time each needs to come within IE's error at accuracy 1e-3.
  md << "\n## VIE against IE at equal error (cloth, error-controlled, 0.1 s)\n\n"
     << "Error: the largest position difference from RK45 at accuracy 1e-10 at t = 0.05 and 0.1 s. "
     << "Target: IE's error at accuracy 1e-3; each method's least wall time reaching it over "
     << "accuracies 1e-2, 1e-3, 1e-4 (VIE) and 1e-2, 1e-3 (IE).\n\n"
     << "| cloth | DOFs | target error | VIE s | IE s | IE / VIE |\n|---|---|---|---|---|---|\n";
  for (int n : quick ? std::vector<int>{18, 32} : std::vector<int>{32, 58, 100}) {
    BenchScene s = cloth_scene_at_shipped_spacing(n, 1e3, 0.1);
    s.sample_period = 0.05;
    BenchRunOptions o;
    o.wall_budget_seconds = quick ? 60.0 : 1800.0;
    const MethodRun reference = run_stiffsim(s, {"rk45", false, 1e-10}, o);
    if (!reference.finished) continue;
    std::map<std::string, std::vector<std::pair<double, double>>> runs;  // method -> (error, wall)
    double target = 0.0;
    for (const char* method : {"vie", "ie"}) {
      // IE below 1e-3 is not needed for the target and costs minutes.
      const std::vector<double> accuracies =
          std::string(method) == "vie" ? std::vector<double>{1e-2, 1e-3, 1e-4} : std::vector<double>{1e-2, 1e-3};
      for (double a : accuracies) {
        const MethodRun run = run_stiffsim(s, {method, false, a}, o);
        const double error = run.finished ? max_position_error(*s.scene, run, reference)
                                          : std::numeric_limits<double>::infinity();
        runs[method].push_back({error, run.wall_seconds});
        if (std::string(method) == "ie" && a == 1e-3) target = error;
        say("scaling: equal error, cloth " + std::to_string(s.dofs()) + " DOFs, " + method + " accuracy " +
            format_number("%.0e", a) + ": error " + format_number("%.2e", error) + ", " +
            format_number("%.2f", run.wall_seconds) + " s");
      }
    }
    auto best = [&](const std::string& method) {
      double t = std::numeric_limits<double>::infinity();
      for (const auto& [error, wall] : runs[method]) {
        if (error <= target * (1.0 + 1e-12)) t = std::min(t, wall);
      }
      return t;
    };
    const double vie = best("vie"), ie = best("ie");
    md << "| " << n << "x" << n << " | " << s.dofs() << " | " << format_number("%.2e", target) << " | "
       << format_number("%.2f", vie) << " | " << format_number("%.2f", ie) << " | "
       << format_number("%.1f", ie / vie) << " |\n";
  }
  // Each file appears whole or not at all, and a failed write is an error.
  write_file_atomically((fs::path(options.out_dir) / "scaling.csv").string(), csv.str());
  write_file_atomically((fs::path(options.out_dir) / "scaling.md").string(), md.str());
  say("scaling: wrote " + (fs::path(options.out_dir) / "scaling.csv").string() + " and scaling.md");
  return 0;
}

}  // namespace stiffsim
