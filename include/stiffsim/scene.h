#pragma once
// A scene composes components; each owns a contiguous slice of q, v and z
// (in the order given). Components interact only through attachments
// (attachment.h), force elements the scene owns: without them every matrix
// of the scene is block diagonal over its components; each attachment adds
// the coupling blocks between the dofs its two points move with. The scene
// is itself a System.

#include <Eigen/Core>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "stiffsim/attachment.h"
#include "stiffsim/system.h"

namespace stiffsim {

class Scene : public System {
 public:
  // Throws InputError naming the attachment when a point does not exist or
  // its component offers no points (point_elements() in system.h).
  Scene(std::string name, std::vector<std::unique_ptr<System>> components,
        std::vector<Attachment> attachments = {});

  // The overloads without a workspace (system.h).
  using System::automatic_force_jacobians;
  using System::energy;
  using System::force_jacobians;
  using System::forces;
  using System::mass_matrix;
  using System::misc_derivatives;
  using System::momentum_residual;
  using System::velocity_map;

  Dimensions dimensions() const override { return dims_; }
  Capabilities capabilities() const override { return caps_; }
  std::string name() const override { return name_; }
  // Holds every component's own data beside the attachments' scratch.
  std::unique_ptr<SystemData> make_data() const override;
  State initial_state() const override;
  std::vector<std::string> position_names() const override;
  std::vector<std::string> velocity_names() const override;
  std::vector<std::string> misc_names() const override;

  void map_velocity_to_qdot(const ConstVectorRef& q, const ConstVectorRef& v,
                            VectorRef qdot) const override;
  const SparseMatrix& velocity_map_pattern() const override { return velocity_map_pattern_; }
  void velocity_map(SystemData&, const ConstVectorRef& q, SparseMatrix* N) const override;
  bool project_positions(VectorRef q) const override;

  const SparseMatrix& mass_matrix_pattern() const override { return patterns().mass; }
  void mass_matrix(SystemData&, const ConstVectorRef& q, SparseMatrix* M) const override;
  void forces(SystemData&, double t, const ConstVectorRef& q, const ConstVectorRef& v,
              const ConstVectorRef& z, VectorRef F) const override;
  void misc_derivatives(SystemData&, double t, const ConstVectorRef& q, const ConstVectorRef& v,
                        const ConstVectorRef& z, VectorRef zdot) const override;
  // Every component's rows: one inverse-dynamics pass each.
  void momentum_residual(SystemData&, double t, const ConstVectorRef& q, const ConstVectorRef& v,
                         const ConstVectorRef& z, const ConstVectorRef& dv, double h,
                         VectorRef r) const override;
  // The component's own when the scene has one component and no attachment.
  std::unique_ptr<StructuredNewtonMatrix> make_structured_newton_matrix() const override;
  const ForceJacobians& jacobian_pattern() const override { return patterns().jacobians; }
  // The components' Jacobians and the attachments' blocks: exact, except
  // that without request.complete the damper's dependence on q through the
  // points' velocity Jacobians is dropped (as for particle springs; K stays
  // symmetric). automatic_force_jacobians() takes the components' automatic
  // ones and the attachments' complete analytic blocks.
  void force_jacobians(SystemData&, double t, const ConstVectorRef& q, const ConstVectorRef& v,
                       const ConstVectorRef& z, const JacobianRequest& request,
                       ForceJacobians* J) const override;
  void automatic_force_jacobians(SystemData&, double t, const ConstVectorRef& q,
                                 const ConstVectorRef& v, const ConstVectorRef& z,
                                 const JacobianRequest& request, ForceJacobians* J) const override;
  // The components' hints side by side (components share no rows, so their
  // colours may coincide); empty unless every component has one.
  std::vector<int> jacobian_colouring_hint() const override;
  // The components' pairs, in the scene's indices; none where attachments
  // couple points (their blocks are not springs').
  std::vector<std::array<int, 2>> covered_couplings() const override;
  double energy(SystemData&, const State& s) const override;

  int component_count() const { return static_cast<int>(components_.size()); }
  const System& component(int i) const { return *components_[i]; }
  // Offsets of component i's slices in q, v and z.
  const Dimensions& offsets(int i) const { return offsets_[i]; }
  const std::vector<Attachment>& attachments() const { return attachments_; }

 private:
  struct Data;
  // `data` as this scene's (it must have made it).
  Data& own(SystemData& data) const;
  using JacobianMethod = void (System::*)(SystemData&, double, const ConstVectorRef&,
                                          const ConstVectorRef&, const ConstVectorRef&,
                                          const JacobianRequest&, ForceJacobians*) const;
  // Each component's Jacobians by `method`, scattered into J.
  void gather_jacobians(Data& data, double t, const ConstVectorRef& q, const ConstVectorRef& v,
                        const ConstVectorRef& z, const JacobianRequest& request, ForceJacobians* J,
                        JacobianMethod method) const;
  // Attachment forces times `scale` added into F (rows of the scene's v),
  // and their Jacobian blocks into J (complete: with the damper's
  // q-dependence).
  void add_attachment_forces(Data& data, double t, const ConstVectorRef& q, const ConstVectorRef& v,
                             double scale, VectorRef F) const;
  void add_attachment_jacobians(Data& data, double t, const ConstVectorRef& q,
                                const ConstVectorRef& v, bool complete, ForceJacobians* J) const;
  // The force on point a of `at` at its points a and b (-it on b).
  static Eigen::Vector3d attachment_force(const Attachment& at, const PointKinematics& a,
                                          const PointKinematics& b);
  // Both points of attachment k at (t, q, v) into a and b.
  void attachment_points(int k, double t, const ConstVectorRef& q, const ConstVectorRef& v,
                         PointKinematics* a, PointKinematics* b) const;

  std::string name_;
  std::vector<std::unique_ptr<System>> components_;
  std::vector<Attachment> attachments_;
  // The most dofs an attachment's point moves with (sizes the data's points).
  int most_point_dofs_ = 0;
  std::vector<Dimensions> offsets_;
  Dimensions dims_;
  Capabilities caps_;
  SparseMatrix velocity_map_pattern_;
  // Per component, the slots of the entries of its matrices in the scene's.
  struct Slots {
    std::vector<int> M, dF_dq, dF_dv, dF_dz, dfz_dq, dfz_dv, dfz_dz;
  };
  // The patterns of M and of the Jacobians, built on first use (a run on a
  // structured Newton matrix never asks for them; an exact chain's are
  // dense).
  struct Patterns {
    SparseMatrix mass;
    ForceJacobians jacobians;
    std::vector<Slots> slots;
    // Per attachment, the slots of its blocks in dF/dq and dF/dv, row-major:
    // rows are the velocity dofs of point a, then point b; dF/dv's columns
    // the same, dF/dq's the position coordinates in the order
    // add_attachment_jacobians() walks them (point_kinematics.h).
    std::vector<std::vector<int>> attachment_q, attachment_v;
  };
  const Patterns& patterns() const;
  mutable std::once_flag patterns_built_;
  mutable std::unique_ptr<Patterns> patterns_;
  std::vector<std::vector<int>> slots_N_;
};

}  // namespace stiffsim
