#pragma once
// Force Jacobians [dF/dq dF/dv dF/dz; dfz/dq dfz/dv dfz/dz] at x = (q, v, z)
// by any JacobianScheme (DESIGN.md section 4). Finite differences perturb the
// columns of one colour of the stacked pattern together (column_colouring.h),
// so a chain or a cloth costs a number of evaluations of (F, f_z) set by its
// stencil, not by its size, where Drake's dense differences cost one per
// state.

#include <Eigen/Core>
#include <vector>

#include "stiffsim/integrators/jacobian_scheme.h"
#include "stiffsim/linalg/column_colouring.h"
#include "stiffsim/system.h"

namespace stiffsim {

class JacobianEvaluator {
 public:
  // For differences, colours the system's jacobian_pattern() and allocates
  // every workspace, so evaluate() allocates nothing. Throws InputError when the system lacks
  // what the scheme needs (analytic: capabilities().analytic_jacobians;
  // automatic: capabilities().automatic_jacobians). The system must outlive
  // the evaluator.
  JacobianEvaluator(const System& system, JacobianScheme scheme);

  // Writes the Jacobians at (t, x), x = (q, v, z) of the system's
  // Dimensions, into J, which must have the structure of
  // system.jacobian_pattern() (kept as it is: only values change). Returns
  // the evaluations of (F, f_z) used (one evaluation is forces() plus
  // misc_derivatives() when nz > 0), for derivative_evaluations_for_jacobian:
  //   analytic   0              system.force_jacobians(request)
  //   forward    1 + colours()  Drake's increment sqrt(eps) max(1, |x_j|);
  //                             error ~ sqrt(eps)
  //   central    2 colours()    increment eps^(5/12) max(1, |x_j|); no base
  //                             evaluation (Drake's 2n + 1 evaluates one it
  //                             never uses); error ~ eps^(2/3)
  //   automatic  0              system.automatic_force_jacobians(): one pass
  //                             of F with derivative lanes (about the cost
  //                             of one evaluation; Drake counts it as one)
  // (0 for differences too when the pattern is empty.) Differences and AD
  // give the complete Jacobian: request.definite and request.complete only
  // concern analytic, and their approximated_terms is 0.
  int evaluate(double t, const Eigen::VectorXd& x, const JacobianRequest& request,
               ForceJacobians* J);

  JacobianScheme scheme() const { return scheme_; }
  // Colours of the stacked pattern over x (0 for analytic and automatic,
  // which do not difference).
  int colours() const { return differences_ ? colouring_.colours : 0; }
  // What evaluate() returns, known in advance.
  int evaluations_per_jacobian() const;

 private:
  // (F, f_z) at (t, x) into f, both stacked as in the Jacobian's rows.
  void evaluate_rates(double t, const Eigen::VectorXd& x, Eigen::VectorXd* f);
  // For every column j of colour `colour`: writes (f_plus - f_minus) / step_j
  // into the stored entries of column j in every block of J.
  void store_columns(int colour, const Eigen::VectorXd& f_plus, const Eigen::VectorXd& f_minus,
                     const Eigen::VectorXd& step, ForceJacobians* J) const;
  // Debug builds: the rows outside the pattern of the perturbed columns did
  // not move (so nothing is lost by writing only the pattern).
  void check_nothing_lost(int colour, const Eigen::VectorXd& f_plus,
                          const Eigen::VectorXd& f_minus);
  void check_structure(const ForceJacobians& J) const;
  // Reads and checks the system's pattern; colours it for differences.
  void prepare();
  bool prepared_ = false;

  const System& system_;
  const std::unique_ptr<SystemData> data_;  // the evaluations' workspace
  const JacobianScheme scheme_;
  const Dimensions dims_;
  const bool differences_;  // forward or central
  ColumnColouring colouring_;
  // Columns of x grouped by colour: colour c owns
  // columns_by_colour_[colour_start_[c], colour_start_[c + 1]).
  std::vector<int> colour_start_, columns_by_colour_;
  // JacobianRequest::acceleration of the evaluation in progress (differences
  // only), and M's scratch for it.
  const double* acceleration_ = nullptr;
  SparseMatrix mass_;
  // The pattern's structure, to check that J keeps it.
  std::vector<Eigen::Index> pattern_nonzeros_;
  // Workspaces: perturbed state, rates and exact increments.
  Eigen::VectorXd x_perturbed_, f_base_, f_plus_, f_minus_, step_plus_, step_minus_, step_sum_;
  // Debug check only: rows in the pattern of the current colour carry the
  // current stamp.
  std::vector<int> row_mark_;
  int mark_stamp_ = 0;
};

}  // namespace stiffsim
