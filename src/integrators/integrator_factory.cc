#include "stiffsim/integrators/integrator_factory.h"

#include "stiffsim/error.h"
#include "stiffsim/integrators/implicit_euler.h"
#include "stiffsim/integrators/runge_kutta3.h"
#include "stiffsim/integrators/runge_kutta45.h"
#include "stiffsim/integrators/semi_explicit_euler.h"
#include "stiffsim/integrators/velocity_implicit_euler.h"

namespace stiffsim {

std::vector<std::string> integrator_names() { return {"vie", "vie2", "ie", "ie2", "semi-explicit-euler", "rk3", "rk45"}; }

std::unique_ptr<IntegratorBase> make_integrator(const std::string& name, const System& system,
                                                const IntegratorSettings& settings,
                                                const ImplicitSettings& implicit) {
  // The "2" variants are their first-order method with local extrapolation
  // of the step-doubling pair.
  ImplicitSettings extrapolated = implicit;
  extrapolated.extrapolate = true;
  if (name == "vie") return std::make_unique<VelocityImplicitEuler>(system, settings, implicit);
  if (name == "vie2") {
    return std::make_unique<VelocityImplicitEuler>(system, settings, extrapolated);
  }
  if (name == "ie") return std::make_unique<ImplicitEuler>(system, settings, implicit);
  if (name == "ie2") return std::make_unique<ImplicitEuler>(system, settings, extrapolated);
  if (name == "semi-explicit-euler") return std::make_unique<SemiExplicitEuler>(system, settings);
  if (name == "rk3") return std::make_unique<RungeKutta3>(system, settings);
  if (name == "rk45") return std::make_unique<RungeKutta45>(system, settings);
  std::string known;
  for (const auto& n : integrator_names()) known += (known.empty() ? "" : ", ") + n;
  throw InputError("unknown integrator '" + name + "' (expected one of: " + known + ")");
}

}  // namespace stiffsim
