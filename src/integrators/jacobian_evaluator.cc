#include "stiffsim/integrators/jacobian_evaluator.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "stiffsim/error.h"
#include "stiffsim/integrators/jacobian_scheme.h"

namespace stiffsim {

JacobianScheme parse_jacobian_scheme(const std::string& name) {
  if (name == "analytic") return JacobianScheme::kAnalytic;
  if (name == "forward") return JacobianScheme::kForward;
  if (name == "central") return JacobianScheme::kCentral;
  if (name == "automatic") return JacobianScheme::kAutomatic;
  throw InputError("unknown Jacobian scheme '" + name +
                   "' (expected analytic, forward, central or automatic)");
}

std::string to_string(JacobianScheme scheme) {
  switch (scheme) {
    case JacobianScheme::kAnalytic:
      return "analytic";
    case JacobianScheme::kForward:
      return "forward";
    case JacobianScheme::kCentral:
      return "central";
    case JacobianScheme::kAutomatic:
      return "automatic";
  }
  return "?";
}

namespace {

// Drake's increments (ImplicitIntegrator::ComputeForwardDiffJacobian and
// ComputeCentralDiffJacobian): sqrt(eps) balances truncation O(delta) against
// round-off O(eps / delta); eps^(5/12) is Drake's compromise between the
// central optimum eps^(1/3) and sqrt(eps).
const double kForwardIncrement = std::sqrt(std::numeric_limits<double>::epsilon());
const double kCentralIncrement = std::pow(std::numeric_limits<double>::epsilon(), 5.0 / 12.0);

// Absolute below 1, relative above, so that x_i + delta always moves x_i by
// about `e` significant digits.
double increment(double x, double e) { return std::abs(x) <= 1.0 ? e : e * std::abs(x); }

// The six blocks, in the order of the stacked matrix: row block r (F, f_z) by
// column block c (q, v, z) is blocks[3 r + c].
std::array<const SparseMatrix*, 6> blocks_of(const ForceJacobians& J) {
  return {&J.dF_dq, &J.dF_dv, &J.dF_dz, &J.dfz_dq, &J.dfz_dv, &J.dfz_dz};
}
std::array<SparseMatrix*, 6> blocks_of(ForceJacobians* J) {
  return {&J->dF_dq, &J->dF_dv, &J->dF_dz, &J->dfz_dq, &J->dfz_dv, &J->dfz_dz};
}
const char* const kBlockNames[6] = {"dF_dq", "dF_dv", "dF_dz", "dfz_dq", "dfz_dv", "dfz_dz"};

// Column block of column j of x and j's index inside it.
std::pair<int, int> column_block(const Dimensions& d, int j) {
  if (j < d.nq) return {0, j};
  if (j < d.nq + d.nv) return {1, j - d.nq};
  return {2, j - d.nq - d.nv};
}

std::string list_schemes(const Capabilities& caps, bool analytic, bool automatic) {
  std::string schemes;
  if (analytic && caps.analytic_jacobians) schemes += "analytic, ";
  schemes += "forward, central";
  if (automatic && caps.automatic_jacobians) schemes += " or automatic";
  return schemes;
}

}  // namespace

JacobianEvaluator::JacobianEvaluator(const System& system, JacobianScheme scheme)
    : system_(system),
      data_(system.make_data()),
      scheme_(scheme),
      dims_(system.dimensions()),
      differences_(scheme == JacobianScheme::kForward || scheme == JacobianScheme::kCentral) {
  const Capabilities caps = system.capabilities();
  if (scheme_ == JacobianScheme::kAnalytic && !caps.analytic_jacobians) {
    throw InputError(system.name() + " has no analytic Jacobians: use " +
                     list_schemes(caps, false, true));
  }
  if (scheme_ == JacobianScheme::kAutomatic && !caps.automatic_jacobians) {
    throw InputError(system.name() +
                     " has no automatic-differentiation Jacobians (its forces are not "
                     "templated on the scalar): use " +
                     list_schemes(caps, true, false));
  }
  // Differences colour the pattern here; the other schemes read it on
  // their first evaluation, so a run that never asks for a Jacobian (the
  // articulated-body recursion on a long exact chain, whose K and D are
  // dense) never builds it.
  if (differences_) prepare();
}

void JacobianEvaluator::prepare() {
  prepared_ = true;
  const ForceJacobians& pattern = system_.jacobian_pattern();
  const auto blocks = blocks_of(pattern);
  const int rows[2] = {dims_.nv, dims_.nz}, cols[3] = {dims_.nq, dims_.nv, dims_.nz};
  for (int b = 0; b < 6; ++b) {
    if (blocks[b]->rows() != rows[b / 3] || blocks[b]->cols() != cols[b % 3] ||
        !blocks[b]->isCompressed()) {
      throw std::logic_error(system_.name() + ": jacobian_pattern()." + kBlockNames[b] +
                             " is not a compressed " + std::to_string(rows[b / 3]) + " x " +
                             std::to_string(cols[b % 3]) + " matrix");
    }
    pattern_nonzeros_.push_back(blocks[b]->nonZeros());
  }
  if (!differences_) return;

  // One colouring of the stacked pattern over x: the columns of q, v and z
  // that share no row of (F, f_z) are perturbed together.
  std::vector<PatternBlock> stacked;
  for (int b = 0; b < 6; ++b) {
    stacked.push_back({blocks[b], b / 3 == 0 ? 0 : dims_.nv,
                       (b % 3 == 0) ? 0 : (b % 3 == 1 ? dims_.nq : dims_.nq + dims_.nv)});
  }
  colouring_ = colour_columns(dims_.ny(), dims_.nx(), stacked);
  // A structured system may know a better colouring (a lattice tiling):
  // taken when it is valid and cheaper.
  const std::vector<int> hint = system_.jacobian_colouring_hint();
  if (static_cast<int>(hint.size()) == dims_.nx()) {
    ColumnColouring known{hint, 0};
    for (int c : hint) known.colours = std::max(known.colours, c + 1);
    if (known.colours < colouring_.colours &&
        is_valid_colouring(dims_.ny(), dims_.nx(), stacked, known)) {
      colouring_ = std::move(known);
    }
  }
  colour_start_.assign(colouring_.colours + 1, 0);
  for (int c : colouring_.colour) {
    if (c >= 0) ++colour_start_[c + 1];
  }
  for (int c = 0; c < colouring_.colours; ++c) colour_start_[c + 1] += colour_start_[c];
  columns_by_colour_.resize(colour_start_[colouring_.colours]);
  std::vector<int> fill(colour_start_.begin(), colour_start_.end() - 1);
  for (int j = 0; j < dims_.nx(); ++j) {
    const int c = colouring_.colour[j];
    if (c >= 0) columns_by_colour_[fill[c]++] = j;
  }

  x_perturbed_.resize(dims_.nx());
  f_base_.resize(dims_.ny());
  f_plus_.resize(dims_.ny());
  f_minus_.resize(dims_.ny());
  step_plus_.setZero(dims_.nx());
  step_minus_.setZero(dims_.nx());
  step_sum_.setZero(dims_.nx());
#ifndef NDEBUG
  row_mark_.assign(dims_.ny(), -1);
#endif
}

int JacobianEvaluator::evaluations_per_jacobian() const {
  switch (scheme_) {
    case JacobianScheme::kForward:
      return colouring_.colours > 0 ? 1 + colouring_.colours : 0;
    case JacobianScheme::kCentral:
      return 2 * colouring_.colours;
    case JacobianScheme::kAnalytic:
    case JacobianScheme::kAutomatic:
      return 0;
  }
  return 0;
}

void JacobianEvaluator::check_structure(const ForceJacobians& J) const {
  const auto blocks = blocks_of(J);
  const int rows[2] = {dims_.nv, dims_.nz}, cols[3] = {dims_.nq, dims_.nv, dims_.nz};
  for (int b = 0; b < 6; ++b) {
    if (blocks[b]->rows() != rows[b / 3] || blocks[b]->cols() != cols[b % 3] ||
        blocks[b]->nonZeros() != pattern_nonzeros_[b] || !blocks[b]->isCompressed()) {
      throw std::logic_error("JacobianEvaluator: J." + std::string(kBlockNames[b]) +
                             " does not have the structure of " + system_.name() +
                             "'s jacobian_pattern()");
    }
  }
}

void JacobianEvaluator::evaluate_rates(double t, const Eigen::VectorXd& x,
                                       Eigen::VectorXd* f) {
  const auto q = x.segment(0, dims_.nq);
  const auto v = x.segment(dims_.nq, dims_.nv);
  const auto z = x.segment(dims_.nq + dims_.nv, dims_.nz);
  system_.forces(*data_, t, q, v, z, f->head(dims_.nv));
  if (acceleration_) {
    // F - M(q) a (JacobianRequest::acceleration).
    system_.mass_matrix(*data_, q, &mass_);
    f->head(dims_.nv).noalias() -=
        mass_ * Eigen::Map<const Eigen::VectorXd>(acceleration_, dims_.nv);
  }
  if (dims_.nz > 0) system_.misc_derivatives(*data_, t, q, v, z, f->tail(dims_.nz));
}

void JacobianEvaluator::store_columns(int colour, const Eigen::VectorXd& f_plus,
                                      const Eigen::VectorXd& f_minus, const Eigen::VectorXd& step,
                                      ForceJacobians* J) const {
  const auto blocks = blocks_of(J);
  for (int k = colour_start_[colour]; k < colour_start_[colour + 1]; ++k) {
    const int j = columns_by_colour_[k];
    const auto [c, local] = column_block(dims_, j);
    const double inverse_step = 1.0 / step[j];
    for (int r = 0; r < 2; ++r) {
      SparseMatrix& B = *blocks[3 * r + c];
      const int row0 = r == 0 ? 0 : dims_.nv;
      const int* inner = B.innerIndexPtr();
      double* values = B.valuePtr();
      for (int e = B.outerIndexPtr()[local]; e < B.outerIndexPtr()[local + 1]; ++e) {
        // Columns of one colour share no row, so every row of this column
        // moved because of x_j alone.
        values[e] = (f_plus[row0 + inner[e]] - f_minus[row0 + inner[e]]) * inverse_step;
      }
    }
  }
}

void JacobianEvaluator::check_nothing_lost(int colour, const Eigen::VectorXd& f_plus,
                                           const Eigen::VectorXd& f_minus) {
#ifndef NDEBUG
  // A row outside the pattern of every perturbed column must not depend on
  // them, so it is bit-for-bit unchanged; if it moved, the system's
  // jacobian_pattern() misses an entry and the Jacobian would silently lose
  // it. (A missing entry in a row that another column of the colour claims
  // is credited to that column instead: only exhaustive differences could
  // tell.)
  const auto blocks = blocks_of(system_.jacobian_pattern());
  ++mark_stamp_;
  for (int k = colour_start_[colour]; k < colour_start_[colour + 1]; ++k) {
    const auto [c, local] = column_block(dims_, columns_by_colour_[k]);
    for (int r = 0; r < 2; ++r) {
      const SparseMatrix& B = *blocks[3 * r + c];
      const int row0 = r == 0 ? 0 : dims_.nv;
      for (int e = B.outerIndexPtr()[local]; e < B.outerIndexPtr()[local + 1]; ++e) {
        row_mark_[row0 + B.innerIndexPtr()[e]] = mark_stamp_;
      }
    }
  }
  for (int i = 0; i < dims_.ny(); ++i) {
    const bool unchanged =
        f_plus[i] == f_minus[i] || (std::isnan(f_plus[i]) && std::isnan(f_minus[i]));
    assert((row_mark_[i] == mark_stamp_ || unchanged) &&
           "JacobianEvaluator: a rate changed outside the Jacobian pattern");
    (void)unchanged;
  }
#else
  (void)colour, (void)f_plus, (void)f_minus;
#endif
}

int JacobianEvaluator::evaluate(double t, const Eigen::VectorXd& x, const JacobianRequest& request,
                                ForceJacobians* J) {
  if (!prepared_) prepare();
  if (x.size() != dims_.nx()) {
    throw std::logic_error("JacobianEvaluator: x has " + std::to_string(x.size()) +
                           " entries, the system " + std::to_string(dims_.nx()));
  }
  check_structure(*J);
  const auto q = x.segment(0, dims_.nq);
  const auto v = x.segment(dims_.nq, dims_.nv);
  const auto z = x.segment(dims_.nq + dims_.nv, dims_.nz);

  switch (scheme_) {
    case JacobianScheme::kAnalytic:
      system_.force_jacobians(*data_, t, q, v, z, request, J);
      return 0;
    case JacobianScheme::kAutomatic:
      // Not counted: the dual-number pass costs about one evaluation of F
      // carried with derivative lanes, never one per colour.
      system_.automatic_force_jacobians(*data_, t, q, v, z, request, J);
      return 0;
    case JacobianScheme::kForward:
    case JacobianScheme::kCentral:
      break;
  }

  // Differences see the true (F, f_z): complete and unapproximated, so
  // request.definite and request.complete do not apply.
  J->approximated_terms = 0;
  const int colours = colouring_.colours;
  if (colours == 0) return 0;
  const bool forward = scheme_ == JacobianScheme::kForward;
  const double e = forward ? kForwardIncrement : kCentralIncrement;
  x_perturbed_ = x;
  acceleration_ = system_.capabilities().constant_mass_matrix ? nullptr : request.acceleration;
  if (acceleration_ && mass_.rows() == 0) mass_ = system_.mass_matrix_pattern();
  if (forward) evaluate_rates(t, x, &f_base_);

  for (int colour = 0; colour < colours; ++colour) {
    const int begin = colour_start_[colour], end = colour_start_[colour + 1];
    auto restore = [&] {
      for (int k = begin; k < end; ++k)
        x_perturbed_[columns_by_colour_[k]] = x[columns_by_colour_[k]];
    };
    // The exactly representable increment (x_j + delta) - x_j, so the
    // divisor is the step the state really took.
    for (int k = begin; k < end; ++k) {
      const int j = columns_by_colour_[k];
      x_perturbed_[j] = x[j] + increment(x[j], e);
      step_plus_[j] = x_perturbed_[j] - x[j];
    }
    evaluate_rates(t, x_perturbed_, &f_plus_);
    if (forward) {
      restore();
      check_nothing_lost(colour, f_plus_, f_base_);
      store_columns(colour, f_plus_, f_base_, step_plus_, J);
      continue;
    }
    for (int k = begin; k < end; ++k) {
      const int j = columns_by_colour_[k];
      x_perturbed_[j] = x[j] - increment(x[j], e);
      step_minus_[j] = x[j] - x_perturbed_[j];
      step_sum_[j] = step_plus_[j] + step_minus_[j];
    }
    evaluate_rates(t, x_perturbed_, &f_minus_);
    restore();
    check_nothing_lost(colour, f_plus_, f_minus_);
    store_columns(colour, f_plus_, f_minus_, step_sum_, J);
  }
  acceleration_ = nullptr;
  return evaluations_per_jacobian();
}

}  // namespace stiffsim
