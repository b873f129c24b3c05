#pragma once
// Small systems and helpers the integrator tests share: each comes with the
// closed form or property the tests check against.

#include <Eigen/Core>
#include <cmath>
#include <memory>
#include <optional>
#include <vector>

#include "stiffsim/integrators/integrator_base.h"
#include "stiffsim/model/particle_meshes.h"
#include "stiffsim/model/particles.h"
#include "stiffsim/system.h"

namespace stiffsim {
namespace {

// One particle of mass m on a spring (k, c) to a pinned anchor, along x, no
// gravity: m x'' = -k (x - L) - c x'. State: q = (x, 0, 0), v = (x', 0, 0).
struct SpringDamper {
  double m = 1.0, k = 100.0, c = 2.0, L = 1.0, x0 = 1.2;
  std::unique_ptr<ParticleSystem> system() const {
    ParticleDescription d;
    d.name = "sd";
    d.positions = {Eigen::Vector3d::Zero(), Eigen::Vector3d(x0, 0, 0)};
    d.masses = {1.0, m};
    d.springs = {Spring{0, 1, L, k, c}};
    d.pinned = {0};
    d.gravity.setZero();
    return std::make_unique<ParticleSystem>(d);
  }
  double zeta() const { return c / (2 * std::sqrt(k * m)); }
  double w0() const { return std::sqrt(k / m); }
  double wd() const { return w0() * std::sqrt(1 - zeta() * zeta()); }
  // Underdamped closed form of the displacement u = x - L from u0, u'(0) = 0.
  double position(double t) const {
    const double u0 = x0 - L, a = zeta() * w0();
    return L + std::exp(-a * t) * (u0 * std::cos(wd() * t) + u0 * a / wd() * std::sin(wd() * t));
  }
  double velocity(double t) const {
    const double u0 = x0 - L, a = zeta() * w0();
    return -u0 * w0() * w0() / wd() * std::exp(-a * t) * std::sin(wd() * t);
  }
  // The exact state (q, v) at t.
  State exact(double t) const {
    Eigen::VectorXd x = Eigen::VectorXd::Zero(6);
    x[0] = position(t);
    x[3] = velocity(t);
    return State(t, x);
  }
  // Largest deviation of (x, x') from the closed form.
  double error(const State& s) const { return (s.x - exact(s.t).x).lpNorm<Eigen::Infinity>(); }
};

[[maybe_unused]] IntegratorSettings fixed(double h, bool estimate = false, double accuracy = 1e-10) {
  IntegratorSettings s;
  s.fixed_step = true;
  s.max_step = h;
  s.error_estimate = estimate;
  s.accuracy = accuracy;
  return s;
}

[[maybe_unused]] std::unique_ptr<ParticleSystem> cloth(int n, double k_stretch,
                                      std::optional<SpringParameters> bend = SpringParameters{
                                          10.0, 0.05}) {
  ClothSpec spec;
  spec.nx = spec.ny = n;
  spec.total_mass = 0.4;
  spec.stretch = SpringParameters{k_stretch, 0.5};
  spec.shear = SpringParameters{100.0, 0.1};
  spec.bend = bend;
  return std::make_unique<ParticleSystem>(make_cloth(spec));
}

[[maybe_unused]] double fitted_slope(const std::vector<double>& h, const std::vector<double>& e) {
  // Least-squares slope of log e against log h.
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  const double n = h.size();
  for (size_t i = 0; i < h.size(); ++i) {
    const double x = std::log(h[i]), y = std::log(e[i]);
    sx += x, sy += y, sxx += x * x, sxy += x * y;
  }
  return (n * sxy - sx * sy) / (n * sxx - sx * sx);
}

// The linear test equation z' = lambda z (nq = nv = 0, nz = 1): the
// stability function of a method is z(h) / z(0).
class LinearTestSystem : public System {
 public:
  explicit LinearTestSystem(double lambda) : lambda_(lambda) {
    pattern_ = empty_jacobians(dimensions());
    std::vector<Eigen::Triplet<double>> one{{0, 0, 1.0}};
    pattern_.dfz_dz.setFromTriplets(one.begin(), one.end());
    pattern_.dfz_dz.makeCompressed();
    mass_.resize(0, 0);
    mass_.makeCompressed();
  }
  Dimensions dimensions() const override { return Dimensions{0, 0, 1}; }
  Capabilities capabilities() const override {
    Capabilities c;
    c.identity_velocity_map = c.constant_mass_matrix = c.diagonal_mass_matrix = true;
    c.symmetric_jacobians = c.analytic_jacobians = true;
    return c;
  }
  std::string name() const override { return "linear"; }
  State initial_state() const override {
    State s;
    s.x = Eigen::VectorXd::Ones(1);
    return s;
  }
  std::vector<std::string> position_names() const override { return {}; }
  std::vector<std::string> velocity_names() const override { return {}; }
  std::vector<std::string> misc_names() const override { return {"y"}; }
  const SparseMatrix& mass_matrix_pattern() const override { return mass_; }
  void mass_matrix(SystemData&, const ConstVectorRef&, SparseMatrix*) const override {}
  void forces(SystemData&, double, const ConstVectorRef&, const ConstVectorRef&,
              const ConstVectorRef&, VectorRef) const override {}
  void misc_derivatives(SystemData&, double, const ConstVectorRef&, const ConstVectorRef&,
                        const ConstVectorRef& z, VectorRef zdot) const override {
    zdot = lambda_ * z;
  }
  const ForceJacobians& jacobian_pattern() const override { return pattern_; }
  void force_jacobians(SystemData&, double, const ConstVectorRef&, const ConstVectorRef&,
                       const ConstVectorRef&, const JacobianRequest&,
                       ForceJacobians* J) const override {
    J->dfz_dz.valuePtr()[0] = lambda_;
  }

 private:
  double lambda_;
  ForceJacobians pattern_;
  SparseMatrix mass_;
};

}  // namespace
}  // namespace stiffsim
