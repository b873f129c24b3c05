#pragma once
// The integration state x = (q, v, z) and its dimensions.

#include <Eigen/Core>

namespace stiffsim {

struct Dimensions {
  int nq = 0;  // generalized positions
  int nv = 0;  // generalized velocities
  int nz = 0;  // miscellaneous first-order states
  int ny() const { return nv + nz; }
  int nx() const { return nq + nv + nz; }
  bool operator==(const Dimensions& o) const { return nq == o.nq && nv == o.nv && nz == o.nz; }
};

// One flat vector x = [q; v; z] so integrators do their arithmetic on it
// directly; the segment views name the parts.
struct State {
  double t = 0.0;
  Eigen::VectorXd x;

  State() = default;
  State(double time, Eigen::VectorXd values) : t(time), x(std::move(values)) {}

  auto q(const Dimensions& d) { return x.segment(0, d.nq); }
  auto v(const Dimensions& d) { return x.segment(d.nq, d.nv); }
  auto z(const Dimensions& d) { return x.segment(d.nq + d.nv, d.nz); }
  auto y(const Dimensions& d) { return x.segment(d.nq, d.ny()); }
  auto q(const Dimensions& d) const { return x.segment(0, d.nq); }
  auto v(const Dimensions& d) const { return x.segment(d.nq, d.nv); }
  auto z(const Dimensions& d) const { return x.segment(d.nq + d.nv, d.nz); }
  auto y(const Dimensions& d) const { return x.segment(d.nq, d.ny()); }
};

}  // namespace stiffsim
