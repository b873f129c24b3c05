#pragma once
// The recursive Newton-Euler algorithm on an ArticulatedModel (Featherstone
// 2008, table 5.1), writing into an ArticulatedData workspace:
//   F = -(M(q) a + C(q, v) + g(q)),
// the rigid bodies' share of the generalized forces of MODELS.md less the
// inertial forces of the joint accelerations a (a = 0 when `acceleration` is
// null); the system adds its force elements' (joint springs, dampers,
// drives, bushings: generalized_element.h). With
// a = (v - v_n) / h, -h F is the velocity-implicit residual M(q)(v - v_n) - h F
// in one O(n) pass, with no mass matrix formed. Templated on the scalar for
// automatic differentiation.

#include <Eigen/Core>

#include "stiffsim/model/articulated_data.h"
#include "stiffsim/model/articulated_model.h"
#include "stiffsim/model/joints.h"

namespace stiffsim {

template <typename T>
using JointVector = Eigen::Matrix<T, Eigen::Dynamic, 1, 0, 6, 1>;

// Result in data->F; q and v hold model.nq and model.nv values, acceleration
// model.nv (or null).
template <typename T, typename Positions, typename Velocities>
void inverse_dynamics(const ArticulatedModel& model, const Positions& q, const Velocities& v,
                      const double* acceleration, ArticulatedData<T>* data) {
  const int nb = model.bodies();
  ArticulatedData<T>& d = *data;
  const Vec6<T> a_world = d.world_acceleration.template cast<T>();
  for (int i = 0; i < nb; ++i) {
    const TreeBody& b = model.tree.bodies[i];
    const int nv = joint_nv(b.type);
    const JointMotion<T> jm =
        body_joint_motion<T>(model, i, q.segment(model.q_offset[i], joint_nq(b.type)));
    d.pose[i] = jm.pose;
    d.S[i] = jm.S;
    const MotionSubspace<T>& S = d.S[i];
    Vec6<T> vJ, cJ;
    if (nv == 1) {
      // Revolute and prismatic joints, nearly every body: fixed-size
      // arithmetic on S's one column (and no velocity product term).
      const Vec6<T> s = S.col(0);
      vJ = s * v[model.v_offset[i]];
      cJ.setZero();
      if (acceleration) cJ = s * T(acceleration[model.v_offset[i]]);
    } else {
      // Joint-sized values in vectors of fixed capacity: a product with a
      // dynamic-size expression would allocate a temporary per body.
      const JointVector<T> vj = v.segment(model.v_offset[i], nv);
      vJ = S * vj;
      cJ = joint_velocity_product<T>(vJ);
      if (acceleration) {
        const JointVector<T> aj =
            Eigen::Map<const Eigen::VectorXd>(acceleration + model.v_offset[i], nv)
                .template cast<T>();
        cJ += S * aj;
      }
    }
    if (b.parent < 0) {
      d.V[i] = vJ;
      d.A[i] = motion_to_child<T>(d.pose[i], a_world) + cJ;
    } else {
      d.V[i] = motion_to_child<T>(d.pose[i], d.V[b.parent]) + vJ;
      d.A[i] = motion_to_child<T>(d.pose[i], d.A[b.parent]) + cJ + cross_motion<T>(d.V[i], vJ);
    }
    const SpatialInertia& I = model.inertia[i];
    d.f[i] = I.apply<T>(d.A[i]) + cross_force<T>(d.V[i], I.apply<T>(d.V[i]));
  }
  d.F.resize(model.nv);
  for (int i = nb - 1; i >= 0; --i) {
    const TreeBody& b = model.tree.bodies[i];
    const int nv = joint_nv(b.type), vo = model.v_offset[i];
    if (nv == 1) {
      d.F[vo] = -Vec6<T>(d.S[i].col(0)).dot(d.f[i]);
    } else {
      const JointVector<T> tau = d.S[i].transpose() * d.f[i];
      d.F.segment(vo, nv) = -tau;
    }
    if (b.parent >= 0) d.f[b.parent] += force_to_parent<T>(d.pose[i], d.f[i]);
  }
}

}  // namespace stiffsim
