#include "stiffsim/integrators/integrator_factory.h"

#include "stiffsim/error.h"
#include "stiffsim/integrators/velocity_implicit_euler.h"

namespace stiffsim {

std::vector<std::string> integrator_names() { return {"vie"}; }

std::unique_ptr<IntegratorBase> make_integrator(const std::string& name, const System& system,
                                                const IntegratorSettings& settings,
                                                const ImplicitSettings& implicit) {
  if (name == "vie") return std::make_unique<VelocityImplicitEuler>(system, settings, implicit);
  std::string known;
  for (const auto& n : integrator_names()) known += (known.empty() ? "" : ", ") + n;
  throw InputError("unknown integrator '" + name + "' (expected one of: " + known + ")");
}

}  // namespace stiffsim
