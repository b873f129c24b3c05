#pragma once
// The simulation loop: drives an integrator to t_final and hands samples at
// the requested period (interpolated by dense output when a sample falls
// inside a step) to a callback.

#include <functional>
#include <vector>

#include "stiffsim/integrators/integrator_base.h"
#include "stiffsim/integrators/sample_sink.h"

namespace stiffsim {

struct SimulationSettings {
  double t_final = 1.0;
  double sample_period = 0.01;  // <= 0: a sample at every step end
};

struct SimulationResult {
  double wall_seconds = 0.0;
  long samples = 0;
  bool stopped_early = false;  // the sample callback or progress asked to stop
};

// Called with each sample (t, x); return false to stop the run early.
using SampleCallback = std::function<bool(double t, const Eigen::VectorXd& x)>;
// Called after every step with the fraction done (0..1).
using ProgressCallback = std::function<void(double fraction)>;
// Called after every step, before that step's samples, with the integrator
// (its state, statistics); return false to stop the run after the step.
using StepCallback = std::function<bool(const IntegratorBase& integrator)>;

// Samples t = 0, T, 2T, ... and t_final. Throws IntegrationError from the
// integrator after the samples before the failure have been delivered.
// The one run loop: the CLI, the Python module and the reports all drive
// their runs through it.
SimulationResult simulate(IntegratorBase& integrator, const State& initial,
                          const SimulationSettings& settings, const SampleCallback& on_sample,
                          const ProgressCallback& on_progress = nullptr,
                          const StepCallback& on_step = nullptr);

// The times simulate() samples after t0 for this period: t0 + k * period
// (k = 1, 2, ...; by multiplication, so they do not drift) while more than
// 1e-9 of a period before t_final, then t_final. Peers that sample at given
// times (CVODE, MuJoCo) take these, so every method of a report is compared
// at the same instants. period <= 0: t_final alone.
std::vector<double> sample_times(double t0, double t_final, double period);

// As above, each sample handed to every sink in order; the run stops after a
// sample that any sink declined. The sinks are not ended: the caller does
// that (end_sinks) once it knows how the run ended.
SimulationResult simulate(IntegratorBase& integrator, const State& initial,
                          const SimulationSettings& settings, const std::vector<SampleSink*>& sinks,
                          const ProgressCallback& on_progress = nullptr,
                          const StepCallback& on_step = nullptr);

}  // namespace stiffsim
