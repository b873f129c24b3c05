#pragma once
// The joint-local force elements of an exact articulated tree
// (generalized_element.h): a joint's spring and damper, and a PD drive. Both
// act on the one coordinate of a revolute or prismatic joint with constant
// stiffness and damping, which the articulated-body recursion folds into its
// pivots, so they are as implicit as the rest of the step.

#include <Eigen/Core>
#include <vector>

#include "stiffsim/model/generalized_element.h"
#include "stiffsim/model/path.h"
#include "stiffsim/system.h"

namespace stiffsim {

// The joint's spring and damper (MODELS.md):
//   tau = -k (q - rest) - c q_dot,
// c being the URDF's damping plus the scene's.
class JointSpringElement {
 public:
  static constexpr bool kJointLocal = true;
  JointSpringElement(int body, int q_index, int v_index, double k, double rest, double c)
      : body_(body), q_(q_index), v_(v_index), k_(k), rest_(rest), c_(c) {}

  Stencil velocity_stencil() const { return {{v_, 1}}; }
  Stencil position_stencil() const { return {{q_, 1}}; }
  template <typename T, typename Q, typename V>
  void add_force(double, const Q& q, const V& v, Eigen::Matrix<T, Eigen::Dynamic, 1>* F) const {
    (*F)[v_] -= T(c_) * v[v_];
    if (k_ != 0.0) (*F)[v_] -= T(k_) * (q[q_] - T(rest_));
  }
  void add_jacobians(double, const ConstVectorRef&, const ConstVectorRef&, const int* k_slots,
                     const int* d_slots, double* K, double* D) const {
    K[k_slots[0]] -= k_;
    D[d_slots[0]] -= c_;
  }
  double energy(double, const ConstVectorRef& q) const {
    const double dq = q[q_] - rest_;
    return 0.5 * k_ * dq * dq;
  }
  int body() const { return body_; }
  double stiffness() const { return k_; }
  double damping() const { return c_; }
  double rest() const { return rest_; }

 private:
  int body_, q_, v_;
  double k_, rest_, c_;
};

// A PD drive toward the target path p(t) (path.h), its rate the velocity
// target:
//   tau = kp (p(t) - q) + kd (p'(t) - q_dot).
// Only kp p(t) + kd p'(t), which no state changes, is explicit. Its energy
// is that of its spring about the current target (a moving target does work
// on the system, which then is not passive).
class JointDriveElement {
 public:
  static constexpr bool kJointLocal = true;
  JointDriveElement(int body, int q_index, int v_index, double kp, double kd, ScalarPath target)
      : body_(body), q_(q_index), v_(v_index), kp_(kp), kd_(kd), target_(std::move(target)) {}

  Stencil velocity_stencil() const { return {{v_, 1}}; }
  Stencil position_stencil() const { return {{q_, 1}}; }
  template <typename T, typename Q, typename V>
  void add_force(double t, const Q& q, const V& v, Eigen::Matrix<T, Eigen::Dynamic, 1>* F) const {
    (*F)[v_] += T(kp_) * (T(target_.value(t)) - q[q_]) + T(kd_) * (T(target_.rate(t)) - v[v_]);
  }
  void add_jacobians(double, const ConstVectorRef&, const ConstVectorRef&, const int* k_slots,
                     const int* d_slots, double* K, double* D) const {
    K[k_slots[0]] -= kp_;
    D[d_slots[0]] -= kd_;
  }
  double energy(double t, const ConstVectorRef& q) const {
    const double dq = q[q_] - target_.value(t);
    return 0.5 * kp_ * dq * dq;
  }
  int body() const { return body_; }
  double stiffness() const { return kp_; }
  double damping() const { return kd_; }
  const ScalarPath& target() const { return target_; }

 private:
  int body_, q_, v_;
  double kp_, kd_;
  ScalarPath target_;
};

}  // namespace stiffsim
