#pragma once
// Articulated rigid bodies (MODELS.md "Articulated bodies from URDF") as a
// System, in either formulation:
// - exact: the RigidTree in reduced coordinates. M(q) by the composite rigid
//   body algorithm (composite_rigid_body.h), which touches only the pairs of
//   bodies on one branch (the tree's branch sparsity is M's pattern);
//   F = -C(q, v) - g(q) by the recursive Newton-Euler algorithm
//   (inverse_dynamics.h), plus the force elements' joint torques.
// - compliant (make_compliant in compliant.h): a forest of free bodies, each
//   with a floating joint to the world, held together by Bushings
//   (bushing.h); M is block diagonal and K, D are block tridiagonal for a
//   chain.
// This class holds what the two share: validation, patterns, drives, the
// root motion, names, energy and attachment points.
// Both are templated on the scalar: automatic_force_jacobians() differentiates
// F exactly by forward-mode automatic differentiation, seeded by a colouring
// of the Jacobian pattern (a chain of free bodies costs a few passes of F
// whatever its length, a dense exact tree about (nq + nv) / 16 passes), and
// checks the analytic derivatives of force_jacobians().

#include <Eigen/Core>
#include <array>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "stiffsim/model/articulated_data.h"
#include "stiffsim/model/articulated_model.h"
#include "stiffsim/model/bushing.h"
#include "stiffsim/model/bushing_element.h"
#include "stiffsim/model/generalized_element.h"
#include "stiffsim/model/joint_elements.h"
#include "stiffsim/model/path.h"
#include "stiffsim/model/rigid_tree.h"
#include "stiffsim/model/spatial.h"
#include "stiffsim/structured_newton_matrix.h"
#include "stiffsim/system.h"

namespace stiffsim {

// A PD drive on a 1-DOF joint of the exact formulation:
//   tau = kp (p(t) - q) + kd (p'(t) - q_dot),
// p the target path (path.h), its rate the velocity target; the system
// makes it a force element (JointDriveElement, joint_elements.h). Its
// stiffness and damping enter K and D (and the articulated-body pivots)
// like a joint spring's, so the drive is as implicit as the rest of the
// step; only kp p(t) + kd p'(t), which no state changes, is explicit.
struct JointDrive {
  int body = 0;  // the driven joint's body in the tree
  double kp = 0.0, kd = 0.0;
  ScalarPath target = ScalarPath::constant(0.0);
};

struct ArticulatedOptions {
  Eigen::Vector3d gravity{0.0, 0.0, -9.81};
  // Per body of the tree (empty: none). Only 1-DOF joints take a spring;
  // damping is added to the URDF's.
  std::vector<JointForce> joint_forces;
  // Compliant formulation only: every body a bushing touches must be a free
  // root (parent -1, floating, identity placement).
  std::vector<Bushing> bushings;
  // Exact formulation only; at most one per joint.
  std::vector<JointDrive> drives;
  // Exact formulation, every root welded to the world (revolute or
  // prismatic root joints): the world frame the tree hangs from translates
  // by d(t) = (x(t), y(t), z(t)) (paths with a continuous rate: constant or
  // sinusoid; a keyframed path's rate jumps, which would be an impulse on
  // the joints). The tree's dynamics in that translating frame are the
  // fixed-base ones with gravity g - d''(t), which is how it is evaluated;
  // q and v stay relative to the base, and so do energy(), kinetic_energy()
  // and world_momentum(). World positions (point_kinematics, the drawing)
  // add d(t), world velocities d'(t).
  std::optional<std::array<ScalarPath, 3>> root_motion;
  // The initial state (sizes nq and nv); empty: every joint at 0, identity
  // quaternions, at rest.
  Eigen::VectorXd initial_q, initial_v;
  std::string formulation = "exact";  // for the name in reports: exact | compliant
};

// The model (ArticulatedModel) is immutable; every evaluation writes into the
// caller's workspace (make_data(): the inverse dynamics', the composite
// rigid body algorithm's, and, made on their first use, the derivatives'
// and the dual numbers'), so evaluations allocate nothing after the first
// and one system serves any number of threads, each with its own data. The
// matrix patterns (dense for a long chain) are built on first use: a run on
// the articulated-body recursion never needs them.
class ArticulatedSystem : public System {
 public:
  // Validates the tree and options; throws InputError naming the component.
  ArticulatedSystem(RigidTree tree, ArticulatedOptions options);
  ~ArticulatedSystem() override;

