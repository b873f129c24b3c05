#include "stiffsim/model/spring_element.h"

#include <cmath>
#include <sstream>

#include "stiffsim/error.h"

namespace stiffsim {

SpringElement::SpringElement(const Spring& spring, std::size_t index, int nodes,
                             const std::string& who)
    : spring_(spring) {
  const std::string tag =
      (who.empty() ? std::string("particles") : who) + ": spring " + std::to_string(index) + ": ";
  for (int end : {spring.a, spring.b}) {
    if (end < 0 || end >= nodes) {
      throw InputError(tag + "node " + std::to_string(end) + " out of range [0, " +
                       std::to_string(nodes) + ")");
    }
  }
  if (spring.a == spring.b) {
    throw InputError(tag + "connects node " + std::to_string(spring.a) + " to itself");
  }
  if (!(std::isfinite(spring.k) && spring.k >= 0.0)) {
    throw InputError(tag + "stiffness k must be finite and >= 0 (got " + format_number(spring.k) +
                     ")");
  }
  if (!(std::isfinite(spring.c) && spring.c >= 0.0)) {
    throw InputError(tag + "damping c must be finite and >= 0 (got " + format_number(spring.c) +
                     ")");
  }
  // Zero is legal (a zero-rest-length spring, even between coincident
  // nodes): its force k d is smooth everywhere.
  if (!(std::isfinite(spring.rest_length) && spring.rest_length >= 0.0)) {
    throw InputError(tag + "rest length must be finite and >= 0 (got " +
                     format_number(spring.rest_length) + ")");
  }
}

void SpringElement::jacobian_difference(const Eigen::Vector3d* x, const Eigen::Vector3d* v,
                                        const Eigen::Vector3d* x_tension,
                                        const JacobianRequest& request, Eigen::Matrix3d* S_out,
                                        Eigen::Matrix3d* C_out, long* approximated) const {
  Eigen::Matrix3d& S = *S_out;
  const Spring& sp = spring_;
  const SpringFrame<double> f = spring_frame(x[0], x[1]);
  // S = df_a/dx_b (f_b = -f_a, and f_a depends on x_b - x_a only).
  if (f.collapsed) {
    // Direction undefined. k I is the exact Jacobian of a zero-rest-length
    // spring (force k d), the only kind that can rest collapsed; for L > 0
    // the exact transverse stiffness diverges as l -> 0, and k I is a
    // finite, positive semidefinite stand-in for it.
    S = sp.k * Eigen::Matrix3d::Identity();
    if (request.definite && sp.rest_length > 0.0 && sp.k > 0.0) ++*approximated;
  } else {
    double transverse = 1.0 - sp.rest_length / f.l;
    if (x_tension) {
      const SpringFrame<double> p = spring_frame(x_tension[0], x_tension[1]);
      // A spring collapsed at p has no direction to carry its tension along.
      if (!p.collapsed) {
        const double reach = request.tension_carried ? p.u.dot(f.l * f.u) : p.l;
        transverse = (reach - sp.rest_length) / f.l;
      }
    }
    if (request.definite && transverse < 0.0) {
      // Choi & Ko 2002: a compressed spring's negative transverse stiffness
      // can make -K indefinite; the iteration matrix drops it.
      transverse = 0.0;
      if (sp.k > 0.0) ++*approximated;
    }
    const Eigen::Matrix3d uut = f.u * f.u.transpose();
    S = sp.k * (transverse * (Eigen::Matrix3d::Identity() - uut) + uut);
    if (request.complete && sp.c != 0.0) {
      // d/dd [c (w.u) u] with w = v_b - v_a and du/dd = P / l,
      // P = I - u u^T: c (u (P w)^T + (w.u) P) / l. Unsymmetric.
      const Eigen::Vector3d w = v[1] - v[0];
      const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - uut;
      S += (sp.c / f.l) * (f.u * (P * w).transpose() + w.dot(f.u) * P);
    }
  }
  *C_out = sp.c * f.u * f.u.transpose();
}

}  // namespace stiffsim
