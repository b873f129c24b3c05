#pragma once
// Semi-explicit (symplectic) Euler, a fixed-step reference:
//   v+ = v + h M(q)^-1 F(t, q, v, z),   z+ = z + h f_z(t, q, v, z),
//   q+ = q + h N(q) v+.
// Updating q with the new velocity makes the map symplectic for
// conservative particle systems, so energy oscillates in a band of O(h)
// instead of drifting as with explicit Euler. One force evaluation per step,
// no error estimate; stable only for h below about 2 / (highest frequency).

#include "stiffsim/integrators/integrator_base.h"

namespace stiffsim {

class SemiExplicitEuler : public IntegratorBase {
 public:
  // Throws InputError unless settings.fixed_step is set and
  // settings.error_estimate is not (the method has no estimate to control).
  SemiExplicitEuler(const System& system, IntegratorSettings settings);
  std::string method_name() const override { return "semi-explicit-euler"; }
  bool supports_error_estimation() const override { return false; }
  int error_estimate_order() const override { return 0; }  // none: never error-controlled
  bool is_explicit() const override { return true; }

 protected:
  bool do_step(double h) override;
  void do_initialize() override;

 private:
  Eigen::VectorXd F_, zdot_, vdot_, qdot_;
};

}  // namespace stiffsim
