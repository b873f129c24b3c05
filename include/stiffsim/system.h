#pragma once
// The problem every integrator sees (DESIGN.md section 1):
//   q_dot = N(q) v,   M(q) v_dot = F(t, q, v, z),   z_dot = f_z(t, q, v, z).
// A System evaluates these pieces and says what it can do, so integrators can
// leave out the work a scene does not need.

#include <Eigen/Core>
#include <array>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "stiffsim/drawing.h"
#include "stiffsim/linalg/sparse_pattern.h"
#include "stiffsim/point_kinematics.h"
#include "stiffsim/state.h"

namespace stiffsim {

class StructuredNewtonMatrix;

using VectorRef = Eigen::Ref<Eigen::VectorXd>;
using ConstVectorRef = Eigen::Ref<const Eigen::VectorXd>;

struct Capabilities {
  bool identity_velocity_map = false;  // N(q) = I (then nq == nv): no N products at all
  bool constant_mass_matrix = false;   // M assembled once per run
  bool diagonal_mass_matrix = false;   // M diagonal: M^-1 is a division
  bool symmetric_jacobians = false;    // dF/dq and dF/dv symmetric (conservative particles)
  bool analytic_jacobians = false;     // force_jacobians() implemented
  bool automatic_jacobians = false;    // automatic_force_jacobians() implemented
  bool has_quaternions = false;        // q holds unit quaternions: project after each step
  bool has_energy = false;             // energy() defined
  // Every force is conservative (in energy()) or dissipative, so the true
  // motion never gains energy.
  bool passive = false;
  // momentum_residual() evaluates M(q) dv - h F without forming M.
  bool momentum_residual = false;
};

// Force Jacobians, each with a pattern that is fixed for the lifetime of the
// system (the values change, the structure never does).
struct ForceJacobians {
  SparseMatrix dF_dq;   // K: nv x nq
  SparseMatrix dF_dv;   // D: nv x nv
  SparseMatrix dF_dz;   // nv x nz
  SparseMatrix dfz_dq;  // nz x nq
  SparseMatrix dfz_dv;  // nz x nv
  SparseMatrix dfz_dz;  // nz x nz
  // Terms the system replaced by a definite approximation on request (see
  // JacobianRequest::definite); 0 for exact Jacobians.
  long approximated_terms = 0;
};

struct JacobianRequest {
  // Allow an approximation that keeps -dF/dq positive semidefinite where the
  // exact Jacobian is not (a compressed spring's transverse stiffness
  // k (1 - L/l) < 0 clamped at 0, Choi & Ko 2002). Only for iteration
  // matrices: the residual always stays exact, so the converged answer is
  // unchanged.
  bool definite = false;
  // Include every term, even ones a system drops by default for symmetry (the
  // particle model's damping force depends on q through the spring direction;
  // MODELS.md allows dropping it from dF/dq). For checking and for methods
  // that need the true Jacobian; iteration matrices may do without.
  bool complete = false;
  // When set (nv values a), the Jacobians are those of F(q, v) - M(q) a at
  // this fixed a. Newton on M(q)(v - v_n) = h F needs the derivative of
  // M(q) dv through q as well as K; with dv ~ h a this is the same order as
  // h^2 K, and without it a chain's Newton converges linearly (rate ~0.2).
  // Systems with a constant mass matrix ignore it.
  const double* acceleration = nullptr;
  // When set (nq positions p), each spring's tension T in the transverse
  // stiffness T/l (I - u u^T) is estimated from p rather than taken as
  // k (l - L) at q: k (l_p - L), or with tension_carried the tension at p
  // carried to q along p's direction, k (u_p . d - L). This is the
  // primal-dual estimate of a stiff spring's force (Tournier et al. 2015,
  // "Stable constrained dynamics"): Newton on (v, lambda) updates lambda by
  // the linearized length, where k (l - L) at a new iterate counts the
  // second-order stretch of its transverse motion, k theta^2 L / 2, as
  // tension. Only for iteration matrices: the residual stays exact.
  const double* tension_positions = nullptr;
  bool tension_carried = false;
  // definite and tension_positions change dF/dq only: dF/dv is the same
  // whatever they say (an integrator takes the damping matrix from an
  // iteration matrix's Jacobians).
};

// The workspace of a System's evaluations: a System is an immutable model,
// and everything an evaluation writes besides its outputs (the recursions'
// workspaces, scratch matrices, a scene's components' own data) lives in a
// SystemData that the system's make_data() creates. Whoever evaluates owns
// one (every integrator and Jacobian evaluator does, per system), so
// evaluations allocate nothing once each kind has run (a few workspaces,
// such as the Jacobians' derivative passes, are made in the data on their
// first use) and one system serves several threads, each with its own
// data. A data fits only the system that made it (debug builds check).
class SystemData {
 public:
  virtual ~SystemData() = default;
};

class System {
 public:
  virtual ~System() = default;

