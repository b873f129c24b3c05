#pragma once
// Full-state implicit Euler (seed: Drake's ImplicitEulerIntegrator; DESIGN.md
// section 3): Newton on all of x = (q, v, z),
//   g(x+) = x+ - x_n - h f(t+, x+) = 0,
// with the v rows scaled by M (the mass-matrix form) so no M^-1 is formed:
//   [ q - q_n - h N(q) v          ]        [ I      -h N      0          ]
//   [ M(q)(v - v_n) - h F         ],  A =  [ -h K   M - h D   -h dF/dz   ]
//   [ z - z_n - h f_z             ]        [ -h Zq  -h Zv     I - h Zz   ]
// (d(N v)/dq is left out of A: zero for N = I, a lagged term otherwise; the
// residual stays exact). A is nq + nv + nz square and unsymmetric, so it goes
// to UMFPACK (or dense LU when small): the same sparse machinery, reuse
// ladder, convergence test and step control as VIE, so that a comparison
// measures the formulation and nothing else.
//
// Error estimate: the implicit trapezoid rule fed by the IE result (default;
// its own iteration matrix I - h/2 J beside I - h J, the Jacobian shared; IE
// is propagated, err = x_ie - x_trapezoid = O(h^2)), or step doubling (two
// half steps propagated; "ie2" extrapolates them as vie2 does).

#include "stiffsim/integrators/implicit_integrator.h"

namespace stiffsim {

class ImplicitEuler : public ImplicitIntegrator {
 public:
  ImplicitEuler(const System& system, IntegratorSettings settings, ImplicitSettings implicit);
  std::string method_name() const override { return extrapolating() ? "ie2" : "ie"; }
  bool supports_error_estimation() const override { return true; }
  int error_estimate_order() const override { return 2; }
  IntegratorReport report() const override;

 protected:
  bool do_step(double h) override;
  void do_initialize() override;

  void compute_jacobian(double t, const Eigen::VectorXd& x, double h) override;
  bool jacobian_depends_on_step() const override { return true; }
  const SparseMatrix& form_iteration_matrix(double h, bool* symmetric) override;
  int unknowns_offset() const override { return 0; }
  void residual(double t, double h, const Eigen::VectorXd& x0, const Eigen::VectorXd& x,
                Eigen::VectorXd* r) override;
  double merit(const Eigen::VectorXd& r) const override;
  const Eigen::VectorXd& residual_scaling() override;
  void begin_newton(double t0, double h, const Eigen::VectorXd& x0) override;

 private:
  bool step_with_trapezoid_estimate(double h);
  bool uses_doubling() const;

  // theta = 1: implicit Euler; theta = 1/2: the trapezoid rule, whose
  // residual also needs x_dot at the step start (xdot0_).
  double theta_ = 1.0;
  Eigen::VectorXd xdot0_;
  const double* mass_diagonal_ = nullptr;
  double merit_step_ = 1.0;  // theta h of the current solve

  SparseMatrix iteration_matrix_;
  SparseMatrix N_;  // N(q) of the last Jacobian when N != I
  std::vector<int> slots_N_, slots_M_, slots_K_, slots_D_, slots_Fz_, slots_Zq_, slots_Zv_,
      slots_Zz_;
  std::vector<int> diagonal_slots_;
  Eigen::VectorXd x_ie_, x_trap_, qdot_, F_, zdot_, dv_;
};

}  // namespace stiffsim
