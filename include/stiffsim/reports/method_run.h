#pragma once
// One run of one method on one scene, as every report takes it: the samples
// at fixed times (dense output between steps), the wall time, the work
// counters, the energy at every step where the report asks, and how it ended.
// Peers (CVODE, MuJoCo) return the same shape (PeerRun) and are converted.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "stiffsim/integrators/integrator_statistics.h"
#include "stiffsim/peers/peer_run.h"
#include "stiffsim/reports/bench_scenes.h"

namespace stiffsim {

struct MethodSpec {
  std::string method;      // vie, vie2, ie, ie2, semi-explicit-euler, rk3, rk45, cvode, mujoco-implicit, mujoco-rk4
  bool fixed = false;      // fixed step h = parameter; else accuracy (rtol for CVODE) = parameter
  double parameter = 1e-3;
  std::string label() const;  // e.g. "vie accuracy 1e-03", "ie h 1e-03"
};

// A field added here must be added to the payload a child process sends
// back (child_process_run.cc) too.
struct MethodRun {
  MethodSpec spec;
  std::vector<double> times;
  std::vector<Eigen::VectorXd> samples;  // x at `times`
  double wall_seconds = 0.0;
  long steps = 0, newton_iterations = 0, factorizations = 0, newton_failures = 0;
  long derivative_evaluations = 0;
  IntegratorStatistics stats;  // stiffsim methods only
  std::string linear_solver;   // stiffsim implicit methods
  std::string settings;        // peers: what they ran with
  bool finished = false;       // reached t_final
  bool over_budget = false;    // stopped by the wall-time budget
  std::string message;         // failure or budget message
  double energy_start = 0.0, energy_max = 0.0, energy_end = 0.0;  // when tracked
  double kinetic_max = 0.0;  // largest kinetic energy 1/2 v^T M v seen, when tracked
  bool non_finite = false;
  // Peak resident set of the process that made this run alone
  // (run_in_child_process); 0 when it ran inside the caller's process.
  double peak_resident_mb = 0.0;
  // After the first step (symbolic analysis, first Jacobian and
  // factorization): the scaling report measures the steps after it.
  double first_step_wall_seconds = 0.0;
  IntegratorStatistics first_step_stats;
};

struct BenchRunOptions {
  double wall_budget_seconds = 60.0;  // stop (as over budget) after this much wall time
  bool track_energy = false;          // energy at every step end (stiffsim methods)
};

// Runs a stiffsim integrator on `scene` from its initial state to t_final,
// sampling every scene.sample_period.
MethodRun run_stiffsim(const BenchScene& scene, const MethodSpec& spec, const BenchRunOptions& options);

// CVODE at rtol = spec.parameter, atol = rtol * 1e-2 (absent peers give a
// run with finished = false and the reason in message).
MethodRun run_cvode_peer(const BenchScene& scene, const MethodSpec& spec, const BenchRunOptions& options);

// The largest |q_i(t) - q_ref_i(t)| over the sample times both runs have,
// over positions that are not quaternion entries (metres for particles and
// free-body positions, radians for joints). Infinity when `run` did not
// reach the last reference sample.
double max_position_error(const System& system, const MethodRun& run, const MethodRun& reference);

// Least-squares slope of log y against log x.
double fitted_exponent(const std::vector<double>& x, const std::vector<double>& y);

// The machine the reports ran on (CPU model, cores, compiler), one line.
std::string machine_description();

// printf-style formatting of one number, for tables.
std::string format_number(const char* format, double x);

// Creates a report's output directory; throws InputError naming it when it
// cannot.
void create_report_directory(const std::string& dir);

// RFC 4180 field: quoted when it holds a comma, quote or newline.
std::string csv_field(const std::string& text);

}  // namespace stiffsim