  // A workspace for this system's evaluations (see SystemData). The default
  // holds nothing: a system whose evaluations need no scratch. Every
  // evaluation below takes the caller's data first; the maps that need no
  // scratch (q_dot = N v, projection, a point's kinematics into the
  // caller's PointKinematics) take none.
  virtual std::unique_ptr<SystemData> make_data() const;

  virtual Dimensions dimensions() const = 0;
  virtual Capabilities capabilities() const = 0;
  virtual std::string name() const = 0;

  // Initial state at t = 0 as the model defines it.
  virtual State initial_state() const = 0;

  // Column names of the trajectory CSV (DESIGN.md section 8), without the
  // "q:" / "v:" / "z:" prefixes. Sizes nq, nv, nz.
  virtual std::vector<std::string> position_names() const = 0;
  virtual std::vector<std::string> velocity_names() const = 0;
  virtual std::vector<std::string> misc_names() const { return {}; }

  // --- Kinematics: q_dot = N(q) v. The defaults are N = I. ---
  virtual void map_velocity_to_qdot(const ConstVectorRef& q, const ConstVectorRef& v,
                                    VectorRef qdot) const;
  // Pattern of N (nq x nv), fixed.
  virtual const SparseMatrix& velocity_map_pattern() const;
  // Values of N(q) written into a matrix with velocity_map_pattern().
  virtual void velocity_map(SystemData&, const ConstVectorRef& q, SparseMatrix* N) const;
  // Restores invariants of q after a step (unit quaternions). Returns true if
  // q changed.
  virtual bool project_positions(VectorRef q) const {
    (void)q;
    return false;
  }

  // --- Mass matrix M(q), nv x nv, symmetric positive definite. ---
  virtual const SparseMatrix& mass_matrix_pattern() const = 0;
  virtual void mass_matrix(SystemData&, const ConstVectorRef& q, SparseMatrix* M) const = 0;

  // --- Forces F (size nv) and f_z (size nz). ---
  virtual void forces(SystemData&, double t, const ConstVectorRef& q, const ConstVectorRef& v,
                      const ConstVectorRef& z, VectorRef F) const = 0;
  virtual void misc_derivatives(SystemData&, double t, const ConstVectorRef& q,
                                const ConstVectorRef& v, const ConstVectorRef& z,
                                VectorRef zdot) const {
    (void)t, (void)q, (void)v, (void)z, (void)zdot;
  }

  // r = M(q) dv - h F(t, q, v, z), the momentum rows of a velocity-implicit
  // residual; only called when capabilities().momentum_residual (an
  // articulated tree: one inverse-dynamics pass, no mass matrix).
  virtual void momentum_residual(SystemData&, double t, const ConstVectorRef& q,
                                 const ConstVectorRef& v, const ConstVectorRef& z,
                                 const ConstVectorRef& dv, double h, VectorRef r) const;
  // A Newton matrix this system factors by its own structure (see
  // structured_newton_matrix.h), or null when it has none.
  virtual std::unique_ptr<StructuredNewtonMatrix> make_structured_newton_matrix() const;

  // --- Jacobians with fixed patterns. ---
  // Matrices sized and structured as force_jacobians() fills them.
  virtual const ForceJacobians& jacobian_pattern() const = 0;
  // Analytic values; only called when capabilities().analytic_jacobians.
  virtual void force_jacobians(SystemData&, double t, const ConstVectorRef& q,
                               const ConstVectorRef& v, const ConstVectorRef& z,
                               const JacobianRequest& request, ForceJacobians* J) const;
  // The exact Jacobians of forces() and misc_derivatives() by forward-mode
  // automatic differentiation; only called when
  // capabilities().automatic_jacobians. The result is complete and exact by
  // construction (approximated_terms = 0): request.definite and
  // request.complete do not apply to it.
  virtual void automatic_force_jacobians(SystemData&, double t, const ConstVectorRef& q,
                                         const ConstVectorRef& v, const ConstVectorRef& z,
                                         const JacobianRequest& request, ForceJacobians* J) const;

