#include "stiffsim/io/run_settings.h"

#include <cmath>
#include <cstdio>

#include "stiffsim/error.h"

namespace stiffsim {
namespace {

enum class Range { kPositive, kNonNegative, kUnitInterval };

// The CLI's option parser checks the same ranges before a scene is loaded;
// this check is the one every front end shares.
double checked(const char* name, double value, Range range) {
  const char* expected = range == Range::kPositive      ? "a positive number"
                         : range == Range::kNonNegative ? "a non-negative number"
                                                        : "a number in (0, 1]";
  const bool ok = std::isfinite(value) &&
                  (range == Range::kNonNegative ? value >= 0.0 : value > 0.0) &&
                  (range != Range::kUnitInterval || value <= 1.0);
  if (!ok) {
    char message[160];
    std::snprintf(message, sizeof(message), "%s: expected %s, got %g", name, expected, value);
    throw InputError(message);
  }
  return value;
}

}  // namespace

RunSettings run_settings(const SceneConfig& config, const RunOverrides& o) {
  RunSettings s;
  s.integrator_name = config.integrator_name;
  s.simulation = config.simulation;
  s.integrator = config.integrator;
  s.implicit = config.implicit;
  // make_integrator() rejects an unknown name with the list of known ones.
  if (o.integrator) s.integrator_name = *o.integrator;
  if (o.t_final) s.simulation.t_final = checked("t_final", *o.t_final, Range::kPositive);
  if (o.step) s.integrator.max_step = checked("step", *o.step, Range::kPositive);
  if (o.fixed_step) s.integrator.fixed_step = *o.fixed_step;
  if (o.error_estimate) s.integrator.error_estimate = *o.error_estimate;
  if (o.accuracy) s.integrator.accuracy = checked("accuracy", *o.accuracy, Range::kUnitInterval);
  if (o.sample_period) {
    s.simulation.sample_period = checked("sample_period", *o.sample_period, Range::kNonNegative);
  }
  if (o.jacobian) s.implicit.jacobian = parse_jacobian_scheme(*o.jacobian);
  if (o.linear_solver) s.implicit.linear_solver = parse_linear_solver_kind(*o.linear_solver);
  if (o.newton_form) s.implicit.newton_form = parse_newton_form(*o.newton_form);
  if (o.error_estimator) s.implicit.error_estimator = parse_error_estimator(*o.error_estimator);
  if (o.newton_solve) s.implicit.newton_solve = parse_newton_solve(*o.newton_solve);
  if (o.newton_tolerance) {
    s.implicit.step_error_tolerance = parse_newton_tolerance(*o.newton_tolerance);
  }
  if (o.preconditioner_precision) {
    s.implicit.single_precision_preconditioner =
        parse_preconditioner_precision(*o.preconditioner_precision);
  }
  if (o.full_newton) s.implicit.full_newton = true;
  if (o.no_reuse) s.implicit.reuse = false;
  if (o.verify_roots) s.implicit.verify_roots = true;
  if (s.integrator.min_step > s.integrator.max_step) {
    char message[160];
    std::snprintf(message, sizeof(message), "step %g is below the scene's simulation.min_step %g",
                  s.integrator.max_step, s.integrator.min_step);
    throw InputError(message);
  }
  return s;
}

}  // namespace stiffsim
