#pragma once
// Bogacki-Shampine 3(2), an explicit reference with an error estimate:
//   k1 = f(t, x)   (the last stage of the previous step: FSAL)
//   k2 = f(t + h/2, x + h/2 k1),   k3 = f(t + 3h/4, x + 3h/4 k2)
//   x+ = x + h (2/9 k1 + 1/3 k2 + 4/9 k3)          (third order, propagated)
//   k4 = f(t + h, x+)
//   err = h (-5/72 k1 + 1/12 k2 + 1/9 k3 - 1/8 k4)  (x+ minus the embedded
//         second-order solution: the local error of that solution, O(h^3))
// with f = (N v, M^-1 F, f_z). Three new derivative evaluations per step
// attempt (one more for the first step); k4 is needed for the next step
// anyway, so the estimate costs no evaluation.

#include "stiffsim/integrators/integrator_base.h"

namespace stiffsim {

class RungeKutta3 : public IntegratorBase {
 public:
  RungeKutta3(const System& system, IntegratorSettings settings);
  std::string method_name() const override { return "rk3"; }
  bool supports_error_estimation() const override { return true; }
  int error_estimate_order() const override { return 3; }
  bool is_explicit() const override { return true; }

 protected:
  bool do_step(double h) override;
  void do_initialize() override;
  void on_accept(double h) override;

 private:
  // k1_ holds f at state() whenever first_stage_valid_ (after the first
  // evaluation and after every accepted step); a rejected attempt leaves it.
  Eigen::VectorXd k1_, k2_, k3_, k4_, stage_;
  bool first_stage_valid_ = false;
};

}  // namespace stiffsim
