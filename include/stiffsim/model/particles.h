#pragma once
// Particle mass-spring systems exactly as MODELS.md defines them: nodes
// (lumped masses, pins and moving pins, gravity and drag) and force
// elements (force_element.h) on them, linear springs with dampers along the
// spring axis so far. N(q) = I, M constant and diagonal, analytic symmetric
// K and D (and complete, unsymmetric ones on request or by automatic
// differentiation).

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include "stiffsim/model/force_element.h"
#include "stiffsim/model/path.h"
#include "stiffsim/model/spring_batch.h"
#include "stiffsim/model/spring_element.h"
#include "stiffsim/system.h"

namespace stiffsim {

// A pinned node that moves: its position is its rest position plus the
// displacement (x(t), y(t), z(t)), its velocity the paths' rates. It stays
// outside the state, so it follows its path exactly under every method.
struct PinMotion {
  int node = 0;  // must also be in ParticleDescription::pinned
  std::array<ScalarPath, 3> displacement{ScalarPath::constant(0.0), ScalarPath::constant(0.0),
                                         ScalarPath::constant(0.0)};
};

struct ParticleDescription {
  std::string name;                        // component name: CSV columns <name>/n<i>/x
  std::vector<Eigen::Vector3d> positions;  // every node, pinned ones included
  std::vector<double> masses;              // every node, > 0
  std::vector<Eigen::Vector3d> velocities;  // initial, every node (empty: all at rest)
  std::vector<Spring> springs;
  std::vector<int> pinned;  // node indices; not degrees of freedom
  std::vector<PinMotion> pin_motions;  // pinned nodes that move (at most one each)
  Eigen::Vector3d gravity{0.0, 0.0, -9.81};
  double drag = 0.0;  // alpha: f_i += -alpha m_i v_i
  // Integer lattice coordinates of every node when the nodes sit on a square
  // grid (cloth), empty otherwise. Only for colouring Jacobian columns.
  std::vector<std::array<int, 2>> lattice;
};

class ParticleSystem : public System {
 public:
  // Validates the description (finite positions, finite positive masses,
  // spring and pinned node indices in range, a != b, k, c and rest lengths
  // finite and >= 0; zero-rest-length springs are legal); throws InputError
  // naming the component otherwise.
  explicit ParticleSystem(ParticleDescription description);

  // The overloads without a workspace (system.h).
  using System::automatic_force_jacobians;
  using System::energy;
  using System::force_jacobians;
  using System::forces;
  using System::mass_matrix;

  Dimensions dimensions() const override;
  Capabilities capabilities() const override;
  std::string name() const override { return desc_.name; }
  State initial_state() const override;
  std::vector<std::string> position_names() const override;
  std::vector<std::string> velocity_names() const override;

  const SparseMatrix& mass_matrix_pattern() const override;
  void mass_matrix(SystemData&, const ConstVectorRef& q, SparseMatrix* M) const override;
  void forces(SystemData&, double t, const ConstVectorRef& q, const ConstVectorRef& v,
              const ConstVectorRef& z, VectorRef F) const override;
  const ForceJacobians& jacobian_pattern() const override;
  // By default the derivative of the damping force through u(x) is dropped
  // from dF/dq (MODELS.md allows it; it changes the Newton rate, never the
  // solution), which keeps K symmetric; request.complete adds it (K is then
  // unsymmetric wherever springs move). With request.definite the transverse
  // factor (1 - L/l) is clamped at 0 and approximated_terms counts the springs.
  void force_jacobians(SystemData&, double t, const ConstVectorRef& q, const ConstVectorRef& v,
                       const ConstVectorRef& z, const JacobianRequest& request,
                       ForceJacobians* J) const override;
  // The complete Jacobians by forward-mode AD of the same spring kernel that
  // forces() runs, one spring at a time with 12 derivative lanes (positions
  // and velocities of its two nodes): O(springs). Differentiates forces() as
  // it is, so a collapsed spring (force 0 by definition) contributes 0 where
  // force_jacobians() substitutes k I.
  void automatic_force_jacobians(SystemData&, double t, const ConstVectorRef& q,
                                 const ConstVectorRef& v, const ConstVectorRef& z,
                                 const JacobianRequest& request, ForceJacobians* J) const override;
  // With a lattice whose springs all span an L1 distance <= 2 (stretch, shear
  // and bend of a cloth): node colour (i + 5 j) mod 13, a perfect Lee-code
  // tiling, so nodes of one colour are at L1 distance >= 5 and never share a
  // row; 6 columns per node give 78 colours at every size, the lower bound.
  std::vector<int> jacobian_colouring_hint() const override;
  // Springs between free nodes a and b for which another node m has springs
  // (a, m) and (m, b), each at least kCoverageRatio times as stiff and as
  // damped, and lies on the segment from a to b at rest (within
  // kCollinearity of its length): a cloth's or rope's bend springs.
  std::vector<std::array<int, 2>> covered_couplings() const override;
  static constexpr double kCollinearity = 0.05;
  // Every node is a point attachments can act on: a free node moves with its
  // three dofs, a pinned one with none (it follows its motion, if any).
  int point_elements() const override { return node_count(); }
  int point_dofs(int node) const override { return dof_of_node_[node] >= 0 ? 3 : 0; }
  void point_kinematics(double t, int node, const Eigen::Vector3d& local, const ConstVectorRef& q,
                        const ConstVectorRef& v, PointKinematics* out) const override;
  // Kinetic + gravitational + spring potential energy.
  double energy(SystemData&, const State& s) const override;
  // One point per node in node order, free nodes from the state and pinned
  // ones where their motion puts them at t (held by the world); segments
  // are the edges of request.triangles when they are in range, else the
  // springs between consecutive nodes (a rope's stretch springs, not its
  // bend springs), else all springs.
  bool draw(double t, const ConstVectorRef& q, const ConstVectorRef& v,
            const DrawingRequest& request, ComponentDrawing* out) const override;

