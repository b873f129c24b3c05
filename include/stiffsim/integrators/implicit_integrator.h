#pragma once
// What implicit methods share (DESIGN.md sections 2-4): Jacobian schemes, the
// four-trial reuse ladder, the Hairer-style Newton convergence test and the
// linear solver behind the iteration matrix. Subclasses hold only their
// method.

#include <string>

#include "stiffsim/integrators/integrator_base.h"
#include "stiffsim/linalg/linear_solver.h"

namespace stiffsim {

enum class JacobianScheme { kAnalytic, kForward, kCentral, kAutomatic };
JacobianScheme parse_jacobian_scheme(const std::string& name);  // "analytic", ...
std::string to_string(JacobianScheme scheme);

enum class NewtonForm {
  kMassMatrix,  // W = M - h D - h^2 K N (v rows scaled by M): keeps sparsity and symmetry
  kGeneric,     // A = I - h J_l, J_l = dl/dy (Drake's form), for checking
};
NewtonForm parse_newton_form(const std::string& name);  // "mass-matrix" | "generic"
std::string to_string(NewtonForm form);

struct ImplicitSettings {
  JacobianScheme jacobian = JacobianScheme::kAnalytic;
  LinearSolverKind linear_solver = LinearSolverKind::kAuto;
  NewtonForm newton_form = NewtonForm::kMassMatrix;
  bool full_newton = false;  // fresh Jacobian and factorization every iteration
  bool reuse = true;         // false: fresh Jacobian and factorization every step attempt
  int max_newton_iterations = 10;
  // Newton stops when eta |dx| <= kappa * accuracy (Hairer & Wanner IV.8);
  // 0.05 is the middle of their recommended [0.01, 0.1].
  double newton_kappa = 0.05;
  // Iteration matrices may use the definite spring approximation
  // (JacobianRequest::definite) so CHOLMOD's LL^T keeps working.
  bool definite_iteration_matrix = true;
  // In passive scenes (Capabilities::passive) a Newton solution whose energy
  // exceeds the step's initial energy is rejected as a spurious root.
  bool energy_guard = true;
};

class ImplicitIntegrator : public IntegratorBase {
 public:
  ImplicitIntegrator(const System& system, IntegratorSettings settings, ImplicitSettings implicit);
  IntegratorReport report() const override;
  const ImplicitSettings& implicit_settings() const { return implicit_; }

 protected:
  enum class Convergence { kConverged, kDiverged, kNotYet };
  // The test of DESIGN.md section 2 / Drake's CheckNewtonConvergence, on the
  // weighted norm of the full-state change dx. `iteration` counts from 0.
  Convergence check_newton_convergence(int iteration, const Eigen::VectorXd& x,
                                       const Eigen::VectorXd& dx, double dx_norm,
                                       double last_dx_norm);
  double newton_tolerance() const { return implicit_.newton_kappa * settings_.accuracy; }
  bool reuse_enabled() const { return implicit_.reuse && !implicit_.full_newton; }

  // Evaluates dF/dq, dF/dv, ... at (t, x) into jacobians_ by the configured
  // scheme, counting jacobian_evaluations and the derivative evaluations it
  // used.
  void compute_force_jacobians(double t, const Eigen::VectorXd& x);
  // Chooses, analyzes (once) and factors the iteration matrix; counts
  // factorizations. Returns false if the matrix is singular.
  bool factor_iteration_matrix(const SparseMatrix& matrix, bool symmetric);
  // dx = A^-1 rhs with the current factorization.
  void solve_iteration_matrix(const Eigen::VectorXd& rhs, Eigen::VectorXd* dx);
  bool iteration_matrix_factored() const { return factored_; }
  void invalidate_factorization() { factored_ = false; }

  const ImplicitSettings implicit_;
  ForceJacobians jacobians_;
  bool jacobians_valid_ = false;

 private:
  LinearSolverChoice solver_;
  bool factored_ = false;
};

}  // namespace stiffsim
