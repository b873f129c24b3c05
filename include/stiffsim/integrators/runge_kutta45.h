#pragma once
// Dormand-Prince 5(4) (Hairer, Norsett & Wanner, Solving ODEs I, II.5,
// code DOPRI5), the explicit reference for smooth non-stiff scenes:
// seven stages with f = (N v, M^-1 F, f_z), the fifth-order solution
// propagated, its last stage f(t + h, x+) the first of the next step (FSAL:
// six new derivative evaluations per step attempt, seven for the first).
// err = x+ minus the embedded fourth-order solution, O(h^5).
//
// Dense output is DOPRI5's continuous extension of order 4 (local error
// O(h^5)), built from the stages of the last accepted step without any
// further evaluation; cubic Hermite on the same steps is one order lower.

#include <array>

#include "stiffsim/integrators/integrator_base.h"

namespace stiffsim {

class RungeKutta45 : public IntegratorBase {
 public:
  RungeKutta45(const System& system, IntegratorSettings settings);
  std::string method_name() const override { return "rk45"; }
  bool supports_error_estimation() const override { return true; }
  int error_estimate_order() const override { return 5; }
  bool is_explicit() const override { return true; }

 protected:
  bool do_step(double h) override;
  void do_initialize() override;
  void on_accept(double h) override;
  bool do_interpolate(double t, Eigen::VectorXd* x) override;

 private:
  static constexpr int kStages = 7;
  // Stages of the current attempt. k_[0] is f at state() whenever
  // first_stage_valid_; a rejected attempt overwrites only k_[1..6].
  std::array<Eigen::VectorXd, kStages> k_;
  // Stages of the last accepted step (swapped in by on_accept, so a rejected
  // attempt never touches them) and its step size, for dense output.
  std::array<Eigen::VectorXd, kStages> accepted_k_;
  double accepted_h_ = 0.0;
  bool has_accepted_step_ = false;
  bool first_stage_valid_ = false;
  Eigen::VectorXd stage_;
};

}  // namespace stiffsim