  // The overloads without a workspace (system.h).
  using System::automatic_force_jacobians;
  using System::energy;
  using System::force_jacobians;
  using System::forces;
  using System::mass_matrix;
  using System::momentum_residual;
  using System::velocity_map;

  Dimensions dimensions() const override { return dims_; }
  Capabilities capabilities() const override;
  std::string name() const override { return model_.tree.name; }
  std::unique_ptr<SystemData> make_data() const override;
  State initial_state() const override;
  std::vector<std::string> position_names() const override;
  std::vector<std::string> velocity_names() const override;

  void map_velocity_to_qdot(const ConstVectorRef& q, const ConstVectorRef& v,
                            VectorRef qdot) const override;
  const SparseMatrix& velocity_map_pattern() const override { return velocity_map_pattern_; }
  void velocity_map(SystemData&, const ConstVectorRef& q, SparseMatrix* N) const override;
  bool project_positions(VectorRef q) const override;

  const SparseMatrix& mass_matrix_pattern() const override { return patterns().mass; }
  void mass_matrix(SystemData&, const ConstVectorRef& q, SparseMatrix* M) const override;
  void forces(SystemData&, double t, const ConstVectorRef& q, const ConstVectorRef& v,
              const ConstVectorRef& z, VectorRef F) const override;
  // M(q) dv - h F by one inverse-dynamics pass at the acceleration dv / h.
  void momentum_residual(SystemData&, double t, const ConstVectorRef& q, const ConstVectorRef& v,
                         const ConstVectorRef& z, const ConstVectorRef& dv, double h,
                         VectorRef r) const override;
  // Exact trees (no bushings): the articulated-body recursion.
  std::unique_ptr<StructuredNewtonMatrix> make_structured_newton_matrix() const override;
  const ForceJacobians& jacobian_pattern() const override { return patterns().jacobians; }
  // Exact K and D (complete: nothing dropped; request.acceleration
  // honoured), analytic: the recursive Newton-Euler derivatives
  // (rnea_derivatives.h) for trees without bushings, O(n d), the free
  // bodies' (forest_derivatives.h) with them, O(n); then the force
  // elements' (joint springs, drives, bushings), each O(1).
  // automatic_force_jacobians differentiates the same F by seeded forward
  // mode and checks both.
  void force_jacobians(SystemData&, double t, const ConstVectorRef& q, const ConstVectorRef& v,
                       const ConstVectorRef& z, const JacobianRequest& request,
                       ForceJacobians* J) const override;
  void automatic_force_jacobians(SystemData&, double t, const ConstVectorRef& q,
                                 const ConstVectorRef& v, const ConstVectorRef& z,
                                 const JacobianRequest& request, ForceJacobians* J) const override;
  double energy(SystemData&, const State& s) const override;
  // Bodies are points attachments can act on (a point fixed in the body's
  // frame), whatever their joints (point_kinematics.h: a planar joint moves
  // a point as two translations and a turn, a floating joint as three
  // translations and three turns, with its quaternion's own columns). In
  // the compliant formulation every body is a floating root; the bushings
  // between them are forces and move no point.
  int point_elements() const override;
  int point_dofs(int body) const override;
  void point_kinematics(double t, int body, const Eigen::Vector3d& local, const ConstVectorRef& q,
                        const ConstVectorRef& v, PointKinematics* out) const override;
  // Exact or compliant: one point per body at its frame's origin (in body
  // order), then one per joint anchored in the world (a root joint that is
  // not floating, or a compliant bushing whose parent is the world) at the
  // joint frame's origin, then one per leaf body whose centre of mass is
  // off its origin, at origin + 2 (COM - origin): the far end of a uniform
  // rod hung from its joint, so the last link of a chain is drawn too, then
  // one per request.hooks point on a body away from its origin (a box hung
  // by a corner reaches out to the corner); a base moved by a root motion
  // carries them all. Segments: each joint's parent point (body origin or
  // world anchor) to its child's origin, each leaf's origin to its tip and
  // each body's origin to its attachment points.
  bool draw(double t, const ConstVectorRef& q, const ConstVectorRef& v,
            const DrawingRequest& request, ComponentDrawing* out) const override;

