#include "stiffsim/integrators/integrator_base.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <sstream>

#include "stiffsim/error.h"
#include "stiffsim/integrators/wall_clock.h"

namespace stiffsim {
namespace {

// Step-size controller constants (Drake takes them from Simbody; see
// reference/drake_integrators.md section 3.4).
constexpr double kSafety = 0.9;
constexpr double kMinShrink = 0.1;
constexpr double kMaxGrow = 5.0;
constexpr double kHysteresisLow = 0.9;
constexpr double kHysteresisHigh = 1.2;
// A convergence failure halves the step.
constexpr double kSubdivision = 0.5;
// Growth of max |x| in one fixed explicit step taken as a blow-up.
constexpr double kBlowUpGrowth = 1e3;
// The slow blow-up of a fixed explicit step (a growth of a few times per step
// passes the test above for many steps), seen in the energy of a passive
// scene: a gain of more than ten times max(|E0|, kEnergyFloor) that is most
// of the kinetic energy (so it is not the bounded energy error of a stable
// run, a small fraction of the energy in motion, and does not depend on
// where the potential has its zero).
constexpr double kEnergyBlowUp = 10.0;
constexpr double kSpuriousKineticShare = 0.5;
constexpr double kEnergyFloor = 1e-6;
// The advice every explicit-instability message ends with.
constexpr const char* kUnstableExplicit =
    ": the explicit method is unstable at this step size (the scene is too stiff for it; use vie "
    "or ie)";

}  // namespace

IntegratorBase::IntegratorBase(const System& system, IntegratorSettings settings)
    : system_(system),
      data_(system.make_data()),
      settings_(settings),
      caps_(system.capabilities()),
      dims_(system.dimensions()) {
  if (!(settings_.max_step > 0.0) || !std::isfinite(settings_.max_step)) {
    throw InputError("step must be a finite positive number of seconds, got " +
                     std::to_string(settings_.max_step));
  }
  if (!(settings_.accuracy > 0.0) || !(settings_.accuracy <= 1.0)) {
    throw InputError("accuracy must be in (0, 1], got " + std::to_string(settings_.accuracy));
  }
  if (settings_.min_step < 0.0 || settings_.min_step > settings_.max_step) {
    throw InputError("minimum step must be in [0, step]");
  }
  if (std::isfinite(settings_.initial_step) &&
      (settings_.initial_step <= 0.0 || settings_.initial_step > settings_.max_step)) {
    throw InputError("initial step must be in (0, step]");
  }
}

IntegratorBase::~IntegratorBase() = default;

bool IntegratorBase::estimating_error() const {
  return !settings_.fixed_step || settings_.error_estimate;
}

void IntegratorBase::initialize(const State& initial) {
  if (initial.x.size() != dims_.nx()) {
    throw std::invalid_argument("initial state has size " + std::to_string(initial.x.size()) +
                                ", the system needs " + std::to_string(dims_.nx()));
  }
  state_ = initial;
  previous_ = initial;
  stats_ = IntegratorStatistics{};
  watch_energy_ = is_explicit() && settings_.fixed_step && caps_.passive && caps_.has_energy;
  initial_energy_ = watch_energy_ ? system_.energy(*data_, initial) : 0.0;
  candidate_.resize(dims_.nx());
  error_.resize(estimating_error() ? dims_.nx() : 0);
  // The pattern is taken on first use: a run on a structured Newton matrix
  // (a long exact chain, whose M is dense) may never need it.
  mass_matrix_ = SparseMatrix();
  mass_matrix_valid_ = false;
  mass_solver_.reset();
  mass_solver_factored_ = false;
  ideal_next_step_ = std::numeric_limits<double>::quiet_NaN();
  at_minimum_ = false;
  dense_valid_ = false;
  dense_f0_.resize(dims_.nx());
  dense_f1_.resize(dims_.nx());
  work_F_.resize(dims_.nv);
  work_zdot_.resize(dims_.nz);
  work_vdot_.resize(dims_.nv);
  do_initialize();
}

void IntegratorBase::check_energy_blow_up(double t, double h) {
  // A passive scene cannot gain energy; a gain of many times its energy
  // scale that is most of the energy in motion is instability growing a few
  // times per step. The kinetic energy is only needed once the gain is large.
  energy_workspace_.t = t;
  energy_workspace_.x = candidate_;
  const double e = system_.energy(*data_, energy_workspace_);
  const double gain = e - initial_energy_;
  bool blown_up = !std::isfinite(e);
  if (!blown_up && gain > kEnergyBlowUp * std::max(std::abs(initial_energy_), kEnergyFloor)) {
    const auto v = candidate_.segment(dims_.nq, dims_.nv);
    const double kinetic = 0.5 * v.dot(mass_matrix_at(candidate_.segment(0, dims_.nq)) * v);
    blown_up = gain > kSpuriousKineticShare * kinetic;
  }
  if (!blown_up) return;
  std::ostringstream what;
  what.precision(4);
  what << "energy grew from " << initial_energy_ << " J to " << e << " J in a passive scene";
  fail_step(h, what.str(), kUnstableExplicit);
}

double IntegratorBase::working_min_step() const {
  return std::max({1e-14, 1e-14 * std::abs(state_.t), settings_.min_step});
}

bool IntegratorBase::try_step(double h) {
  if (!do_step(h)) return false;
  // A non-finite result is a failed step, never an accepted one: the step
  // shrinks and, at the minimum step, the user gets an IntegrationError.
  return candidate_.allFinite() && (error_.size() == 0 || error_.allFinite());
}

void IntegratorBase::accept(double h) {
  previous_ = state_;
  state_.x.swap(candidate_);
  state_.t += h;
  dense_valid_ = false;
  on_accept(h);
  ++stats_.steps_taken;
  if (std::isnan(stats_.actual_initial_step_size_taken)) stats_.actual_initial_step_size_taken = h;
  if (std::isnan(stats_.largest_step_size_taken) || h > stats_.largest_step_size_taken) {
    stats_.largest_step_size_taken = h;
  }
}

void IntegratorBase::fail_at_minimum(double h, const std::string& why) const {
  std::ostringstream minimum;
  minimum.precision(6);
  minimum << " (minimum " << working_min_step() << " s)";
  fail_step(h, why, minimum.str());
}

void IntegratorBase::fail_step(double h, const std::string& why, const std::string& detail) const {
  // Name the entries a user should look at: non-finite ones first, then the
  // largest in magnitude.
  const Eigen::VectorXd& x = candidate_.size() == state_.x.size() ? candidate_ : state_.x;
  std::vector<int> order(x.size());
  std::iota(order.begin(), order.end(), 0);
  auto badness = [&](int i) { return std::isfinite(x[i]) ? std::abs(x[i]) : HUGE_VAL; };
  const int shown = std::min<int>(3, x.size());
  std::partial_sort(order.begin(), order.begin() + shown, order.end(),
                    [&](int a, int b) { return badness(a) > badness(b); });
  std::vector<std::string> names;
  for (auto& n : system_.position_names()) names.push_back("q:" + n);
  for (auto& n : system_.velocity_names()) names.push_back("v:" + n);
  for (auto& n : system_.misc_names()) names.push_back("z:" + n);
  std::ostringstream msg;
  msg.precision(6);
  msg << method_name() << ": " << why << " at t = " << state_.t << " s with step h = " << h << " s"
      << detail << "; largest state entries of the last attempt:";
  for (int k = 0; k < shown; ++k) {
    const int i = order[k];
    msg << (k ? ", " : " ") << (i < static_cast<int>(names.size()) ? names[i] : "x") << " = "
        << x[i];
  }
  throw IntegrationError(msg.str(), state_.t, h);
}

void IntegratorBase::step_at_most(double t_limit) {
  const double t0 = state_.t;
  const double h_max = t_limit - t0;
  if (!(h_max > 0.0)) throw std::invalid_argument("step_at_most: limit is not after t");

  if (settings_.fixed_step) {
    // Snap to the limit rather than leave a sliver of a step behind.
    double h = h_max < 1.001 * settings_.max_step ? h_max : settings_.max_step;
    while (!try_step(h)) {
      if (is_explicit()) {
        // An explicit step cannot fail to converge: a non-finite result is
        // instability, and halving would only hide that the fixed step the
        // user asked for is too large.
        fail_step(h, "state became non-finite", kUnstableExplicit);
      }
      h *= kSubdivision;
      ++stats_.substep_failures;
      ++stats_.step_shrinkages_from_substep_failures;
      if (h < working_min_step()) fail_at_minimum(h, "Newton iteration failed to converge");
    }
    if (is_explicit()) {
      // Instability shows long before the state overflows: each step
      // multiplies it by the amplification factor of the fastest mode. A
      // resolved motion never grows the state a thousandfold in one step, so
      // such a step stops the run before garbage reaches the trajectory.
      const double before = std::max(state_.x.lpNorm<Eigen::Infinity>(), 1.0);
      const double after = candidate_.lpNorm<Eigen::Infinity>();
      if (after > kBlowUpGrowth * before) {
        std::ostringstream growth;
        growth.precision(3);
        growth << "state grew by a factor of " << after / before << " in one step";
        fail_step(h, growth.str(), kUnstableExplicit);
      }
      if (watch_energy_) check_energy_blow_up(t0 + h, h);
    }
    accept(h);
    if (h == h_max) state_.t = t_limit;
    return;
  }

  // Error-controlled step (reference/drake_integrators.md section 3.2).
  double h =
      std::isnan(ideal_next_step_)
          ? (std::isfinite(settings_.initial_step) ? settings_.initial_step : settings_.max_step)
          : ideal_next_step_;
  for (;;) {
    bool limited = false;
    if (h_max < 0.95 * h) {
      h = h_max;
      limited = true;
    } else if (h_max < 1.001 * h) {
      h = h_max;
    }
    h = std::min(h, settings_.max_step);
    double a = h;
    while (!try_step(a)) {
      a *= kSubdivision;
      ++stats_.substep_failures;
      ++stats_.step_shrinkages_from_substep_failures;
      if (a < working_min_step()) {
        if (is_explicit()) {
          fail_at_minimum(a, settings_.throw_on_minimum_step
                                 ? "state became non-finite"
                                 : "no step could be taken (the state became non-finite)");
        }
        if (settings_.throw_on_minimum_step) {
          fail_at_minimum(a,
                          "Newton iteration failed to converge (or the state became "
                          "non-finite)");
        }
        fail_at_minimum(a, "no step could be taken");
      }
    }
    h = a;
    const double err = state_change_norm(error_);
    // CalcAdjustedStepSize (section 3.4).
    const double accuracy = settings_.accuracy;
    const int p = error_estimate_order();
    bool accept_step;
    double next;
    if (!std::isfinite(err)) {
      accept_step = false;
      next = kMinShrink * h;
    } else {
      next = err == 0.0 ? kMaxGrow * h : kSafety * h * std::pow(accuracy / err, 1.0 / p);
      if (next > h) {
        at_minimum_ = false;
        if (next < kHysteresisHigh * h) next = h;
      }
      if (next < h) {
        if (at_minimum_) {
          next = h;
        } else if (err <= accuracy) {
          next = h;
        } else {
          next = std::min(next, kHysteresisLow * h);
        }
      }
      next = std::clamp(next, kMinShrink * h, kMaxGrow * h);
      next = std::min(next, settings_.max_step);
      if (next < working_min_step()) {
        if (next < h && settings_.throw_on_minimum_step) {
          fail_at_minimum(next, "error control wants a step below the minimum");
        }
        next = working_min_step();
        at_minimum_ = true;
      }
      accept_step = next >= h;
    }
    if (accept_step) {
      if (!limited) ideal_next_step_ = next;
      if (std::isnan(stats_.smallest_adapted_step_size_taken) ||
          (h < stats_.smallest_adapted_step_size_taken && h < h_max)) {
        stats_.smallest_adapted_step_size_taken = h;
      }
      accept(h);
      if (h == h_max) state_.t = t_limit;
      return;
    }
    ++stats_.step_shrinkages_from_error_control;
    h = next;
  }
}

void IntegratorBase::integrate_to(double t_final) {
  while (state_.t < t_final) step_at_most(t_final);
}

const SparseMatrix& IntegratorBase::mass_matrix_at(const ConstVectorRef& q) {
  if (mass_matrix_valid_ && (caps_.constant_mass_matrix || q == mass_q_)) return mass_matrix_;
  const auto start = WallClock::now();
  if (mass_matrix_.rows() == 0) mass_matrix_ = system_.mass_matrix_pattern();
  mass_q_ = q;
  system_.mass_matrix(*data_, q, &mass_matrix_);
  stats_.assembly_seconds += seconds_since(start);
  ++stats_.mass_matrix_assemblies;
  mass_matrix_valid_ = true;
  mass_solver_factored_ = false;
  return mass_matrix_;
}

void IntegratorBase::evaluate_forces(double t, const Eigen::VectorXd& x, Eigen::VectorXd* F,
                                     Eigen::VectorXd* zdot) {
  const auto start = WallClock::now();
  const auto q = x.segment(0, dims_.nq);
  const auto v = x.segment(dims_.nq, dims_.nv);
  const auto z = x.segment(dims_.nq + dims_.nv, dims_.nz);
  system_.forces(*data_, t, q, v, z, *F);
  if (dims_.nz > 0) system_.misc_derivatives(*data_, t, q, v, z, *zdot);
  ++stats_.derivative_evaluations;
  stats_.derivative_seconds += seconds_since(start);
}

void IntegratorBase::solve_mass_matrix(double t, const ConstVectorRef& q, const Eigen::VectorXd& F,
                                       Eigen::VectorXd* a) {
  const SparseMatrix& M = mass_matrix_at(q);
  a->resize(dims_.nv);
  if (caps_.diagonal_mass_matrix) {
    for (int i = 0; i < dims_.nv; ++i) (*a)[i] = F[i] / M.valuePtr()[i];
    return;
  }
  if (!mass_solver_) {
    LinearSolverChoice choice = make_linear_solver(LinearSolverKind::kAuto, M, true);
    mass_solver_ = std::move(choice.solver);
    mass_solver_->analyze(M);
    ++stats_.symbolic_analyses;
  }
  if (!mass_solver_factored_) {
    if (!mass_solver_->factorize(M)) {
      throw IntegrationError(
          method_name() + ": mass matrix is singular at t = " + std::to_string(t), t, 0.0);
    }
    mass_solver_factored_ = true;
  }
  mass_solver_->solve(F, a);
}

void IntegratorBase::evaluate_state_derivative(double t, const Eigen::VectorXd& x,
                                               Eigen::VectorXd* xdot) {
  xdot->resize(dims_.nx());
  const auto q = x.segment(0, dims_.nq);
  const auto v = x.segment(dims_.nq, dims_.nv);
  if (caps_.identity_velocity_map) {
    xdot->segment(0, dims_.nq) = v;
  } else {
    system_.map_velocity_to_qdot(q, v, xdot->segment(0, dims_.nq));
    ++stats_.velocity_map_evaluations;
  }
  evaluate_forces(t, x, &work_F_, &work_zdot_);
  solve_mass_matrix(t, q, work_F_, &work_vdot_);
  xdot->segment(dims_.nq, dims_.nv) = work_vdot_;
  xdot->segment(dims_.nq + dims_.nv, dims_.nz) = work_zdot_;
}

double IntegratorBase::state_change_norm(const Eigen::VectorXd& dx) const {
  // Weighted infinity norm with unit weights. Quaternion components are
  // dimensionless like radians (a rotation by a small angle a changes them by
  // about a/2), so they are measured directly rather than through N^+.
  if (dx.size() == 0) return 0.0;
  if (!dx.allFinite()) return std::numeric_limits<double>::quiet_NaN();
  return dx.lpNorm<Eigen::Infinity>();
}

void IntegratorBase::interpolate(double t, Eigen::VectorXd* x) {
  const double t0 = previous_.t, t1 = state_.t;
  const double h = t1 - t0;
  if (h <= 0.0 || t >= t1) {
    *x = state_.x;
    return;
  }
  if (t <= t0) {
    *x = previous_.x;
    return;
  }
  if (do_interpolate(t, x)) return;
  if (!dense_valid_) {
    const long before = stats_.derivative_evaluations;
    evaluate_state_derivative(t0, previous_.x, &dense_f0_);
    evaluate_state_derivative(t1, state_.x, &dense_f1_);
    stats_.dense_output_evaluations += stats_.derivative_evaluations - before;
    dense_valid_ = true;
  }
  const double s = (t - t0) / h, s2 = s * s, s3 = s2 * s;
  const double h00 = 2 * s3 - 3 * s2 + 1, h10 = s3 - 2 * s2 + s;
  const double h01 = -2 * s3 + 3 * s2, h11 = s3 - s2;
  *x = h00 * previous_.x + (h10 * h) * dense_f0_ + h01 * state_.x + (h11 * h) * dense_f1_;
}

IntegratorReport IntegratorBase::report() const {
  IntegratorReport r;
  r.method = method_name();
  r.mode = settings_.fixed_step ? "fixed-step" : "error-controlled";
  r.error_estimate = estimating_error();
  if (caps_.identity_velocity_map) r.skipped.push_back("N(q) products: N = I");
  if (caps_.constant_mass_matrix) r.skipped.push_back("mass matrix reassembly: M is constant");
  if (caps_.diagonal_mass_matrix) r.skipped.push_back("mass matrix factorization: M is diagonal");
  if (!estimating_error()) {
    r.skipped.push_back("error estimate: fixed-step mode without --error-estimate");
  }
  return r;
}

}  // namespace stiffsim
