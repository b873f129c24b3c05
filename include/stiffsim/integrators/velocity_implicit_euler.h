#pragma once
// Velocity-implicit Euler (seed: Drake's VelocityImplicitEulerIntegrator).
//
// Step h from (t_n, q_n, y_n), y = (v, z):
//   q+ = q_n + h N(q+) v+,   y+ = y_n + h f_y(t+, q+, y+).
// Newton runs on y only, with N lagged one iterate:
//   q_{k+1} = q_n + h N(q_k) v_{k+1}.
// Newton matrix: the mass-matrix form
//   W = [ M - h D - h^2 K N(q_k)     -h dF/dz ]
//       [ -h dfz/dv - h^2 dfz/dq N     I - h dfz/dz ]
// (default; sparse, symmetric for conservative particles) or Drake's generic
// A = I - h J_l. The residual is always exact; only the matrix may lag.
//
// Error estimate: the full step x_big, then two half steps x_small; the
// half-step result is propagated and err = x_big - x_small, which equals the
// local error of x_small to O(h^3) (order 2). The full step is tried first
// because it fails to converge more often. Without an estimate (fixed-step
// mode, error_estimate off) one Newton solve per step. "vie2" propagates the
// local extrapolation 2 x_small - x_big instead (second order, same three
// solves).

#include "stiffsim/integrators/implicit_integrator.h"

namespace stiffsim {

class VelocityImplicitEuler : public ImplicitIntegrator {
 public:
  VelocityImplicitEuler(const System& system, IntegratorSettings settings,
                        ImplicitSettings implicit);
  std::string method_name() const override { return extrapolating() ? "vie2" : "vie"; }
  bool supports_error_estimation() const override { return true; }
  // x_big - x_small is O(h^2); with extrapolation it bounds the O(h^3) error
  // of 2 x_small - x_big from above, and the controller keeps its exponent.
  int error_estimate_order() const override { return 2; }

 protected:
  bool do_step(double h) override;
  void do_initialize() override;

  void compute_jacobian(double t, const Eigen::VectorXd& x, double h) override;
  bool jacobian_depends_on_step() const override { return true; }
  const SparseMatrix& form_iteration_matrix(double h, bool* symmetric) override;
  // q_{k+1} = q_n + h N(q_k) v_{k+1}: N lagged one iterate.
  void complete_iterate(double h, const Eigen::VectorXd& x0, Eigen::VectorXd* x) override;
  int unknowns_offset() const override { return dims_.nq; }
  // Residual of the y equations at the current iterate (q, y); in the
  // mass-matrix form the v rows are M(q) (v - v_n) - h F.
  void residual(double t, double h, const Eigen::VectorXd& x0, const Eigen::VectorXd& x,
                Eigen::VectorXd* r) override;
  double merit(const Eigen::VectorXd& r) const override;
  double residual_norm(const Eigen::VectorXd& r) const override;
  const Eigen::VectorXd& residual_scaling() override;
  const Eigen::VectorXd& predictor(double h, const Eigen::VectorXd& x0) override;
  bool has_potential() const override { return use_potential_merit_; }
  double guess_potential(double t0, double h, const Eigen::VectorXd& x0,
                         const Eigen::VectorXd& x) override;
  void begin_newton(double t0, double h, const Eigen::VectorXd& x0) override;
  bool potential_search(int trial) const override;
  double potential(double t, const Eigen::VectorXd& x0, const Eigen::VectorXd& x, double h,
                   bool new_iterate, bool jacobian_at_x = false) override;
  double potential_roundoff(double g) const override;
  // Whether form_iteration_matrix() assembles W in one pass (shared_pattern_).
  bool assembles_in_one_pass() const { return shared_pattern_; }

 private:
  // G_k(v) = 1/2 (v - v_n)^T M (v - v_n) + Phi(q_n + h v) - h/2 v^T D_k v,
  // or without its last term (damping false: no damping matrix needed).
  double incremental_potential(double t, const Eigen::VectorXd& x0, const Eigen::VectorXd& x,
                               double h, bool damping = true);
  // The damping matrix at the current iterate that enters the potential.
  void evaluate_damping(double t, const Eigen::VectorXd& x);
  // mass_diagonal_ for the step from x0 (nullptr unless M is diagonal).
  void load_mass_diagonal(const Eigen::VectorXd& x0);
  // The first Newton iterate of a fixed step of size h from the current
  // state, given the predictor's: whichever of the point
  // ImplicitSettings::predictor_share of the way to it and the step's
  // start (v = v_n) is the lower point of the incremental potential.
  const Eigen::VectorXd& first_iterate(double h, const Eigen::VectorXd& predicted);
  const double* mass_diagonal_ = nullptr;
  bool use_potential_merit_ = false;
  Eigen::VectorXd predicted_;  // predictor()'s result
  Eigen::VectorXd start_iterate_;  // first_iterate()'s v = v_n
  Eigen::VectorXd shared_iterate_;  // ... and its point toward the predictor
  Eigen::VectorXd guess_iterate_;  // guess_potential()'s completed iterate
  // Fixed steps without an estimate: the last step's local error estimate
  // |v - v_pred| / 2 (see do_step()) and the step it was taken with.
  double step_error_ = 0.0, step_error_h_ = 0.0;
  // ... and that step's velocity change |v - v_n| (infinity norm), against
  // which first_iterate() judges the predictor.
  double step_change_ = 0.0;
  static constexpr double kTrustedPredictorMiss = 0.1;
  double g_scale_ = 0.0;       // energy magnitude, for the round-off of G
  ForceJacobians merit_jacobians_;
  // D_k of G_k: merit_jacobians_.dF_dv, or jacobians_.dF_dv where those
  // were evaluated at the iterate (potential()).
  const SparseMatrix* damping_matrix_ = nullptr;
  State energy_state_;
  Eigen::VectorXd dv_;

  // Workspaces, sized once in do_initialize().
  SparseMatrix iteration_matrix_;
  std::vector<int> slots_M_, slots_D_, slots_K_, slots_Fz_, slots_Zq_, slots_Zv_, slots_Zz_;
  // D and K fill W's pattern in its own order, with no z states: the
  // mass-matrix form is assembled in one pass (form_iteration_matrix()).
  bool shared_pattern_ = false;
  std::vector<int> identity_slots_;  // diagonal of the z (or generic) block
  SparseMatrix N_;                   // N(q_k) when N != I
  SparseMatrix KN_, ZqN_;
  std::vector<int> product_marker_;  // multiply_into_pattern()'s scratch
  Eigen::VectorXd residual_state_, qdot_, F_, zdot_;  // residual_state_: (q_n + h N v, v, z)
};

}  // namespace stiffsim
