#include "stiffsim/model/bushing_element.h"

#include <cmath>

#include "stiffsim/model/joints.h"
#include "stiffsim/model/quaternion.h"

namespace stiffsim {
namespace {

using Mat3d = Eigen::Matrix3d;
using Vec3d = Eigen::Vector3d;
// Derivatives of a 3-vector with respect to the 12 motions of a bushing's
// two bodies: (parent displacement, parent rotation, child displacement,
// child rotation) for positions, (parent velocity, parent angular velocity,
// child velocity, child angular velocity) for velocities, all in the world.
using Jac = Eigen::Matrix<double, 3, 12>;
using Row = Eigen::Matrix<double, 1, 12>;

// Column offsets in a Jac: body 0 is the parent, 1 the child; part 0 the
// translation (or linear velocity), 1 the rotation (or angular velocity).
constexpr int col(int body, int part) { return 6 * body + 3 * part; }

// A free body's pose and world velocities, and the world rotation per unit
// change of each raw quaternion component.
struct BodyFrame {
  Mat3d R = Mat3d::Identity();
  Vec3d p = Vec3d::Zero(), velocity = Vec3d::Zero(), omega = Vec3d::Zero();
  Eigen::Matrix<double, 3, 4> turn = Eigen::Matrix<double, 3, 4>::Zero();
};

BodyFrame body_frame(const ConstVectorRef& q, const ConstVectorRef& v, int qo, int vo) {
  BodyFrame b;
  const Eigen::Vector4d quat = q.segment<4>(qo + 3);
  b.R = quaternion_rotation<double>(quat);
  b.p = q.segment<3>(qo);
  b.velocity = v.segment<3>(vo);
  b.omega = b.R * v.segment<3>(vo + 3);
  // The rotation uses q / |q|: dq turns the body by 4 / |q|^2 N(q)^T dq in
  // its own frame (rnea_derivatives.h).
  b.turn = (4.0 / quat.squaredNorm()) * b.R * quaternion_rate_map(quat).transpose();
  return b;
}

}  // namespace

Stencil BushingElement::velocity_stencil() const {
  if (at_.parent_v < 0) return {{at_.child_v, 6}};
  return {{at_.parent_v, 6}, {at_.child_v, 6}};
}

Stencil BushingElement::position_stencil() const {
  if (at_.parent_q < 0) return {{at_.child_q, 7}};
  return {{at_.parent_q, 7}, {at_.child_q, 7}};
}

void BushingElement::add_jacobians(double, const ConstVectorRef& q, const ConstVectorRef& v,
                                   const int* k_slots, const int* d_slots, double* K,
                                   double* D) const {
  const Bushing& bu = bushing_;
  // The forces of add_bushing_forces (bushing.h), term by term, each
  // with its derivatives Jx (positions) and Jv (velocities).
  const bool has_parent = bu.parent >= 0;
  BodyFrame a;  // the world at rest when there is no parent
  if (has_parent) a = body_frame(q, v, at_.parent_q, at_.parent_v);
  const BodyFrame b = body_frame(q, v, at_.child_q, at_.child_v);
  const BushingProjector g = bushing_projector(bu.type);
  const Mat3d I = Mat3d::Identity();

  const Mat3d RJ = a.R * bu.placement.linear();
  const Vec3d r = a.R * bu.placement.translation();  // the joint origin from the parent's
  const Vec3d n = RJ * bu.axis;
  const Vec3d d = b.p - (a.p + r);
  const Vec3d lever = b.p - a.p;
  const double nd = n.dot(d);
  const Vec3d dv = b.velocity - (a.velocity + a.omega.cross(lever));
  const Vec3d dw = b.omega - a.omega;
  const double ndv = n.dot(dv), ndw = n.dot(dw);

  // Derivatives of the kinematic quantities.
  Jac dd_x = Jac::Zero(), dn_x = Jac::Zero(), ddv_x = Jac::Zero(), dlever_x = Jac::Zero();
  Jac ddv_v = Jac::Zero(), ddw_v = Jac::Zero();
  dd_x.block<3, 3>(0, col(0, 0)) = -I;
  dd_x.block<3, 3>(0, col(0, 1)) = skew(r);
  dd_x.block<3, 3>(0, col(1, 0)) = I;
  dlever_x.block<3, 3>(0, col(0, 0)) = -I;
  dlever_x.block<3, 3>(0, col(1, 0)) = I;
  dn_x.block<3, 3>(0, col(0, 1)) = -skew(n);
  ddv_x.block<3, 3>(0, col(0, 0)) = skew(a.omega);
  ddv_x.block<3, 3>(0, col(1, 0)) = -skew(a.omega);
  ddv_v.block<3, 3>(0, col(0, 0)) = -I;
  ddv_v.block<3, 3>(0, col(0, 1)) = skew(lever);
  ddv_v.block<3, 3>(0, col(1, 0)) = I;
  ddw_v.block<3, 3>(0, col(0, 1)) = -I;
  ddw_v.block<3, 3>(0, col(1, 1)) = I;
  Row dnd_x = n.transpose() * dd_x;
  dnd_x.segment<3>(col(0, 1)) += n.cross(d).transpose();
  Row dndv_x = n.transpose() * ddv_x;
  dndv_x.segment<3>(col(0, 1)) += n.cross(dv).transpose();
  const Row dndv_v = n.transpose() * ddv_v;
  Row dndw_x = Row::Zero();
  dndw_x.segment<3>(col(0, 1)) = n.cross(dw).transpose();
  const Row dndw_v = n.transpose() * ddw_v;

  // Linear: f = -k alpha d - c alpha dv - sigma n, with the prismatic joint's
  // spring and damper on n . d folded into sigma; the parent also carries
  // -lambda n x d (its axis turns the projected spring).
  const JointForce& jf = bu.joint;
  const bool prismatic = bu.type == JointType::kPrismatic;
  const double k_joint = prismatic ? jf.stiffness : 0.0, c_joint = prismatic ? jf.damping : 0.0;
  const double ks = bu.k_lin * g.beta + k_joint, cs = bu.c_lin * g.beta + c_joint;
  const double lambda = ks * nd - k_joint * jf.rest;
  const double sigma = lambda + cs * ndv;
  const double ka = bu.k_lin * g.alpha, ca = bu.c_lin * g.alpha;
  const Vec3d f = -ka * d - ca * dv - sigma * n;
  Jac f_x = -ka * dd_x - ca * ddv_x - n * (ks * dnd_x + cs * dndv_x) - sigma * dn_x;
  Jac f_v = -ca * ddv_v - n * (cs * dndv_v);
  const Vec3d nxd = n.cross(d);
  Vec3d m_parent = -lambda * nxd, m_child = Vec3d::Zero();
  Jac mp_x = -nxd * (ks * dnd_x) - lambda * (-skew(d) * dn_x + skew(n) * dd_x);
  Jac mp_v = Jac::Zero(), mc_x = Jac::Zero(), mc_v = Jac::Zero();

  // Angular.
  if (g.tilt_only) {
    const Vec3d nb = b.R * bu.axis;
    Jac dnb_x = Jac::Zero();
    dnb_x.block<3, 3>(0, col(1, 1)) = -skew(nb);
    const Vec3d tilt = bu.k_ang * nb.cross(n);
    const Jac tilt_x = bu.k_ang * (skew(nb) * dn_x - skew(n) * dnb_x);
    m_child += tilt;
    m_parent -= tilt;
    mc_x += tilt_x;
    mp_x -= tilt_x;
    const Vec3d dw_perp = dw - ndw * n;
    const Jac perp_x = -n * dndw_x - ndw * dn_x;
    const Jac perp_v = ddw_v - n * dndw_v;
    m_child -= bu.c_ang * dw_perp;
    m_parent += bu.c_ang * dw_perp;
    mc_x -= bu.c_ang * perp_x;
    mp_x += bu.c_ang * perp_x;
    mc_v -= bu.c_ang * perp_v;
    mp_v += bu.c_ang * perp_v;
  } else {
    // The axial vector of S - S^T, S = R_child R_joint^T, changes by
    // (tr S I - S) phi_child - (tr S I - S^T) phi_parent.
    const Mat3d S = b.R * RJ.transpose();
    Vec3d axial;
    axial << S(2, 1) - S(1, 2), S(0, 2) - S(2, 0), S(1, 0) - S(0, 1);
    Jac axial_x = Jac::Zero();
    axial_x.block<3, 3>(0, col(1, 1)) = S.trace() * I - S;
    axial_x.block<3, 3>(0, col(0, 1)) = -(S.trace() * I - S.transpose());
    m_child -= 0.5 * bu.k_ang * axial;
    m_parent += 0.5 * bu.k_ang * axial;
    mc_x -= 0.5 * bu.k_ang * axial_x;
    mp_x += 0.5 * bu.k_ang * axial_x;
    m_child -= bu.c_ang * dw;
    m_parent += bu.c_ang * dw;
    mc_v -= bu.c_ang * ddw_v;
    mp_v += bu.c_ang * ddw_v;
  }

  // The revolute joint's spring on theta = atan2(y, x) and its damper.
  if (bu.type == JointType::kRevolute && (jf.stiffness != 0.0 || jf.damping != 0.0)) {
    const Vec3d e1 = reference_direction(bu.axis);  // as the forces' angle (bushing.h)
    const Vec3d ea = RJ * e1, eb = b.R * e1, fa = n.cross(ea);
    const double x = ea.dot(eb), y = fa.dot(eb), rho = x * x + y * y;
    const double theta = std::atan2(y, x);
    // dtheta/dphi_child = grad = eb x h; the parent's is -grad. grad turns
    // with a common rotation, so its parent derivative is -[grad]x minus the
    // child's.
    const Vec3d h = (x * fa - y * ea) / rho;
    const Vec3d grad = eb.cross(h);
    const Vec3d dx = eb.cross(ea), dy = eb.cross(fa);
    const Mat3d grad_child = skew(h) * skew(eb) + skew(eb) *
                                                      (fa * dx.transpose() - ea * dy.transpose() -
                                                       2.0 * h * (x * dx + y * dy).transpose()) /
                                                      rho;
    Jac grad_x = Jac::Zero();
    grad_x.block<3, 3>(0, col(1, 1)) = grad_child;
    grad_x.block<3, 3>(0, col(0, 1)) = -skew(grad) - grad_child;
    Row theta_x = Row::Zero();
    theta_x.segment<3>(col(1, 1)) = grad.transpose();
    theta_x.segment<3>(col(0, 1)) = -grad.transpose();
    const double torque = -jf.stiffness * (theta - jf.rest);
    const Jac spring_x = torque * grad_x - jf.stiffness * grad * theta_x;
    m_child += torque * grad;
    m_parent -= torque * grad;
    mc_x += spring_x;
    mp_x -= spring_x;
    const Vec3d damp = -jf.damping * ndw * n;
    const Jac damp_x = -jf.damping * (n * dndw_x + ndw * dn_x);
    const Jac damp_v = -jf.damping * n * dndw_v;
    m_child += damp;
    m_parent -= damp;
    mc_x += damp_x;
    mp_x -= damp_x;
    mc_v += damp_v;
    mp_v -= damp_v;
  }

  // Moments about the body origins: the child's force acts at its origin;
  // the parent takes -f there, at the lever p_child - p_parent.
  const Vec3d tau_parent = f.cross(lever) + m_parent;
  const Jac tp_x = mp_x - skew(lever) * f_x + skew(f) * dlever_x;
  const Jac tp_v = mp_v - skew(lever) * f_v;

  // Chain rule to the raw coordinates, per (row body, column body) block.
  const BodyFrame* frames[2] = {&a, &b};
  const Jac* force_x[2] = {&f_x, &f_x};
  const Jac* force_v[2] = {&f_v, &f_v};
  const double force_sign[2] = {-1.0, 1.0};
  const Jac* moment_x[2] = {&tp_x, &mc_x};
  const Jac* moment_v[2] = {&tp_v, &mc_v};
  const Vec3d moment[2] = {tau_parent, m_child};
  // The stencil: velocity runs (parent, child) of 6, K's columns 7 per
  // body, D's 6, the parent's absent for the world.
  const int runs = has_parent ? 2 : 1;
  for (int row = has_parent ? 0 : 1; row < 2; ++row) {
    const Mat3d Rt = frames[row]->R.transpose();
    for (int column = has_parent ? 0 : 1; column < 2; ++column) {
      const BodyFrame& c = *frames[column];
      const int xp = col(column, 0), xr = col(column, 1);
      Eigen::Matrix<double, 6, 7> Kb;
      Eigen::Matrix<double, 6, 6> Db;
      // A rotation phi of the column body also turns its world angular
      // velocity by phi x omega; a body's own rotation turns its rows R^T.
      const Mat3d omega_turn = -skew(c.omega);
      for (int part = 0; part < 2; ++part) {
        const Jac& Jx = part == 0 ? *force_x[row] : *moment_x[row];
        const Jac& Jv = part == 0 ? *force_v[row] : *moment_v[row];
        Mat3d rotation = Jx.block<3, 3>(0, xr) + Jv.block<3, 3>(0, xr) * omega_turn;
        if (part == 1 && row == column) rotation += skew(moment[row]);
        const Mat3d out = part == 0 ? Mat3d(force_sign[row] * I) : Rt;
        Kb.block<3, 3>(3 * part, 0) = out * Jx.block<3, 3>(0, xp);
        Kb.block<3, 4>(3 * part, 3) = out * rotation * c.turn;
        Db.block<3, 3>(3 * part, 0) = out * Jv.block<3, 3>(0, xp);
        Db.block<3, 3>(3 * part, 3) = out * Jv.block<3, 3>(0, xr) * c.R;
      }
      const int run = has_parent ? row : 0;
      const int k0 = has_parent ? 7 * column : 0, d0 = has_parent ? 6 * column : 0;
      for (int j = 0; j < 7; ++j) {
        double* dst = K + k_slots[(k0 + j) * runs + run];
        for (int i = 0; i < 6; ++i) dst[i] += Kb(i, j);
      }
      for (int j = 0; j < 6; ++j) {
        double* dst = D + d_slots[(d0 + j) * runs + run];
        for (int i = 0; i < 6; ++i) dst[i] += Db(i, j);
      }
    }
  }
}

}  // namespace stiffsim
