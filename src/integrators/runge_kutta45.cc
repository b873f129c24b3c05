#include "stiffsim/integrators/runge_kutta45.h"

namespace stiffsim {
namespace {

// Dormand-Prince tableau (Hairer, Norsett & Wanner, Table II.5.2).
constexpr double c2 = 1.0 / 5, c3 = 3.0 / 10, c4 = 4.0 / 5, c5 = 8.0 / 9;
constexpr double a21 = 1.0 / 5;
constexpr double a31 = 3.0 / 40, a32 = 9.0 / 40;
constexpr double a41 = 44.0 / 45, a42 = -56.0 / 15, a43 = 32.0 / 9;
constexpr double a51 = 19372.0 / 6561, a52 = -25360.0 / 2187, a53 = 64448.0 / 6561,
                 a54 = -212.0 / 729;
constexpr double a61 = 9017.0 / 3168, a62 = -355.0 / 33, a63 = 46732.0 / 5247, a64 = 49.0 / 176,
                 a65 = -5103.0 / 18656;
// Fifth-order weights (= the last row of A, which is what makes FSAL work).
constexpr double b1 = 35.0 / 384, b3 = 500.0 / 1113, b4 = 125.0 / 192, b5 = -2187.0 / 6784,
                 b6 = 11.0 / 84;
// Fifth- minus fourth-order weights.
constexpr double e1 = 71.0 / 57600, e3 = -71.0 / 16695, e4 = 71.0 / 1920, e5 = -17253.0 / 339200,
                 e6 = 22.0 / 525, e7 = -1.0 / 40;
// Continuous extension (DOPRI5's CONTD5 coefficients d1..d7; d2 = 0).
constexpr double d1 = -12715105075.0 / 11282082432, d3 = 87487479700.0 / 32700410799,
                 d4 = -10690763975.0 / 1880347072, d5 = 701980252875.0 / 199316789632,
                 d6 = -1453857185.0 / 822651844, d7 = 69997945.0 / 29380423;

}  // namespace

RungeKutta45::RungeKutta45(const System& system, IntegratorSettings settings)
    : IntegratorBase(system, settings) {}

void RungeKutta45::do_initialize() {
  for (int i = 0; i < kStages; ++i) {
    k_[i].resize(dims_.nx());
    accepted_k_[i].resize(dims_.nx());
  }
  stage_.resize(dims_.nx());
  first_stage_valid_ = false;
  has_accepted_step_ = false;
}

bool RungeKutta45::do_step(double h) {
  const double t = state_.t;
  const Eigen::VectorXd& x = state_.x;
  auto& k = k_;
  if (!first_stage_valid_) {
    evaluate_state_derivative(t, x, &k[0]);
    first_stage_valid_ = true;
  }
  stage_ = x + (h * a21) * k[0];
  evaluate_state_derivative(t + c2 * h, stage_, &k[1]);
  stage_ = x + h * (a31 * k[0] + a32 * k[1]);
  evaluate_state_derivative(t + c3 * h, stage_, &k[2]);
  stage_ = x + h * (a41 * k[0] + a42 * k[1] + a43 * k[2]);
  evaluate_state_derivative(t + c4 * h, stage_, &k[3]);
  stage_ = x + h * (a51 * k[0] + a52 * k[1] + a53 * k[2] + a54 * k[3]);
  evaluate_state_derivative(t + c5 * h, stage_, &k[4]);
  stage_ = x + h * (a61 * k[0] + a62 * k[1] + a63 * k[2] + a64 * k[3] + a65 * k[4]);
  evaluate_state_derivative(t + h, stage_, &k[5]);
  candidate_ = x + h * (b1 * k[0] + b3 * k[2] + b4 * k[3] + b5 * k[4] + b6 * k[5]);
  // Project before the last stage so that it is f at the state the next step
  // starts from, and FSAL stays exact.
  if (caps_.has_quaternions) system_.project_positions(candidate_.segment(0, dims_.nq));
  evaluate_state_derivative(t + h, candidate_, &k[6]);
  if (estimating_error()) {
    error_ = h * (e1 * k[0] + e3 * k[2] + e4 * k[3] + e5 * k[4] + e6 * k[5] + e7 * k[6]);
  }
  return true;
}

void RungeKutta45::on_accept(double h) {
  // Keep the accepted stages for dense output (pointer swaps), then start
  // the next step from the last of them.
  for (int i = 0; i < kStages; ++i) k_[i].swap(accepted_k_[i]);
  k_[0] = accepted_k_[kStages - 1];
  accepted_h_ = h;
  has_accepted_step_ = true;
}

bool RungeKutta45::do_interpolate(double t, Eigen::VectorXd* x) {
  if (!has_accepted_step_) return false;
  // CONTD5 evaluates y0 + s (dy + s1 (h k1 - dy + s ((2 dy - h k1 - h k7)
  // + s1 h sum d_i k_i))), dy = y1 - y0, s1 = 1 - s; expanded here into one
  // weight per vector so Eigen forms the sum in a single pass.
  const double s = (t - previous_.t) / accepted_h_, s1 = 1.0 - s;
  const double ss1 = s * s1, s2s1 = s * ss1, s2s12 = s2s1 * s1;
  const double wy = s * s + 2.0 * s2s1;
  const double w1 = ss1 - s2s1 + s2s12 * d1;
  const double w7 = -s2s1 + s2s12 * d7;
  const auto& k = accepted_k_;
  const double h = accepted_h_;
  *x = previous_.x + wy * (state_.x - previous_.x) +
       h * (w1 * k[0] + (s2s12 * d3) * k[2] + (s2s12 * d4) * k[3] + (s2s12 * d5) * k[4] +
            (s2s12 * d6) * k[5] + w7 * k[6]);
  return true;
}

}  // namespace stiffsim
