#include "stiffsim/linalg/linear_solver.h"

#include <cstdio>
#include <stdexcept>
#include <string>

#include "stiffsim/linalg/cholmod_solver.h"
#include "stiffsim/linalg/dense_solvers.h"
#include "stiffsim/linalg/umfpack_solver.h"

namespace stiffsim {
namespace {

// Up to kSmallSystemMaxSize unknowns a dense factorization beats the
// symbolic bookkeeping of a sparse one; above this density the fill-in makes
// the factor dense anyway.
constexpr double kDenseMinDensity = 0.1;
// SmallSystems::kByDensity (symmetric matrices): below kSmallSystemMaxSize a
// pattern denser than this stays dense. A factorization reused over many
// steps makes the solves the cost, and CHOLMOD's factor of a banded or grid
// pattern is a fraction of the dense one. VIE under error control, medians
// of 5 (the chord both ways, identical steps): models/rope.yaml (147
// unknowns, 10% dense) 0.67 s against 1.01 s at accuracy 1e-3 over 2 s,
// vie2 1.86 s against 2.88 s at 1e-5 over 1 s; an 8x8 cloth (186, 17%)
// 0.33 s against 0.38 s; a 10-node rope (27, 48%) 0.37 s against 0.38 s.
// Unsymmetric ones stay dense: UMFPACK's overhead lost on a 63-unknown
// rope with a box (0.070 s against 0.050 s).
constexpr double kSmallDenseMinDensity = 0.5;

std::string format_percent(double fraction) {
  char text[32];
  std::snprintf(text, sizeof text, "%.3g%%", 100.0 * fraction);
  return text;
}

std::unique_ptr<LinearSolver> construct(LinearSolverKind kind) {
  switch (kind) {
    case LinearSolverKind::kDenseLU:
      return std::make_unique<DenseLUSolver>();
    case LinearSolverKind::kDenseLDLT:
      return std::make_unique<DenseLDLTSolver>();
    case LinearSolverKind::kCholmod:
      return std::make_unique<CholmodSolver>();
    case LinearSolverKind::kUmfpack:
      return std::make_unique<UmfpackSolver>();
    case LinearSolverKind::kAuto:
      break;
  }
  throw std::logic_error("construct: kAuto has no solver of its own");
}

std::string describe(LinearSolverKind kind) {
  switch (kind) {
    case LinearSolverKind::kDenseLU:
      return "dense LU";
    case LinearSolverKind::kDenseLDLT:
      return "dense LDLT";
    case LinearSolverKind::kCholmod:
      return "CHOLMOD LL^T";  // simplicial or supernodal: see factorization_note()
    case LinearSolverKind::kUmfpack:
      return "UMFPACK";
    case LinearSolverKind::kAuto:
      break;
  }
  return "auto";
}

}  // namespace

LinearSolverKind parse_linear_solver_kind(const std::string& name) {
  if (name == "auto") return LinearSolverKind::kAuto;
  // "dense" is the safe dense choice: LU needs neither symmetry nor
  // definiteness. Ask for "dense-ldlt" explicitly to get LDLT.
  if (name == "dense" || name == "dense-lu") return LinearSolverKind::kDenseLU;
  if (name == "dense-ldlt") return LinearSolverKind::kDenseLDLT;
  if (name == "cholmod") return LinearSolverKind::kCholmod;
  if (name == "umfpack") return LinearSolverKind::kUmfpack;
  throw std::invalid_argument("unknown linear solver '" + name +
                              "'; expected one of: auto, dense, dense-lu, dense-ldlt, "
                              "cholmod, umfpack");
}

std::string to_string(LinearSolverKind kind) {
  switch (kind) {
    case LinearSolverKind::kAuto:
      return "auto";
    case LinearSolverKind::kDenseLU:
      return "dense-lu";
    case LinearSolverKind::kDenseLDLT:
      return "dense-ldlt";
    case LinearSolverKind::kCholmod:
      return "cholmod";
    case LinearSolverKind::kUmfpack:
      return "umfpack";
  }
  return "unknown";
}

LinearSolverChoice make_linear_solver(LinearSolverKind kind, const SparseMatrix& pattern,
                                      bool symmetric, SmallSystems small) {
  if (pattern.rows() != pattern.cols()) {
    throw std::invalid_argument("make_linear_solver: matrix is " + std::to_string(pattern.rows()) +
                                " x " + std::to_string(pattern.cols()) + ", not square");
  }
  const std::string symmetry = symmetric ? "symmetric" : "unsymmetric";
  if (kind != LinearSolverKind::kAuto) {
    if (!symmetric &&
        (kind == LinearSolverKind::kCholmod || kind == LinearSolverKind::kDenseLDLT)) {
      throw std::invalid_argument("linear solver '" + to_string(kind) +
                                  "' needs a symmetric matrix; use 'umfpack', 'dense-lu' "
                                  "or 'auto' for this unsymmetric one");
    }
    return {construct(kind), "requested " + to_string(kind) + " (" + symmetry + ")"};
  }

  const long n = static_cast<long>(pattern.rows());
  const double density =
      n == 0 ? 1.0 : static_cast<double>(pattern.nonZeros()) / (static_cast<double>(n) * n);
  const std::string size = "n = " + std::to_string(n);
  const std::string fill = "density " + format_percent(density);
  const bool by_density = small == SmallSystems::kByDensity && symmetric;
  const bool small_dense =
      n <= kSmallSystemMaxSize && (!by_density || density > kSmallDenseMinDensity);
  const bool dense = n <= kSmallSystemMaxSize ? small_dense : density > kDenseMinDensity;
  std::string why;
  if (n <= kSmallSystemMaxSize && by_density) {
    why = size + " <= " + std::to_string(kSmallSystemMaxSize) + " and " + fill +
          (small_dense ? " > " : " <= ") + format_percent(kSmallDenseMinDensity);
  } else if (n <= kSmallSystemMaxSize) {
    why = size + " <= " + std::to_string(kSmallSystemMaxSize);
  } else if (dense) {
    why = size + " > " + std::to_string(kSmallSystemMaxSize) + " but " + fill + " > " +
          format_percent(kDenseMinDensity);
  } else {
    why = size + " > " + std::to_string(kSmallSystemMaxSize) + " and " + fill +
          " <= " + format_percent(kDenseMinDensity);
  }
  LinearSolverKind picked;
  if (dense) {
    picked = symmetric ? LinearSolverKind::kDenseLDLT : LinearSolverKind::kDenseLU;
  } else {
    picked = symmetric ? LinearSolverKind::kCholmod : LinearSolverKind::kUmfpack;
  }
  return {construct(picked), why + ", " + symmetry + ": " + describe(picked)};
}

}  // namespace stiffsim
