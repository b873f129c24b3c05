#pragma once
// How the force Jacobians of an implicit step are obtained: the system's
// analytic ones, forward or central differences over coloured columns, or
// forward-mode automatic differentiation (DESIGN.md section 2).

#include <string>

namespace stiffsim {

enum class JacobianScheme { kAnalytic, kForward, kCentral, kAutomatic };
// "analytic", "forward", "central" or "automatic"; throws InputError otherwise.
JacobianScheme parse_jacobian_scheme(const std::string& name);
std::string to_string(JacobianScheme scheme);

}  // namespace stiffsim
