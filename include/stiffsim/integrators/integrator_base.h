#pragma once
// What every integrator shares (DESIGN.md section 4): fixed-step and
// error-controlled stepping, the weighted error norm, step-size adaptation,
// minimum-step handling, dense output and statistics. Subclasses implement
// one step.

#include <Eigen/Core>
#include <limits>
#include <memory>
#include <string>

#include "stiffsim/integrators/integrator_statistics.h"
#include "stiffsim/linalg/linear_solver.h"
#include "stiffsim/state.h"
#include "stiffsim/system.h"

namespace stiffsim {

struct IntegratorSettings {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  double max_step = 0.01;      // error-controlled: largest step; fixed: the step
  double initial_step = kNaN;  // NaN: max_step
  double min_step = 0.0;       // requested minimum (the working minimum is never below 1e-14 |t|)
  bool fixed_step = false;
  // Fixed-step mode: also compute the error estimate (it costs the method's
  // extra work, e.g. two half steps for VIE). Error-controlled mode always
  // estimates.
  bool error_estimate = false;
  double accuracy = 1e-3;  // target of the weighted infinity norm of the local error
  bool throw_on_minimum_step = true;
};

class IntegratorBase {
 public:
  IntegratorBase(const System& system, IntegratorSettings settings);
  virtual ~IntegratorBase();
  IntegratorBase(const IntegratorBase&) = delete;
  IntegratorBase& operator=(const IntegratorBase&) = delete;

  virtual std::string method_name() const = 0;
  virtual bool supports_error_estimation() const = 0;
  // Order of the local error estimate (2 for VIE: error of O(h^2)).
  virtual int error_estimate_order() const = 0;
  // Explicit methods have no convergence failure to recover from by halving
  // the step: a non-finite fixed step means the method is unstable there, so
  // it throws at once instead of halving down to the minimum step.
  virtual bool is_explicit() const { return false; }

  // Sets the state, resets the statistics and the per-run workspaces.
  void initialize(const State& initial);

  // Takes one step that ends no later than t_limit (fixed or error-controlled
  // according to the settings). Throws IntegrationError when no step can be
  // taken (Newton divergence or non-finite state at the minimum step; for an
  // explicit method in fixed-step mode, the first non-finite step).
  void step_at_most(double t_limit);
  // Steps until t reaches t_final exactly.
  void integrate_to(double t_final);

  const State& state() const { return state_; }
  double previous_time() const { return previous_.t; }
  const State& previous_state() const { return previous_; }
  // Dense output over the last step [previous_time(), t]: the method's own
  // interpolant where it has one (do_interpolate), cubic Hermite otherwise.
  // The Hermite endpoint derivatives are evaluated lazily (once per step,
  // counted in statistics().dense_output_evaluations).
  void interpolate(double t, Eigen::VectorXd* x);

  const IntegratorStatistics& statistics() const { return stats_; }
  virtual IntegratorReport report() const;
  const IntegratorSettings& settings() const { return settings_; }
  const System& system() const { return system_; }
  const Dimensions& dims() const { return dims_; }
  // The error estimate of the last accepted step (empty if none was computed).
  const Eigen::VectorXd& error_estimate() const { return error_; }
  bool estimating_error() const;

 protected:
  // One step of size h from state() to candidate_; when estimating_error(),
  // also writes error_. Returns false on a convergence failure (the caller
  // shrinks h). May throw IntegrationError for unrecoverable trouble.
  virtual bool do_step(double h) = 0;
  // Called once by initialize() after the base is reset.
  virtual void do_initialize() {}
  // Called when the attempt of size h that do_step() just made is accepted
  // (state() already holds its result). Attempts that are rejected never get
  // here, so a method keeps per-step data (e.g. dense-output stages) from
  // the accepted step only.
  virtual void on_accept(double h) { (void)h; }
  // The method's own interpolant at t strictly inside the last accepted
  // step, into *x; false falls back to cubic Hermite.
  virtual bool do_interpolate(double t, Eigen::VectorXd* x) {
    (void)t, (void)x;
    return false;
  }

  // x_dot = (N(q) v, M^-1 F, f_z) at (t, x), counted as one derivative
  // evaluation (statistics().derivative_evaluations).
  void evaluate_state_derivative(double t, const Eigen::VectorXd& x, Eigen::VectorXd* xdot);
  // Weighted infinity norm of a state change (weights 1; position changes
  // measured in velocity coordinates through N^+ for quaternion blocks).
  double state_change_norm(const Eigen::VectorXd& dx) const;
  // Evaluates F (and f_z) into the given vectors, counting and timing it.
  void evaluate_forces(double t, const Eigen::VectorXd& x, Eigen::VectorXd* F,
                       Eigen::VectorXd* zdot);
  // Assembles M(q) into mass_matrix_ unless M is constant and already
  // there, or was assembled at this very q.
  const SparseMatrix& mass_matrix_at(const ConstVectorRef& q);
  // Solves M(q) a = F (a division for a diagonal M, otherwise a factorization
  // kept until M changes). t only names the time if M is singular. a may not
  // alias F.
  void solve_mass_matrix(double t, const ConstVectorRef& q, const Eigen::VectorXd& F,
                         Eigen::VectorXd* a);

  const System& system_;
  // The workspace of every evaluation of system_ (system.h: SystemData).
  const std::unique_ptr<SystemData> data_;
  const IntegratorSettings settings_;
  const Capabilities caps_;
  const Dimensions dims_;
  State state_;
  State previous_;
  Eigen::VectorXd candidate_;  // result of do_step
  Eigen::VectorXd error_;      // error estimate of do_step
  IntegratorStatistics stats_;

 private:
  bool try_step(double h);
  void accept(double h);
  double working_min_step() const;
  [[noreturn]] void fail_at_minimum(double h, const std::string& why) const;
  // Throws IntegrationError "<method>: <why> at t = .. s with step h = .. s
  // <detail>; largest state entries of the last attempt: ...".
  [[noreturn]] void fail_step(double h, const std::string& why, const std::string& detail) const;
  // Fixed explicit steps of a passive scene: throws when the candidate at t
  // has gained energy that no stable step could (watch_energy_).
  void check_energy_blow_up(double t, double h);

  SparseMatrix mass_matrix_;
  Eigen::VectorXd mass_q_;  // where mass_matrix_ was assembled
  bool mass_matrix_valid_ = false;
  std::unique_ptr<LinearSolver> mass_solver_;  // for M^-1 F when M is not diagonal
  bool mass_solver_factored_ = false;
  // Fixed-step explicit methods on passive scenes with an energy: the energy
  // at initialize(), to stop a slow blow-up (integrator_base.cc).
  bool watch_energy_ = false;
  double initial_energy_ = 0.0;
  State energy_workspace_;
  double ideal_next_step_ = std::numeric_limits<double>::quiet_NaN();
  bool at_minimum_ = false;
  // Dense output workspace.
  bool dense_valid_ = false;
  Eigen::VectorXd dense_f0_, dense_f1_;
  Eigen::VectorXd work_F_, work_zdot_, work_vdot_;
};

}  // namespace stiffsim
