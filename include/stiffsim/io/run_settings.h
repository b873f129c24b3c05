#pragma once
// The settings of one run: the scene's simulation block with the options the
// user gave on top of it (the CLI's run options, the Python keywords). Both
// front ends go through run_settings(), so an option means the same thing and
// is checked the same way in either.

#include <optional>
#include <string>

#include "stiffsim/integrators/implicit_integrator.h"
#include "stiffsim/integrators/integrator_base.h"
#include "stiffsim/integrators/simulator.h"
#include "stiffsim/io/scene_yaml.h"

namespace stiffsim {

// Each field overrides the scene only when set; the names are the CLI's
// options without the dashes (step: --step, ...).
struct RunOverrides {
  std::optional<std::string> integrator;
  std::optional<double> t_final, step, accuracy, sample_period;
  std::optional<bool> fixed_step, error_estimate;
  std::optional<std::string> jacobian, linear_solver, newton_form, error_estimator, newton_solve,
      newton_tolerance, preconditioner_precision;
  bool full_newton = false;  // only ever switches full Newton on, as the flag does
  bool no_reuse = false;     // only ever switches the reuse ladder off
  bool verify_roots = false;  // only ever switches the root check on
};

struct RunSettings {
  std::string integrator_name;
  SimulationSettings simulation;
  IntegratorSettings integrator;
  ImplicitSettings implicit;
};

// The scene's settings with `overrides` applied. Throws InputError for a
// value out of range (a step or end time that is not a positive finite
// number, an accuracy outside (0, 1], a negative sample period), an unknown
// implicit option name, or a step below the scene's min_step. An unknown
// integrator name is left to make_integrator(), which lists the known ones.
RunSettings run_settings(const SceneConfig& config, const RunOverrides& overrides);

}  // namespace stiffsim
