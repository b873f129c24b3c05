#include "stiffsim/io/scene_run.h"

#include <chrono>
#include <cstdio>
#include <initializer_list>
#include <memory>

#include "stiffsim/error.h"
#include "stiffsim/integrators/integrator_factory.h"
#include "stiffsim/io/trajectory_writer.h"
#include "stiffsim/io/vtk_writer.h"

namespace stiffsim {
namespace {

// Thrown by the progress callback through simulate() to stop after a step.
struct Stopped {
  std::string why;
};

}  // namespace

SceneRunResult run_scene(const SceneRunRequest& request, const SceneRunHooks& hooks) {
  SceneConfig config = load_scene(request.scene, request.sets);
  if (hooks.on_note) {
    for (const std::string& note : config.notes) hooks.on_note(note);
  }
  const RunSettings settings = run_settings(config, request.overrides);
  const Scene& scene = *config.scene;
  std::unique_ptr<IntegratorBase> integrator =
      make_integrator(settings.integrator_name, scene, settings.integrator, settings.implicit);

  // Writers only now that the scene has loaded: a bad scene leaves no files.
  // Each reserves a temporary file, so an unwritable path fails before the run.
  std::unique_ptr<TrajectoryWriter> trajectory;
  std::unique_ptr<StatsWriter> stats;
  std::unique_ptr<VtkWriter> vtk;
  if (!request.output.empty()) {
    trajectory = std::make_unique<TrajectoryWriter>(request.output, scene);
  }
  if (!request.stats.empty()) stats = std::make_unique<StatsWriter>(request.stats);
  if (!request.vtk.empty()) {
    vtk = std::make_unique<VtkWriter>(request.vtk, scene, config.surfaces);
  }

  SceneRunResult result;
  result.source = config.source;
  RunSummary& summary = result.summary;
  summary.scene = scene.name();
  summary.dofs = scene.dimensions();
  summary.accuracy = settings.integrator.accuracy;
  summary.step = settings.integrator.max_step;
  summary.sample_period = settings.simulation.sample_period;
  summary.t_final = settings.simulation.t_final;
  const State initial = scene.initial_state();
  summary.energy_start = scene.energy(initial);

  // The summary's view of the samples: where the run got to.
  struct Tracker : SampleSink {
    RunSummary* summary;
    Eigen::VectorXd last_x;
    explicit Tracker(RunSummary* s) : summary(s) {}
    bool on_sample(double t, const Eigen::VectorXd& x) override {
      summary->t_reached = t;
      last_x = x;
      ++summary->samples;
      return true;
    }
  } tracker(&summary);
  std::vector<SampleSink*> sinks;
  for (SampleSink* sink : std::initializer_list<SampleSink*>{trajectory.get(), vtk.get()}) {
    if (sink) sinks.push_back(sink);
  }
  sinks.push_back(&tracker);
  const ProgressCallback on_progress = [&](double fraction) {
    if (!hooks.on_progress) return;
    std::string why = hooks.on_progress(fraction, settings.simulation.t_final);
    if (!why.empty()) throw Stopped{std::move(why)};
  };

  const auto start = std::chrono::steady_clock::now();
  try {
    const SimulationResult run =
        simulate(*integrator, initial, settings.simulation, sinks, on_progress);
    summary.stopped_early = run.stopped_early;
    if (run.stopped_early) summary.stop_reason = "stopped by the sample callback";
  } catch (const Stopped& stop) {
    result.failure = SceneRunFailure::kStopped;
    char message[200];
    std::snprintf(message, sizeof(message), "interrupted by %s at t = %g s (last step h = %g s)",
                  stop.why.c_str(), integrator->state().t,
                  integrator->state().t - integrator->previous_time());
    result.message = message;
  } catch (const IntegrationError& e) {
    // The integrator's message names the time, the step and the method
    // (error.h), so it is passed on as is.
    result.failure = SceneRunFailure::kIntegration;
    result.message = e.what();
    result.failure_time = e.time();
    result.failure_step = e.step();
  } catch (const InputError& e) {
    result.failure = SceneRunFailure::kInput;
    result.message = e.what();
  } catch (const std::exception& e) {
    result.failure = SceneRunFailure::kOther;
    result.message = e.what();
  }
  summary.wall_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (result.failure != SceneRunFailure::kNone) {
    summary.stopped_early = true;
    summary.stop_reason = result.message;
  }
  summary.statistics = integrator->statistics();
  summary.report = integrator->report();
  if (tracker.last_x.size() > 0) {
    summary.energy_end = scene.energy(State(summary.t_reached, tracker.last_x));
  }

  // A failed run keeps what it computed, marked as incomplete; if even that
  // cannot be written, the writers' destructors remove their temporary files.
  for (std::string& error : end_sinks(sinks, result.message)) {
    result.write_errors.push_back(std::move(error));
  }
  if (stats) {
    try {
      stats->write(summary);
    } catch (const std::exception& e) {
      result.write_errors.push_back(e.what());
    }
  }
  if (trajectory) result.trajectory_rows = trajectory->rows();
  return result;
}

}  // namespace stiffsim
