#include "stiffsim/integrators/simulator.h"

#include <cmath>
#include <exception>

#include "stiffsim/integrators/wall_clock.h"

namespace stiffsim {

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
  // Sample k is at t0 + k * period (computed by multiplication so samples do
  // not drift); samples inside a step come from dense output.
  long next_sample = 1;
  auto sample_time = [&](long k) { return initial.t + k * period; };
  while (integrator.state().t < t_final) {
    integrator.step_at_most(t_final);
    const double t = integrator.state().t;
    if (on_step && !on_step(integrator)) {
      result.stopped_early = true;
      break;
    }
    if (period > 0.0) {
      // A sample within round-off of the step end is taken at the step end.
      const double snap = 1e-9 * period;
      while (next_sample * period + initial.t <= t + snap &&
             sample_time(next_sample) < t_final - snap) {
        const double ts = sample_time(next_sample);
        if (std::abs(ts - t) <= snap) {
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
