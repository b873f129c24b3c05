#include "stiffsim/integrators/simulator.h"

#include <cmath>
#include <exception>

#include "stiffsim/integrators/wall_clock.h"

namespace stiffsim {
namespace {

// Sample k >= 1 of a run (sample_times() in simulator.h).
struct SampleGrid {
  double t0, t_final, period;
  double time(long k) const { return t0 + k * period; }
  // A sample within round-off of a step end is taken at the step end.
  double snap() const { return 1e-9 * period; }
  // Sample k comes before t_final (which is always a sample of its own).
  bool before_end(long k) const { return time(k) < t_final - snap(); }
};

}  // namespace

std::vector<double> sample_times(double t0, double t_final, double period) {
  std::vector<double> times;
  if (period > 0.0) {
    const SampleGrid grid{t0, t_final, period};
    for (long k = 1; grid.before_end(k); ++k) times.push_back(grid.time(k));
  }
  times.push_back(t_final);
  return times;
}

SimulationResult simulate(IntegratorBase& integrator, const State& initial,
                          const SimulationSettings& settings, const SampleCallback& on_sample,
                          const ProgressCallback& on_progress, const StepCallback& on_step) {
  const auto start = WallClock::now();
  SimulationResult result;
  auto elapsed = [&] { return seconds_since(start); };
  integrator.initialize(initial);
  const double t_final = settings.t_final;
  const double period = settings.sample_period;
  Eigen::VectorXd sample;
  auto deliver = [&](double t, const Eigen::VectorXd& x) {
    ++result.samples;
    return !on_sample || on_sample(t, x);
  };
  if (!deliver(initial.t, initial.x)) {
    result.stopped_early = true;
    result.wall_seconds = elapsed();
    return result;
  }
  // Samples inside a step come from dense output.
  const SampleGrid grid{initial.t, t_final, period};
  long next_sample = 1;
  while (integrator.state().t < t_final) {
    integrator.step_at_most(t_final);
    const double t = integrator.state().t;
    if (on_step && !on_step(integrator)) {
      result.stopped_early = true;
      break;
    }
    if (period > 0.0) {
      while (grid.time(next_sample) <= t + grid.snap() && grid.before_end(next_sample)) {
        const double ts = grid.time(next_sample);
        if (std::abs(ts - t) <= grid.snap()) {
          sample = integrator.state().x;
        } else {
          integrator.interpolate(ts, &sample);
        }
        ++next_sample;
        if (!deliver(ts, sample)) {
          result.stopped_early = true;
          result.wall_seconds = elapsed();
          return result;
        }
      }
      if (t >= t_final) {
        if (!deliver(t, integrator.state().x)) result.stopped_early = true;
      }
    } else if (!deliver(t, integrator.state().x)) {
      result.stopped_early = true;
      break;
    }
    if (on_progress) on_progress((t - initial.t) / (t_final - initial.t));
  }
  result.wall_seconds = elapsed();
  return result;
}

SimulationResult simulate(IntegratorBase& integrator, const State& initial,
                          const SimulationSettings& settings, const std::vector<SampleSink*>& sinks,
                          const ProgressCallback& on_progress, const StepCallback& on_step) {
  const SampleCallback on_sample = [&sinks](double t, const Eigen::VectorXd& x) {
    bool go_on = true;
    for (SampleSink* sink : sinks) go_on = sink->on_sample(t, x) && go_on;
    return go_on;
  };
  return simulate(integrator, initial, settings, on_sample, on_progress, on_step);
}

std::vector<std::string> end_sinks(const std::vector<SampleSink*>& sinks,
                                   const std::string& reason) {
  std::vector<std::string> errors;
  for (SampleSink* sink : sinks) {
    try {
      sink->on_end(reason);
    } catch (const std::exception& e) {
      errors.push_back(e.what());
    }
  }
  return errors;
}

}  // namespace stiffsim