  const ParticleDescription& description() const { return desc_; }
  int node_count() const { return static_cast<int>(desc_.positions.size()); }
  // DOF index of a node's x coordinate, or -1 if the node is pinned.
  int dof_of_node(int node) const { return dof_of_node_[node]; }
  // Where a pinned node is at time t, and its velocity.
  Eigen::Vector3d pinned_position(int node, double t) const;
  Eigen::Vector3d pinned_velocity(int node, double t) const;

 private:
  // Throws std::logic_error unless J has the sizes of jacobian_pattern().
  void check_jacobian_pattern(const ForceJacobians& J, const char* caller) const;

  ParticleDescription desc_;
  // Position and velocity of node i at time t: from q and v for a free node,
  // from its rest position and motion for a pinned one. Inline: the energy
  // and element loops call them per node, and a free node must cost a read.
  Eigen::Vector3d node_position(int i, const ConstVectorRef& q, double t) const {
    const int di = dof_of_node_[i];
    if (di >= 0) return q.segment<3>(di);
    return motion_of_node_[i] < 0 ? desc_.positions[i] : pinned_position(i, t);
  }
  Eigen::Vector3d node_velocity(int i, const ConstVectorRef& v, double t) const {
    const int di = dof_of_node_[i];
    if (di >= 0) return v.segment<3>(di);
    return motion_of_node_[i] < 0 ? Eigen::Vector3d::Zero() : pinned_velocity(i, t);
  }

  // Positions and velocities of element e's stencil at t; false when every
  // node of it is pinned (it then acts on no degree of freedom). dofs[i]
  // (when given) receives node i's first DOF, or -1 where pinned.
  template <typename E>
  bool gather(const E& e, double t, const ConstVectorRef& q, const ConstVectorRef& v,
              Eigen::Vector3d* x, Eigen::Vector3d* vel, int* dofs = nullptr) const;

  std::vector<int> dof_of_node_;  // 3*free index or -1
  std::vector<int> motion_of_node_;  // index into desc_.pin_motions or -1
  int free_nodes_ = 0;
  SparseMatrix mass_pattern_;
  ForceJacobians jacobian_pattern_;
  // The force elements, one set per type, with their blocks' slots in the
  // Jacobian patterns.
  ElementSet<SpringElement> springs_;
  // forces() adds the springs between two free nodes through the batch
  // (spring_batch.h), the others (springs_.elements[i] for i in
  // pinned_springs_) through their elements.
  SpringBatch free_springs_;
  std::vector<int> pinned_springs_;
  // Calls fn on every element set: the loops over forces, Jacobians,
  // energy and patterns are written once for every element type.
  template <typename Fn>
  void for_each_element_set(Fn&& fn) const {
    fn(springs_);
  }
  template <typename Fn>
  void for_each_element_set(Fn&& fn) {
    fn(springs_);
  }
  // Slot of every diagonal entry (i, i) of the Jacobian patterns (for drag).
  std::vector<int> diagonal_slots_;
  // Mass of every DOF (each free node's mass three times): the diagonal of M.
  Eigen::VectorXd free_mass_;
};

}  // namespace stiffsim
