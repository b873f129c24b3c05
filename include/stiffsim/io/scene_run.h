#pragma once
// One run of a scene file as `stiffsim run` makes it: load the scene with its
// --set overrides, apply the run options, integrate to t_final and write the
// trajectory CSV, the stats JSON and the VTK frames that were asked for. The
// CLI and the Python module both call run_scene(); what stays in each is how
// it shows progress and how it reports the outcome.

#include <functional>
#include <string>
#include <vector>

#include "stiffsim/io/run_settings.h"
#include "stiffsim/io/stats_writer.h"

namespace stiffsim {

struct SceneRunRequest {
  std::string scene;              // scene file (YAML or bare URDF)
  std::vector<std::string> sets;  // "PATH=VALUE" overrides, as --set
  RunOverrides overrides;
  std::string output, stats, vtk;  // empty: that file is not written
};

struct SceneRunHooks {
  // Each note of the loaders (what they ignored or assumed).
  std::function<void(const std::string& note)> on_note;
  // Called after every step with the fraction of the run done and the end
  // time it is a fraction of (the scene's, or the override). A non-empty
  // return stops the run after that step and names why (e.g. "SIGINT"); the
  // files are then finished as for a failed run.
  std::function<std::string(double fraction, double t_final)> on_progress;
};

enum class SceneRunFailure { kNone, kStopped, kIntegration, kInput, kOther };

struct SceneRunResult {
  RunSummary summary;
  std::string source;  // the scene file as the user named it
  SceneRunFailure failure = SceneRunFailure::kNone;
  // Why the run ended early (the integrator's message for kIntegration,
  // "interrupted by <why> at t = .. s (last step h = .. s)" for kStopped);
  // empty when it finished.
  std::string message;
  double failure_time = 0.0, failure_step = 0.0;  // IntegrationError's, for kIntegration
  long trajectory_rows = 0;
  // Files that could not be finished (each a message); the others are.
  std::vector<std::string> write_errors;
};

// Throws InputError before any file is created for a bad scene, bad options
// or an unwritable output path. A failure during the integration is not
// thrown: the files keep what was computed, marked as stopped early, and the
// result says what happened.
SceneRunResult run_scene(const SceneRunRequest& request, const SceneRunHooks& hooks = {});

}  // namespace stiffsim
