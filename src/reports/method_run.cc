#include "stiffsim/reports/method_run.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <sstream>

#include "stiffsim/error.h"
#include "stiffsim/integrators/integrator_factory.h"
#include "stiffsim/integrators/simulator.h"
#include "stiffsim/peers/cvode_peer.h"

namespace stiffsim {

std::string MethodSpec::label() const {
  char buffer[96];
  std::snprintf(buffer, sizeof buffer, "%s %s %.0e", method.c_str(), fixed ? "h" : "accuracy", parameter);
  return buffer;
}

MethodRun run_stiffsim(const BenchScene& bench, const MethodSpec& spec, const BenchRunOptions& options) {
  MethodRun run;
  run.spec = spec;
  const System& system = *bench.scene;
  IntegratorSettings settings;
  settings.fixed_step = spec.fixed;
  if (spec.fixed) {
    settings.max_step = spec.parameter;
  } else {
    settings.accuracy = spec.parameter;
    settings.max_step = bench.step;
  }
  std::unique_ptr<IntegratorBase> integrator;
  try {
    integrator = make_integrator(spec.method, system, settings, ImplicitSettings{});
  } catch (const std::exception& e) {
    run.message = e.what();
    return run;
  }
  const State initial = system.initial_state();
  SparseMatrix mass;  // the pattern is taken when energy is tracked (dense for exact chains)
  const bool energy = options.track_energy && system.capabilities().has_energy;
  // The meters' own workspace: the integrator's is its own.
  const std::unique_ptr<SystemData> data = energy ? system.make_data() : nullptr;
  if (energy) run.energy_start = run.energy_max = run.energy_end = system.energy(*data, initial);
  const auto start = std::chrono::steady_clock::now();
  auto elapsed = [&] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  };
  // Per step: the first step's cost, a non-finite state, the energy, the
  // wall-time budget; samples at k * sample_period and t_final (the initial
  // state is not one).
  auto on_step = [&](const IntegratorBase& it) {
    const State& s = it.state();
    if (it.statistics().steps_taken == 1) {
      run.first_step_wall_seconds = elapsed();
      run.first_step_stats = it.statistics();
    }
    if (!s.x.allFinite()) {
      run.non_finite = true;
      run.message = "non-finite state at t = " + std::to_string(s.t);
      return false;
    }
    if (energy) {
      const double e = system.energy(*data, s);
      run.energy_max = std::max(run.energy_max, e);
      run.energy_end = e;
      const Dimensions d = system.dimensions();
      if (mass.rows() == 0) mass = system.mass_matrix_pattern();
      system.mass_matrix(*data, s.q(d), &mass);
      const Eigen::VectorXd v = s.v(d);
      run.kinetic_max = std::max(run.kinetic_max, 0.5 * v.dot(mass * v));
    }
    if (elapsed() > options.wall_budget_seconds) {
      run.over_budget = true;
      char m[128];
      std::snprintf(m, sizeof m, "over the %.0f s budget at t = %.3g", options.wall_budget_seconds,
                    s.t);
      run.message = m;
      return false;
    }
    return true;
  };
  // The error meters read the samples after the run (the initial state is
  // not one).
  struct Recorder : SampleSink {
    MethodRun* run;
    double t0;
    Recorder(MethodRun* r, double t) : run(r), t0(t) {}
    bool on_sample(double t, const Eigen::VectorXd& x) override {
      if (t > t0) {
        run->times.push_back(t);
        run->samples.push_back(x);
      }
      return true;
    }
  } recorder(&run, initial.t);
  try {
    simulate(*integrator, initial, SimulationSettings{bench.t_final, bench.sample_period},
             std::vector<SampleSink*>{&recorder}, nullptr, on_step);
    run.finished = !run.over_budget && !run.non_finite;
  } catch (const IntegrationError& e) {
    run.message = e.what();
  } catch (const std::exception& e) {
    run.message = e.what();
  }
  run.wall_seconds = elapsed();
  const IntegratorStatistics& st = integrator->statistics();
  run.stats = st;
  run.steps = st.steps_taken;
  run.newton_iterations = st.newton_raphson_iterations;
  run.factorizations = st.iteration_matrix_factorizations;
  run.newton_failures = st.substep_failures;
  run.derivative_evaluations = st.derivative_evaluations;
  run.linear_solver = integrator->report().linear_solver;
  return run;
}

