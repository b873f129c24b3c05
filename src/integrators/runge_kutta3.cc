#include "stiffsim/integrators/runge_kutta3.h"

namespace stiffsim {

RungeKutta3::RungeKutta3(const System& system, IntegratorSettings settings)
    : IntegratorBase(system, settings) {}

void RungeKutta3::do_initialize() {
  for (Eigen::VectorXd* k : {&k1_, &k2_, &k3_, &k4_, &stage_}) k->resize(dims_.nx());
  first_stage_valid_ = false;
}

bool RungeKutta3::do_step(double h) {
  const double t = state_.t;
  const Eigen::VectorXd& x = state_.x;
  if (!first_stage_valid_) {
    evaluate_state_derivative(t, x, &k1_);
    first_stage_valid_ = true;
  }
  stage_ = x + (0.5 * h) * k1_;
  evaluate_state_derivative(t + 0.5 * h, stage_, &k2_);
  stage_ = x + (0.75 * h) * k2_;
  evaluate_state_derivative(t + 0.75 * h, stage_, &k3_);
  candidate_ = x + h * ((2.0 / 9.0) * k1_ + (1.0 / 3.0) * k2_ + (4.0 / 9.0) * k3_);
  // Project before the last stage so that it is f at the state the next step
  // starts from, and FSAL stays exact.
  if (caps_.has_quaternions) system_.project_positions(candidate_.segment(0, dims_.nq));
  evaluate_state_derivative(t + h, candidate_, &k4_);
  if (estimating_error()) {
    error_ = h * ((-5.0 / 72.0) * k1_ + (1.0 / 12.0) * k2_ + (1.0 / 9.0) * k3_ - 0.125 * k4_);
  }
  return true;
}

void RungeKutta3::on_accept(double h) {
  (void)h;
  k1_.swap(k4_);
}

}  // namespace stiffsim
