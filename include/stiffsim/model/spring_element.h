#pragma once
// The linear spring with a damper along its axis (MODELS.md), the first
// force element of a particle system (force_element.h):
//   f_a = (k (l - L) + c (v_b - v_a).u) u,  f_b = -f_a,
// u the unit vector from a to b and l the length.

#include <Eigen/Core>
#include <array>
#include <string>
#include <unsupported/Eigen/AutoDiff>

#include "stiffsim/model/force_element.h"
#include "stiffsim/system.h"

namespace stiffsim {

struct Spring {
  int a = 0, b = 0;          // node indices (pinned nodes allowed)
  double rest_length = 0.0;  // L
  double k = 0.0;            // stiffness, N/m
  double c = 0.0;            // damping along the axis, N s/m
};

// Below this length a spring counts as collapsed: its direction is undefined
// and L/l would overflow. Far below any physical length, far above underflow.
constexpr double kCollapsedSpringLength = 1e-100;

// Geometry of one spring at the current positions. A collapsed spring gets
// u = 0, so both its elastic and damping forces vanish (the direction of
// k (l - L) u is undefined there), and collapsed = true so the Jacobian can
// pick a finite value.
template <typename Scalar>
struct SpringFrame {
  Vector3<Scalar> u;
  Scalar l;
  bool collapsed;
};

// A value without its derivatives (the identity on doubles).
inline double constant_part(double x) { return x; }
template <typename Derivatives>
Eigen::AutoDiffScalar<Derivatives> constant_part(const Eigen::AutoDiffScalar<Derivatives>& x) {
  return Eigen::AutoDiffScalar<Derivatives>(x.value());
}

template <typename Scalar>
SpringFrame<Scalar> spring_frame(const Vector3<Scalar>& xa, const Vector3<Scalar>& xb) {
  const Vector3<Scalar> d = xb - xa;
  const Scalar l = d.norm();
  // The derivative of |d| at d = 0 is NaN, and NaN * (u = 0) would leak into
  // dual numbers: a collapsed l is a constant.
  if (!(l > kCollapsedSpringLength)) return {Vector3<Scalar>::Zero(), constant_part(l), true};
  return {d / l, l, false};
}

class SpringElement {
 public:
  static constexpr int kNodes = 2;

  // Throws InputError "<who>: spring <index>: ..." unless both nodes are in
  // [0, nodes) and differ, and k, c and the rest length are finite and >= 0
  // (a zero rest length is legal).
  SpringElement(const Spring& spring, std::size_t index, int nodes, const std::string& who);

  std::array<int, kNodes> nodes() const { return {spring_.a, spring_.b}; }
  const Spring& spring() const { return spring_; }

  // The one definition of the spring force: forces() runs it on doubles,
  // the automatic Jacobian on dual numbers, so the two cannot disagree.
  template <typename Scalar>
  void force(const Vector3<Scalar>* x, const Vector3<Scalar>* v, Vector3<Scalar>* f) const {
    const Vector3<Scalar> vab = v[1] - v[0];
    const SpringFrame<Scalar> fr = spring_frame(x[0], x[1]);
    f[0] = (spring_.k * (fr.l - spring_.rest_length) + spring_.c * vab.dot(fr.u)) * fr.u;
    f[1] = -f[0];
  }

  // By default the derivative of the damping force through u is dropped
  // from K (MODELS.md allows it: it only slows Newton down, the residual
  // stays exact), which keeps K symmetric; request.complete adds it. With
  // request.definite a compressed spring's transverse factor (1 - L/l) is
  // clamped at 0 and counted in *approximated. With x_tension (the nodes at
  // request.tension_positions) the transverse factor is T / (k l) for the
  // request's tension estimate T (system.h), clamped likewise.
  // The force depends on x_b - x_a and v_b - v_a alone, so its blocks are
  // -S, S, S, -S for K and -C, C, C, -C for D (force_element.h): S =
  // df_a/dx_b and C = df_a/dv_b.
  static constexpr bool kDifference = true;
  void jacobian_difference(const Eigen::Vector3d* x, const Eigen::Vector3d* v,
                           const Eigen::Vector3d* x_tension, const JacobianRequest& request,
                           Eigen::Matrix3d* S, Eigen::Matrix3d* C, long* approximated) const;

  // Inline: the energy guard and the incremental potential evaluate every
  // spring once per step or search trial, as often as the forces.
  double energy(const Eigen::Vector3d* x) const {
    const double stretch = (x[1] - x[0]).norm() - spring_.rest_length;
    return 0.5 * spring_.k * stretch * stretch;
  }

 private:
  Spring spring_;
};

}  // namespace stiffsim
