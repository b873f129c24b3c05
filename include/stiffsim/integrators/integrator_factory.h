#pragma once
// Constructs an integrator by its CLI name.

#include <memory>
#include <string>
#include <vector>

#include "stiffsim/integrators/implicit_integrator.h"

namespace stiffsim {

// Names accepted by make_integrator ("vie", ...).
std::vector<std::string> integrator_names();

// Throws InputError for an unknown name.
std::unique_ptr<IntegratorBase> make_integrator(const std::string& name, const System& system,
                                                const IntegratorSettings& settings,
                                                const ImplicitSettings& implicit);

}  // namespace stiffsim