MethodRun run_cvode_peer(const BenchScene& bench, const MethodSpec& spec, const BenchRunOptions& options) {
  MethodRun run;
  run.spec = spec;
  if (!cvode_available()) {
    run.message = "stiffsim was built without SUNDIALS";
    return run;
  }
  (void)options;  // CVODE runs to the end: no budget hook
  CvodeOptions o;
  o.relative_tolerance = spec.parameter;
  o.absolute_tolerance = spec.parameter * 1e-2;
  const PeerRun p = run_cvode(*bench.scene, bench.scene->initial_state(),
                              sample_times(0.0, bench.t_final, bench.sample_period), o);
  run.times = p.times;
  run.samples = p.samples;
  run.wall_seconds = p.wall_seconds;
  run.steps = p.steps;
  run.factorizations = p.linear_setups;
  run.derivative_evaluations = p.rhs_evaluations;
  run.settings = p.settings;
  run.finished = !p.failed;
  run.message = p.message;
  return run;
}

double max_position_error(const System& system, const MethodRun& run, const MethodRun& reference) {
  const std::vector<std::string> names = system.position_names();
  std::vector<int> compared;
  for (int i = 0; i < static_cast<int>(names.size()); ++i) {
    const std::string& n = names[i];
    const auto slash = n.rfind('/');
    const std::string leaf = slash == std::string::npos ? n : n.substr(slash + 1);
    if (leaf == "qw" || leaf == "qx" || leaf == "qy" || leaf == "qz") continue;
    compared.push_back(i);
  }
  if (run.times.size() < reference.times.size()) return std::numeric_limits<double>::infinity();
  double worst = 0.0;
  for (std::size_t k = 0; k < reference.times.size(); ++k) {
    for (int i : compared) {
      const double d = std::abs(run.samples[k][i] - reference.samples[k][i]);
      if (!std::isfinite(d)) return std::numeric_limits<double>::infinity();
      worst = std::max(worst, d);
    }
  }
  return worst;
}

double fitted_exponent(const std::vector<double>& x, const std::vector<double>& y) {
  const int n = static_cast<int>(x.size());
  if (n < 2) return std::numeric_limits<double>::quiet_NaN();
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (int i = 0; i < n; ++i) {
    const double a = std::log(x[i]), b = std::log(y[i]);
    sx += a, sy += b, sxx += a * a, sxy += a * b;
  }
  return (n * sxy - sx * sy) / (n * sxx - sx * sx);
}

std::string machine_description() {
  std::string cpu = "unknown CPU";
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  int cores = 0;
  while (std::getline(in, line)) {
    if (line.rfind("model name", 0) == 0 && cpu == "unknown CPU") {
      const auto colon = line.find(':');
      if (colon != std::string::npos) cpu = line.substr(colon + 2);
    }
    if (line.rfind("processor", 0) == 0) ++cores;
  }
  std::ostringstream out;
  out << cpu << ", " << cores << " logical cores, compiled by "
#if defined(__clang__)
      << "clang " << __clang_major__ << "." << __clang_minor__;
#elif defined(__GNUC__)
      << "GCC " << __GNUC__ << "." << __GNUC_MINOR__;
#else
      << "an unknown compiler";
#endif
  return out.str();
}

std::string format_number(const char* format, double x) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, format, x);
  return buffer;
}

void create_report_directory(const std::string& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) throw InputError(dir + ": cannot create the report directory (" + ec.message() + ")");
}

std::string csv_field(const std::string& text) {
  if (text.find_first_of(",\"\n") == std::string::npos) return text;
  std::string out = "\"";
  for (char c : text) {
    if (c == '"') out += '"';
    out += c;
  }
  return out + "\"";
}

}  // namespace stiffsim