  // A colouring of the columns of x = (q, v, z) for finite-difference
  // Jacobians that the system knows from its structure (a lattice), one
  // colour per column, -1 for columns without entries; empty when it knows
  // none. JacobianEvaluator checks it and uses it when it needs fewer colours
  // than its greedy colouring.
  virtual std::vector<int> jacobian_colouring_hint() const { return {}; }
  // Pairs of points whose coupling in the Newton matrix a solver may leave
  // out of a factorization it uses as an approximation (a preconditioner,
  // a chord's matrix): each pair (the first velocity index of each point's
  // three) is coupled by exactly one force element that depends on the
  // difference of their positions and velocities alone (a spring), whose
  // stiffness and damping are covered, within a factor of
  // kCoverageRatio, by stiffer elements along a path between the two
  // points in the same direction. Such an element's block of the Newton
  // matrix, [S -S; -S S], then lies below 2 / kCoverageRatio times the
  // blocks of the path, so removing it whole (coupling and diagonal
  // share) changes the matrix by that fraction at most. Empty by default.
  virtual std::vector<std::array<int, 2>> covered_couplings() const { return {}; }
  static constexpr double kCoverageRatio = 10.0;

  // Material points that forces between components can act on
  // (point_kinematics.h): their number (particle nodes, bodies of a tree;
  // 0 when the system offers none), the most dofs one of them moves with,
  // and one point's kinematics: `element` with the offset `local` in its
  // frame, at (t, q, v). Position coordinates without a velocity of their
  // own (a quaternion) get their own columns; allocates nothing when `out`
  // has room for point_dofs(element) entries in each of its lists.
  virtual int point_elements() const { return 0; }
  virtual int point_dofs(int element) const {
    (void)element;
    return 0;
  }
  virtual void point_kinematics(double t, int element, const Eigen::Vector3d& local,
                                const ConstVectorRef& q, const ConstVectorRef& v,
                                PointKinematics* out) const;

  // The system's picture at (t, q, v) (drawing.h) into *out; false, with
  // *out untouched, for a system with no geometry (a pure ODE).
  virtual bool draw(double t, const ConstVectorRef& q, const ConstVectorRef& v,
                    const DrawingRequest& request, ComponentDrawing* out) const {
    (void)t, (void)q, (void)v, (void)request, (void)out;
    return false;
  }

  // Total energy (kinetic + potential) where defined, NaN otherwise.
  virtual double energy(SystemData&, const State& s) const {
    (void)s;
    return std::numeric_limits<double>::quiet_NaN();
  }

  // --- The same evaluations on a workspace made for the one call. ---
  // For tests, reports and one-off queries: each call allocates a data, so
  // nothing that steps uses them. A derived class re-exports them with
  // `using System::forces;` and the like.
  void velocity_map(const ConstVectorRef& q, SparseMatrix* N) const {
    velocity_map(*make_data(), q, N);
  }
  void mass_matrix(const ConstVectorRef& q, SparseMatrix* M) const {
    mass_matrix(*make_data(), q, M);
  }
  void forces(double t, const ConstVectorRef& q, const ConstVectorRef& v, const ConstVectorRef& z,
              VectorRef F) const {
    forces(*make_data(), t, q, v, z, F);
  }
  void misc_derivatives(double t, const ConstVectorRef& q, const ConstVectorRef& v,
                        const ConstVectorRef& z, VectorRef zdot) const {
    misc_derivatives(*make_data(), t, q, v, z, zdot);
  }
  void momentum_residual(double t, const ConstVectorRef& q, const ConstVectorRef& v,
                         const ConstVectorRef& z, const ConstVectorRef& dv, double h,
                         VectorRef r) const {
    momentum_residual(*make_data(), t, q, v, z, dv, h, r);
  }
  void force_jacobians(double t, const ConstVectorRef& q, const ConstVectorRef& v,
                       const ConstVectorRef& z, const JacobianRequest& request,
                       ForceJacobians* J) const {
    force_jacobians(*make_data(), t, q, v, z, request, J);
  }
  void automatic_force_jacobians(double t, const ConstVectorRef& q, const ConstVectorRef& v,
                                 const ConstVectorRef& z, const JacobianRequest& request,
                                 ForceJacobians* J) const {
    automatic_force_jacobians(*make_data(), t, q, v, z, request, J);
  }
  double energy(const State& s) const { return energy(*make_data(), s); }
};

// Builds an empty ForceJacobians with the right sizes for `d` (all patterns
// empty): a starting point for systems that fill only some blocks.
ForceJacobians empty_jacobians(const Dimensions& d);

}  // namespace stiffsim