  // --- For reports and tests. ---
  const RigidTree& tree() const { return model_.tree; }
  const ArticulatedModel& model() const { return model_; }
  const ArticulatedOptions& options() const { return options_; }
  // The force elements (generalized_element.h): every 1-DOF joint's spring
  // and damper (the URDF's damping plus the scene's spring and damper),
  // the drives, the bushings.
  const GeneralizedElementSet<JointSpringElement>& joint_springs() const {
    return elements_.joint_springs;
  }
  const GeneralizedElementSet<JointDriveElement>& drives() const { return elements_.drives; }
  const GeneralizedElementSet<BushingElement>& bushings() const { return elements_.bushings; }
  // Per body, the joint-local elements' stiffness and damping on its joint
  // (zero for joints with more than one coordinate): what the
  // articulated-body recursion folds into its pivots.
  const std::vector<double>& pivot_stiffness() const { return pivot_stiffness_; }
  const std::vector<double>& pivot_damping() const { return pivot_damping_; }
  // Where the root motion has moved the tree's base at t, and its velocity
  // (zero without one).
  Eigen::Vector3d root_displacement(double t) const;
  Eigen::Vector3d root_velocity(double t) const;
  int body_q_offset(int body) const { return model_.q_offset[body]; }
  int body_v_offset(int body) const { return model_.v_offset[body]; }
  // Poses of every body in the world; with a root motion, in the base's
  // frame (add root_displacement(t): the state alone does not know t).
  std::vector<Pose<double>> world_poses(const Eigen::VectorXd& q) const;
  // Spatial velocity of every body in its own coordinates.
  std::vector<Vec6<double>> body_velocities(const Eigen::VectorXd& q,
                                            const Eigen::VectorXd& v) const;
  // Total momentum in the world frame: angular about the world origin, then
  // linear (with a root motion, of the motion relative to the base).
  Vec6<double> world_momentum(const Eigen::VectorXd& q, const Eigen::VectorXd& v) const;
  // Kinetic energy alone.
  double kinetic_energy(const Eigen::VectorXd& q, const Eigen::VectorXd& v) const;
  // The free coordinate of bushing k (its joint angle or offset, as the
  // joint spring sees it).
  double bushing_coordinate(int k, const Eigen::VectorXd& q) const;
  // Passes of F per Jacobian (colours / lanes, rounded up).
  int jacobian_passes() const { return patterns().jacobian_passes; }

 private:
  // The workspace make_data() creates (defined with the evaluations), and
  // `data` as this system's (it must have made it).
  struct Data;
  Data& own(SystemData& data) const;
  // F (or F - M a) into data->F: the inverse dynamics, then the force
  // elements.
  template <typename T, typename Positions, typename Velocities>
  void generalized_forces(double t, const Positions& q, const Velocities& v,
                          const double* acceleration, ArticulatedData<T>* data) const;
  void exact_jacobians(Data& data, double t, const ConstVectorRef& q, const ConstVectorRef& v,
                       const double* acceleration, ForceJacobians* J) const;
  // Adds the force elements' K and D into J (after the recursion's terms).
  void add_element_jacobians(double t, const ConstVectorRef& q, const ConstVectorRef& v,
                             ForceJacobians* J) const;
  // Gravity as the world's upward acceleration, less the root's at t.
  Vec6<double> world_acceleration_at(double t) const;

  // One set per element type; the loops over forces, Jacobians and energy
  // go through for_each_element_set(), so a new element type is one line
  // there. kElementTypes indexes Patterns::element_slots.
  struct Elements {
    GeneralizedElementSet<JointSpringElement> joint_springs;
    GeneralizedElementSet<JointDriveElement> drives;
    GeneralizedElementSet<BushingElement> bushings;
  };
  static constexpr int kElementTypes = 3;
  template <typename Fn>
  void for_each_element_set(Fn&& fn) const {
    fn(elements_.joint_springs, 0);
    fn(elements_.drives, 1);
    fn(elements_.bushings, 2);
  }

  struct Patterns {
    SparseMatrix mass;
    ForceJacobians jacobians;
    // Value slots of M in the order the composite rigid body algorithm
    // produces its blocks (see mass_matrix()).
    std::vector<int> mass_slots;
    std::array<ElementSlots, kElementTypes> element_slots;
    std::vector<int> column_colour;  // over (q, v)
    int colours = 0, jacobian_passes = 0;
  };
  const Patterns& patterns() const;

  ArticulatedModel model_;
  ArticulatedOptions options_;
  Elements elements_;
  std::vector<double> pivot_stiffness_, pivot_damping_;
  Dimensions dims_;
  SparseMatrix velocity_map_pattern_;
  bool constant_mass_ = false;
  mutable std::once_flag patterns_built_;
  mutable std::unique_ptr<Patterns> patterns_;
};

}  // namespace stiffsim
