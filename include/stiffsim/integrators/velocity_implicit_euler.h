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
// mode, error_estimate off) one Newton solve per step.

#include "stiffsim/integrators/implicit_integrator.h"

namespace stiffsim {

class VelocityImplicitEuler : public ImplicitIntegrator {
 public:
  VelocityImplicitEuler(const System& system, IntegratorSettings settings,
                        ImplicitSettings implicit);
  std::string method_name() const override { return "vie"; }
  bool supports_error_estimation() const override { return true; }
  int error_estimate_order() const override { return 2; }

 protected:
  bool do_step(double h) override;
  void do_initialize() override;

 private:
  // Solves one implicit Euler step of size h from (t0, x0) starting at the
  // guess; the ladder runs trials 1..4. Result in *x.
  bool solve_step(double t0, double h, const Eigen::VectorXd& x0, const Eigen::VectorXd& guess,
                  Eigen::VectorXd* x);
  bool newton(double t0, double h, const Eigen::VectorXd& x0, const Eigen::VectorXd& guess,
              int trial, Eigen::VectorXd* x);
  // The refresh ladder: kSkip when the rung would rebuild the matrix that
  // just failed, kGiveUp at trial 4.
  enum class Refresh { kProceed, kSkip, kGiveUp };
  Refresh refresh_matrices(double t, const Eigen::VectorXd& x, double h, int trial);
  void compute_jacobian_and_factor(double t, const Eigen::VectorXd& x, double h);
  // Force Jacobians at (t, q + h N(q) v, y) for the state x.
  void compute_jacobian(double t, const Eigen::VectorXd& x, double h);
  bool form_and_factor(double h);
  // Residual of the y equations at the current iterate (q, y); in the
  // mass-matrix form the v rows are M(q) (v - v_n) - h F.
  void residual(double t, double h, const Eigen::VectorXd& x0, const Eigen::VectorXd& x,
                Eigen::VectorXd* r);

  // Trials 1-3 are the reuse ladder; trial 4 iterates with a fresh Jacobian
  // at every iterate before the step is given up.
  static constexpr int kFullNewtonTrial = 4;
  // Halvings of a Newton step before the iteration counts as diverged.
  static constexpr int kMaxBacktracks = 8;

  void advance_positions(double h, const Eigen::VectorXd& x0, Eigen::VectorXd* x);
  // Squared residual norm the line search decreases.
  double merit(const Eigen::VectorXd& r) const;
  const double* mass_diagonal_ = nullptr;
  // False when a converged step gained energy in a passive scene.
  bool passes_energy_guard(const Eigen::VectorXd& x0, const Eigen::VectorXd& x);
  bool guard_energy_ = false;
  State energy_state_;
  // The line search's incremental potential G_k and the damping matrix at
  // the current iterate that enters it.
  double incremental_potential(double t, const Eigen::VectorXd& x0, const Eigen::VectorXd& x,
                               double h);
  void evaluate_damping(double t, const Eigen::VectorXd& x);
  bool use_potential_merit_ = false;
  double g_scale_ = 0.0;  // energy magnitude, for the round-off of G
  ForceJacobians merit_jacobians_;
  Eigen::VectorXd dv_, Dv_;

  // Workspaces, sized once in do_initialize().
  SparseMatrix iteration_matrix_;
  std::vector<int> slots_M_, slots_D_, slots_K_, slots_Fz_, slots_Zq_, slots_Zv_, slots_Zz_;
  std::vector<int> identity_slots_;  // diagonal of the z (or generic) block
  double factored_h_ = 0.0;
  // Step start and h of the Jacobian the ladder last evaluated (NaN after a
  // full-Newton iterate replaced it).
  double jacobian_step_t_ = 0.0, jacobian_step_h_ = 0.0;
  SparseMatrix N_;  // N(q_k) when N != I
  SparseMatrix KN_, ZqN_;
  Eigen::VectorXd x_big_, x_half_, x_small_, guess_;
  Eigen::VectorXd x_trial_, r_trial_;
  Eigen::VectorXd r_, dy_, dx_, qdot_, F_, zdot_, q_prev_;
};

}  // namespace stiffsim
