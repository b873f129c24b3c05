#include <cmath>

#include "scene_sections.h"
#include "stiffsim/integrators/integrator_factory.h"

namespace stiffsim {
namespace scene_file {

std::vector<std::string> simulation_keys() {
  return {"integrator",
          "t_final",
          "step",
          "fixed_step",
          "error_estimate",
          "accuracy",
          "sample_period",
          "min_step",
          "jacobian",
          "linear_solver",
          "newton_form",
          "full_newton",
          "reuse",
          "definite_iteration_matrix",
          "exact_hessian_near_root",
          "finish_near_root",
          "error_estimator",
          "newton_solve",
          "newton_tolerance",
          "preconditioner_precision"};
}

namespace {

// Likewise for the length of a run: at a microsecond a step, 10^9 steps of the
// smallest scene already take a quarter of an hour.
constexpr double kMaxSteps = 1e9;

}  // namespace

void read_simulation(const Section& top, SceneConfig* config) {
  if (!top.has("simulation")) return;
  const Section s(top.doc(), top.get("simulation"), "simulation", "", simulation_keys());
  config->integrator_name = s.choice_or("integrator", integrator_names(), config->integrator_name);
  config->simulation.t_final = s.number_or("t_final", Range::kPositive, config->simulation.t_final);
  config->integrator.max_step = s.number_or("step", Range::kPositive, config->integrator.max_step);
  // Even error control cannot take steps longer than `step`, so a run needs at
  // least t_final / step of them; beyond kMaxSteps that is a typo in an
  // exponent (step: 1e-310), and the run would never end.
  if (config->simulation.t_final / config->integrator.max_step > kMaxSteps) {
    std::ostringstream what;
    if (s.has("step")) {
      what << "step " << config->integrator.max_step << " would need more than " << kMaxSteps
           << " steps to reach t_final " << config->simulation.t_final;
    } else {
      what << "t_final " << config->simulation.t_final << " would need more than " << kMaxSteps
           << " steps of the default step " << config->integrator.max_step;
    }
    s.fail(s.has("step") ? s.get("step") : s.get("t_final"), what.str());
  }
  config->integrator.fixed_step = s.boolean_or("fixed_step", config->integrator.fixed_step);
  config->integrator.error_estimate =
      s.boolean_or("error_estimate", config->integrator.error_estimate);
  config->integrator.accuracy =
      s.number_or("accuracy", Range::kUnitInterval, config->integrator.accuracy);
  config->simulation.sample_period =
      s.number_or("sample_period", Range::kNonNegative, config->simulation.sample_period);
  config->integrator.min_step =
      s.number_or("min_step", Range::kNonNegative, config->integrator.min_step);
  if (config->integrator.min_step > config->integrator.max_step) {
    // Shortest round-trip form: "0.01", not std::to_string's "0.010000".
    std::ostringstream step;
    step << config->integrator.max_step;
    s.fail(s.get("min_step"),
           "min_step must not exceed step (" + step.str() + "), got " + s.get("min_step").Scalar());
  }
  ImplicitSettings& implicit = config->implicit;
  if (s.has("jacobian")) {
    implicit.jacobian = parse_jacobian_scheme(s.choice_or("jacobian", jacobian_scheme_names(), ""));
  }
  if (s.has("linear_solver")) {
    implicit.linear_solver =
        parse_linear_solver_kind(s.choice_or("linear_solver", linear_solver_names(), ""));
  }
  if (s.has("newton_form")) {
    implicit.newton_form = parse_newton_form(s.choice_or("newton_form", newton_form_names(), ""));
  }
  if (s.has("error_estimator")) {
    implicit.error_estimator =
        parse_error_estimator(s.choice_or("error_estimator", error_estimator_names(), ""));
  }
  if (s.has("newton_solve")) {
    implicit.newton_solve =
        parse_newton_solve(s.choice_or("newton_solve", newton_solve_names(), ""));
  }
  if (s.has("newton_tolerance")) {
    implicit.step_error_tolerance =
        parse_newton_tolerance(s.choice_or("newton_tolerance", newton_tolerance_names(), ""));
  }
  if (s.has("preconditioner_precision")) {
    implicit.single_precision_preconditioner = parse_preconditioner_precision(
        s.choice_or("preconditioner_precision", preconditioner_precision_names(), ""));
  }
  implicit.full_newton = s.boolean_or("full_newton", implicit.full_newton);
  implicit.reuse = s.boolean_or("reuse", implicit.reuse);
  implicit.definite_iteration_matrix =
      s.boolean_or("definite_iteration_matrix", implicit.definite_iteration_matrix);
  implicit.exact_hessian_near_root =
      s.boolean_or("exact_hessian_near_root", implicit.exact_hessian_near_root);
  implicit.finish_near_root = s.boolean_or("finish_near_root", implicit.finish_near_root);
}

}  // namespace scene_file
}  // namespace stiffsim
