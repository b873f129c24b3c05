// Every Jacobian scheme against the complete analytic Jacobian of the particle
// model (MODELS.md), the coloured differences' constant cost, and the block
// layout of x = (q, v, z) on small systems with misc states.

#include "stiffsim/integrators/jacobian_evaluator.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>

#include "stiffsim/error.h"
#include "stiffsim/integrators/implicit_integrator.h"
#include "stiffsim/model/particle_meshes.h"
#include "stiffsim/model/particles.h"

// Not under AddressSanitizer, whose own malloc a replacement would shadow.
#if defined(__GLIBC__) && !defined(__SANITIZE_ADDRESS__)
// Counts heap allocations while g_counting is set: evaluate() must allocate
// nothing (its workspaces are sized in the constructor).
extern "C" void* __libc_malloc(size_t size);
static std::atomic<bool> g_counting{false};
static std::atomic<long> g_allocations{0};
extern "C" void* malloc(size_t size) {
  if (g_counting.load(std::memory_order_relaxed)) ++g_allocations;
  return __libc_malloc(size);
}
#define STIFFSIM_COUNTS_ALLOCATIONS 1
#endif

namespace stiffsim {
namespace {

using Eigen::MatrixXd;
using Eigen::VectorXd;

constexpr JacobianScheme kAllSchemes[] = {JacobianScheme::kAnalytic, JacobianScheme::kForward,
                                          JacobianScheme::kCentral, JacobianScheme::kAutomatic};
const char* const kBlockNames[6] = {"dF_dq", "dF_dv", "dF_dz", "dfz_dq", "dfz_dv", "dfz_dz"};

std::array<const SparseMatrix*, 6> blocks(const ForceJacobians& J) {
  return {&J.dF_dq, &J.dF_dv, &J.dF_dz, &J.dfz_dq, &J.dfz_dv, &J.dfz_dz};
}

// Per block, max |A - B| over the entries divided by the largest |B| of that
// block: the scale a Newton matrix sees, so tiny entries need no relative
// match of their own (and an all-zero reference block demands exact zeros).
// Both matrices share one pattern, so stored values line up one to one.
std::array<double, 6> block_errors(const ForceJacobians& A, const ForceJacobians& B) {
  std::array<double, 6> errors{};
  const auto a = blocks(A), b = blocks(B);
  for (int k = 0; k < 6; ++k) {
    EXPECT_EQ(a[k]->nonZeros(), b[k]->nonZeros()) << kBlockNames[k];
    double diff = 0.0, scale = 0.0;
    for (Eigen::Index e = 0; e < b[k]->nonZeros(); ++e) {
      diff = std::max(diff, std::abs(a[k]->valuePtr()[e] - b[k]->valuePtr()[e]));
      scale = std::max(scale, std::abs(b[k]->valuePtr()[e]));
    }
    errors[k] = scale > 0.0 ? diff / scale : (diff > 0.0 ? INFINITY : 0.0);
  }
  return errors;
}

double max_error(const std::array<double, 6>& errors) {
  return *std::max_element(errors.begin(), errors.end());
}

ClothSpec cloth_spec(int n) {
  ClothSpec spec;
  spec.nx = spec.ny = n;
  spec.total_mass = 0.4;
  spec.stretch = SpringParameters{1e3, 2.0};
  spec.shear = SpringParameters{1e2, 0.5};
  spec.bend = SpringParameters{10.0, 0.1};
  spec.drag = 0.3;  // pins: the default two corners
  return spec;
}

RopeSpec rope_spec() {
  RopeSpec spec;
  spec.nodes = 25;
  spec.total_mass = 0.1;
  spec.stretch = SpringParameters{5e3, 1.0};
  spec.bend = SpringParameters{2.0, 0.1};
  spec.drag = 0.2;
  return spec;
}

// Positions moved from the rest grid by up to `jitter` times the spring
// spacing (some springs compressed, some stretched), velocities in [-1, 1].
constexpr double kJitter = 0.05;
VectorXd random_state(const ParticleSystem& sys, double spacing, double jitter, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  const Dimensions d = sys.dimensions();
  VectorXd x = sys.initial_state().x;
  for (int i = 0; i < d.nq; ++i) x[i] += jitter * spacing * uniform(rng);
  for (int i = d.nq; i < d.nx(); ++i) x[i] = uniform(rng);
  return x;
}

ForceJacobians evaluate(const System& sys, JacobianScheme scheme, const VectorXd& x,
                        bool complete = true, int* evaluations = nullptr) {
  JacobianEvaluator evaluator(sys, scheme);
  ForceJacobians J = sys.jacobian_pattern();
  JacobianRequest request;
  request.complete = complete;
  const int used = evaluator.evaluate(0.0, x, request, &J);
  EXPECT_EQ(used, evaluator.evaluations_per_jacobian());
  if (evaluations != nullptr) *evaluations = used;
  return J;
}

// Forward differences: truncation delta |F''| / 2 and round-off
// eps |F| / delta, both ~sqrt(eps) relative: 1e-7 to 1e-6 measured. Central
// ones: truncation ~eps^(5/6) but the same kind of round-off,
// eps |F| / (2 delta) ~ 4e-10 |F|, which bites in dF/dv, whose entries (c,
// drag) are small against F (the elastic forces): the test states keep
// |F| / max |dF/dv| near 5 (strains of a few percent), where that is 2e-9.
// AD is exact to round-off.
double tolerance(JacobianScheme scheme) {
  switch (scheme) {
    case JacobianScheme::kForward:
      return 1e-5;
    case JacobianScheme::kCentral:
    case JacobianScheme::kAutomatic:
      return 1e-8;
    case JacobianScheme::kAnalytic:
      return 0.0;
  }
  return 0.0;
}

void expect_every_scheme_matches_complete_analytic(const ParticleSystem& sys, const VectorXd& x,
                                                   const std::string& what) {
  const ForceJacobians reference = evaluate(sys, JacobianScheme::kAnalytic, x);
  for (JacobianScheme scheme : kAllSchemes) {
    const ForceJacobians J = evaluate(sys, scheme, x);
    const std::array<double, 6> errors = block_errors(J, reference);
    EXPECT_LE(max_error(errors), tolerance(scheme))
        << what << ", " << to_string(scheme) << ": dF/dq " << errors[0] << ", dF/dv " << errors[1];
    EXPECT_EQ(J.approximated_terms, 0);
    std::printf("  %-28s %-9s max relative difference dF/dq %.2e, dF/dv %.2e\n", what.c_str(),
                to_string(scheme).c_str(), errors[0], errors[1]);
  }
}

TEST(JacobianEvaluator, EverySchemeMatchesCompleteAnalyticOnACloth) {
  const ParticleSystem cloth(make_cloth(cloth_spec(10)));
  for (unsigned seed : {1u, 2u, 3u}) {
    expect_every_scheme_matches_complete_analytic(cloth,
                                                  random_state(cloth, 1.0 / 9, kJitter, seed),
                                                  "cloth 10x10 seed " + std::to_string(seed));
  }
}

TEST(JacobianEvaluator, EverySchemeMatchesCompleteAnalyticOnARope) {
  const ParticleSystem rope(make_rope(rope_spec()));
  for (unsigned seed : {4u, 5u, 6u}) {
    expect_every_scheme_matches_complete_analytic(rope, random_state(rope, 1.0 / 24, kJitter, seed),
                                                  "rope 25 seed " + std::to_string(seed));
  }
}

// Bounds on the colours of the stacked pattern [dF/dq dF/dv] that depend on
// the stencil only: no colouring beats the most columns met in one row, and
// greedy never needs more than one plus the most columns one column meets.
struct StencilBounds {
  int lower = 0, upper = 0;
};

// [dF/dq dF/dv] as one matrix over (q, v) (particle systems have no z).
SparseMatrix stacked_pattern(const System& sys) {
  const Dimensions d = sys.dimensions();
  PatternBuilder builder(d.nv, d.nq + d.nv);
  builder.add_pattern(sys.jacobian_pattern().dF_dq, 0, 0);
  builder.add_pattern(sys.jacobian_pattern().dF_dv, 0, d.nq);
  return builder.build();
}

StencilBounds stencil_bounds(const System& sys) {
  const SparseMatrix S = stacked_pattern(sys);
  const SparseMatrix rows = S.transpose();  // column i: the columns of row i
  StencilBounds bounds;
  for (int i = 0; i < rows.outerSize(); ++i) {
    bounds.lower = std::max(bounds.lower, static_cast<int>(rows.col(i).nonZeros()));
  }
  std::vector<int> seen(S.cols(), -1);
  for (int j = 0; j < S.outerSize(); ++j) {
    int met = 0;
    for (SparseMatrix::InnerIterator r(S, j); r; ++r) {
      for (SparseMatrix::InnerIterator c(rows, r.row()); c; ++c) {
        if (seen[c.row()] != j) seen[c.row()] = j, ++met;
      }
    }
    bounds.upper = std::max(bounds.upper, met);
  }
  return bounds;
}

TEST(JacobianEvaluator, ColouredDifferencesCostIsSetByTheStencilNotTheSize) {
  const ParticleSystem small(make_cloth(cloth_spec(10)));
  const ParticleSystem large(make_cloth(cloth_spec(60)));
  const ParticleSystem rope(make_rope(rope_spec()));
  const JacobianEvaluator small_forward(small, JacobianScheme::kForward);
  const JacobianEvaluator large_forward(large, JacobianScheme::kForward);
  const JacobianEvaluator rope_forward(rope, JacobianScheme::kForward);
  std::printf(
      "  colours of [dF/dq dF/dv] over (q, v): cloth 10x10 %d (%d columns), "
      "cloth 60x60 %d (%d columns), rope 25 %d (%d columns)\n",
      small_forward.colours(), small.dimensions().nx(), large_forward.colours(),
      large.dimensions().nx(), rope_forward.colours(), rope.dimensions().nx());

  // A node meets 12 others (4 stretch, 4 shear, 4 bend: the L1 ball of
  // radius 2), so a row holds 2 x 3 x 13 = 78 columns, and a column meets
  // the 6 columns of each node within L1 distance 4: 6 x 41 = 246. Both
  // cloths have interior nodes, so both share these bounds, whatever n.
  const StencilBounds small_bounds = stencil_bounds(small), large_bounds = stencil_bounds(large);
  EXPECT_EQ(small_bounds.lower, 78);
  EXPECT_EQ(small_bounds.upper, 246);
  EXPECT_EQ(large_bounds.lower, small_bounds.lower);
  EXPECT_EQ(large_bounds.upper, small_bounds.upper);
  for (const JacobianEvaluator* e : {&small_forward, &large_forward}) {
    EXPECT_GE(e->colours(), small_bounds.lower);
    EXPECT_LE(e->colours(), small_bounds.upper);
  }
  // The cloth's lattice colouring (ParticleSystem::jacobian_colouring_hint)
  // reaches the lower bound at every size: the same 78 colours, so the same
  // 79 forward evaluations, for 10x10 and 60x60.
  EXPECT_EQ(small_forward.colours(), 78);
  EXPECT_EQ(large_forward.colours(), 78);
  // Greedy alone stays within the bounds and drifts only slowly with size.
  const ColumnColouring small_greedy = colour_columns(stacked_pattern(small));
  const ColumnColouring large_greedy = colour_columns(stacked_pattern(large));
  EXPECT_GT(small_greedy.colours, 78);
  EXPECT_LE(large_greedy.colours, small_greedy.colours * 11 / 10);
  EXPECT_LE(large_greedy.colours, small_bounds.upper);
  // The rope's band (5 nodes a row) is coloured optimally by greedy.
  EXPECT_EQ(rope_forward.colours(), stencil_bounds(rope).lower);
  EXPECT_EQ(stencil_bounds(rope).lower, 30);

  int small_evaluations = 0, large_evaluations = 0;
  const VectorXd x = random_state(large, 1.0 / 59, kJitter, 7);
  const ForceJacobians large_J =
      evaluate(large, JacobianScheme::kForward, x, true, &large_evaluations);
  evaluate(small, JacobianScheme::kForward, random_state(small, 1.0 / 9, kJitter, 7), true,
           &small_evaluations);
  EXPECT_EQ(small_evaluations, 1 + small_forward.colours());
  EXPECT_EQ(large_evaluations, 1 + large_forward.colours());
  // The large cloth's differences are right too, not just cheap.
  const ForceJacobians reference = evaluate(large, JacobianScheme::kAnalytic, x);
  EXPECT_LE(max_error(block_errors(large_J, reference)), tolerance(JacobianScheme::kForward));

  const JacobianEvaluator large_central(large, JacobianScheme::kCentral);
  EXPECT_EQ(large_central.colours(), large_forward.colours());
  EXPECT_EQ(large_central.evaluations_per_jacobian(), 2 * large_central.colours());
}

TEST(JacobianEvaluator, AnalyticAndAutomaticAgreeOnTheRopeAtManyStates) {
  const ParticleSystem rope(make_rope(rope_spec()));
  double worst = 0.0;
  for (unsigned seed = 10; seed < 30; ++seed) {
    const VectorXd x = random_state(rope, 1.0 / 24, 0.4, seed);  // AD has no round-off issue
    worst = std::max(worst, max_error(block_errors(evaluate(rope, JacobianScheme::kAutomatic, x),
                                                   evaluate(rope, JacobianScheme::kAnalytic, x))));
  }
  std::printf("  rope, 20 states: automatic vs analytic (complete) max relative difference %.2e\n",
              worst);
  EXPECT_LE(worst, 1e-12);  // the same formula, derived twice: round-off only
}

TEST(JacobianEvaluator, AnalyticDefaultDropsOnlyTheDampingTermThroughTheSpringDirection) {
  ClothSpec spec = cloth_spec(6);
  const ParticleSystem damped(make_cloth(spec));
  const VectorXd x = random_state(damped, 0.2, 0.2, 11);
  const Dimensions d = damped.dimensions();
  const ForceJacobians complete = evaluate(damped, JacobianScheme::kAnalytic, x, true);
  const ForceJacobians dropped = evaluate(damped, JacobianScheme::kAnalytic, x, false);
  // dF/dv is the same; dF/dq differs, and only the complete one is unsymmetric.
  EXPECT_EQ(MatrixXd(complete.dF_dv), MatrixXd(dropped.dF_dv));
  const MatrixXd K_complete(complete.dF_dq), K_dropped(dropped.dF_dq);
  EXPECT_GT((K_complete - K_dropped).norm(), 1e-3 * K_complete.norm());
  EXPECT_TRUE(K_dropped.isApprox(K_dropped.transpose(), 1e-14));
  EXPECT_FALSE(K_complete.isApprox(K_complete.transpose(), 1e-6));

  // The difference is exactly d/dq of the damping force c ((v_b - v_a).u) u:
  // the Jacobian of the same cloth with k = 0, no gravity and no drag, whose
  // only force is the damping.
  ParticleDescription damping_only = make_cloth(spec);
  for (Spring& s : damping_only.springs) s.k = 0.0;
  damping_only.gravity.setZero();
  damping_only.drag = 0.0;
  const ParticleSystem dampers(damping_only);
  const MatrixXd K_damping(evaluate(dampers, JacobianScheme::kCentral, x).dF_dq);
  EXPECT_LE((K_complete - K_dropped - K_damping).cwiseAbs().maxCoeff(),
            1e-8 * K_damping.cwiseAbs().maxCoeff());

  // Without velocities, or without dampers, there is nothing to drop.
  VectorXd at_rest = x;
  at_rest.segment(d.nq, d.nv).setZero();
  EXPECT_EQ(MatrixXd(evaluate(damped, JacobianScheme::kAnalytic, at_rest, true).dF_dq),
            MatrixXd(evaluate(damped, JacobianScheme::kAnalytic, at_rest, false).dF_dq));
  spec.stretch->c = spec.shear->c = spec.bend->c = 0.0;
  const ParticleSystem undamped(make_cloth(spec));
  EXPECT_EQ(MatrixXd(evaluate(undamped, JacobianScheme::kAnalytic, x, true).dF_dq),
            MatrixXd(evaluate(undamped, JacobianScheme::kAnalytic, x, false).dF_dq));
}

TEST(JacobianEvaluator, DifferencesAndAutomaticIgnoreTheDefiniteRequest) {
  // A cloth shrunk by 3%: every spring compressed, so the definite analytic
  // Jacobian clamps; the other schemes still give the exact one.
  const ParticleSystem cloth(make_cloth(cloth_spec(5)));
  VectorXd x = random_state(cloth, 0.25, 0.01, 12);
  x.head(cloth.dimensions().nq) *= 0.97;
  const ForceJacobians exact = evaluate(cloth, JacobianScheme::kAnalytic, x);
  JacobianEvaluator analytic(cloth, JacobianScheme::kAnalytic);
  ForceJacobians clamped = cloth.jacobian_pattern();
  analytic.evaluate(0.0, x, JacobianRequest{true, true}, &clamped);
  ASSERT_GT(clamped.approximated_terms, 0);  // otherwise this test proves nothing
  for (JacobianScheme scheme :
       {JacobianScheme::kForward, JacobianScheme::kCentral, JacobianScheme::kAutomatic}) {
    JacobianEvaluator evaluator(cloth, scheme);
    ForceJacobians J = cloth.jacobian_pattern();
    J.approximated_terms = 99;
    evaluator.evaluate(0.0, x, JacobianRequest{true, false}, &J);
    EXPECT_EQ(J.approximated_terms, 0) << to_string(scheme);
    EXPECT_LE(max_error(block_errors(J, exact)), tolerance(scheme)) << to_string(scheme);
  }
}

#ifdef STIFFSIM_COUNTS_ALLOCATIONS
TEST(JacobianEvaluator, EvaluateAllocatesNothing) {
  const ParticleSystem cloth(make_cloth(cloth_spec(8)));
  const VectorXd x = random_state(cloth, 1.0 / 7, kJitter, 13);
  for (JacobianScheme scheme : kAllSchemes) {
    JacobianEvaluator evaluator(cloth, scheme);
    ForceJacobians J = cloth.jacobian_pattern();
    evaluator.evaluate(0.0, x, JacobianRequest{}, &J);
    g_allocations = 0;
    g_counting = true;
    evaluator.evaluate(0.0, x, JacobianRequest{}, &J);
    g_counting = false;
    EXPECT_EQ(g_allocations.load(), 0) << to_string(scheme);
  }
}
#endif

// --- Systems with misc states -------------------------------------------------

// Robertson's stiff chemical kinetics: nq = nv = 0, nz = 3, every block but
// dfz/dz empty. Analytic Jacobians only when asked, AD never.
class Robertson : public System {
 public:
  explicit Robertson(bool analytic) : analytic_(analytic) {
    pattern_ = empty_jacobians(dimensions());
    PatternBuilder dense(3, 3);
    dense.add_block(0, 0, 3, 3);
    pattern_.dfz_dz = dense.build();
  }
  Dimensions dimensions() const override { return Dimensions{0, 0, 3}; }
  Capabilities capabilities() const override {
    Capabilities c;
    c.analytic_jacobians = analytic_;
    return c;
  }
  std::string name() const override { return "robertson"; }
  State initial_state() const override { return State(0.0, Eigen::Vector3d(1.0, 0.0, 0.0)); }
  std::vector<std::string> position_names() const override { return {}; }
  std::vector<std::string> velocity_names() const override { return {}; }
  const SparseMatrix& mass_matrix_pattern() const override { return mass_; }
  void mass_matrix(SystemData&, const ConstVectorRef&, SparseMatrix*) const override {}
  void forces(SystemData&, double, const ConstVectorRef&, const ConstVectorRef&,
              const ConstVectorRef&, VectorRef) const override {}
  void misc_derivatives(SystemData&, double, const ConstVectorRef&, const ConstVectorRef&,
                        const ConstVectorRef& y, VectorRef ydot) const override {
    ydot[0] = -0.04 * y[0] + 1e4 * y[1] * y[2];
    ydot[2] = 3e7 * y[1] * y[1];
    ydot[1] = -ydot[0] - ydot[2];
  }
  const ForceJacobians& jacobian_pattern() const override { return pattern_; }
  void force_jacobians(SystemData&, double, const ConstVectorRef&, const ConstVectorRef&,
                       const ConstVectorRef& y, const JacobianRequest&,
                       ForceJacobians* J) const override {
    Eigen::Matrix3d A;
    A << -0.04, 1e4 * y[2], 1e4 * y[1],               //
        0.04, -1e4 * y[2] - 6e7 * y[1], -1e4 * y[1],  //
        0.0, 6e7 * y[1], 0.0;
    // A dense 3x3 pattern stores column-major.
    std::copy(A.data(), A.data() + 9, J->dfz_dz.valuePtr());
  }

 private:
  bool analytic_;
  ForceJacobians pattern_;
  SparseMatrix mass_{0, 0};
};

// Two positions, two velocities and one misc state, every block coupled:
//   F0 = -k q0 + sin(q1) z,   F1 = -c v1 + q0 v0,   fz = -z^3 + q1 v0.
class Coupled : public System {
 public:
  // With `drop_dfz_dq` the pattern misses dfz/dq1: a broken system, for the
  // debug check that differences lose nothing.
  explicit Coupled(bool drop_dfz_dq = false) {
    pattern_ = empty_jacobians(dimensions());
    auto dense = [](int rows, int cols) {
      PatternBuilder b(rows, cols);
      b.add_block(0, 0, rows, cols);
      return b.build();
    };
    pattern_.dF_dq = dense(2, 2);
    PatternBuilder dv(2, 2);
    dv.add(1, 0);
    dv.add(1, 1);
    pattern_.dF_dv = dv.build();
    PatternBuilder dz(2, 1);
    dz.add(0, 0);
    pattern_.dF_dz = dz.build();
    PatternBuilder zq(1, 2);
    if (!drop_dfz_dq) zq.add(0, 1);
    pattern_.dfz_dq = zq.build();
    PatternBuilder zv(1, 2);
    zv.add(0, 0);
    pattern_.dfz_dv = zv.build();
    pattern_.dfz_dz = dense(1, 1);
    PatternBuilder m(2, 2);
    m.add_diagonal(0, 2);
    mass_ = m.build();
  }
  Dimensions dimensions() const override { return Dimensions{2, 2, 1}; }
  Capabilities capabilities() const override {
    Capabilities c;
    c.analytic_jacobians = true;
    return c;
  }
  std::string name() const override { return "coupled"; }
  State initial_state() const override { return State(0.0, VectorXd::Zero(5)); }
  std::vector<std::string> position_names() const override { return {"a", "b"}; }
  std::vector<std::string> velocity_names() const override { return {"a", "b"}; }
  const SparseMatrix& mass_matrix_pattern() const override { return mass_; }
  void mass_matrix(SystemData&, const ConstVectorRef&, SparseMatrix* M) const override {
    std::fill(M->valuePtr(), M->valuePtr() + 2, 1.0);
  }
  void forces(SystemData&, double, const ConstVectorRef& q, const ConstVectorRef& v,
              const ConstVectorRef& z, VectorRef F) const override {
    F[0] = -kK * q[0] + std::sin(q[1]) * z[0];
    F[1] = -kC * v[1] + q[0] * v[0];
  }
  void misc_derivatives(SystemData&, double, const ConstVectorRef& q, const ConstVectorRef& v,
                        const ConstVectorRef& z, VectorRef zdot) const override {
    zdot[0] = -z[0] * z[0] * z[0] + q[1] * v[0];
  }
  const ForceJacobians& jacobian_pattern() const override { return pattern_; }
  void force_jacobians(SystemData&, double, const ConstVectorRef& q, const ConstVectorRef& v,
                       const ConstVectorRef& z, const JacobianRequest&,
                       ForceJacobians* J) const override {
    J->dF_dq.coeffRef(0, 0) = -kK;
    J->dF_dq.coeffRef(1, 0) = v[0];
    J->dF_dq.coeffRef(0, 1) = std::cos(q[1]) * z[0];
    J->dF_dq.coeffRef(1, 1) = 0.0;
    J->dF_dv.coeffRef(1, 0) = q[0];
    J->dF_dv.coeffRef(1, 1) = -kC;
    J->dF_dz.coeffRef(0, 0) = std::sin(q[1]);
    if (J->dfz_dq.nonZeros() > 0) J->dfz_dq.coeffRef(0, 1) = v[0];
    J->dfz_dv.coeffRef(0, 0) = q[1];
    J->dfz_dz.coeffRef(0, 0) = -3.0 * z[0] * z[0];
  }

 private:
  static constexpr double kK = 7.0, kC = 0.3;
  ForceJacobians pattern_;
  SparseMatrix mass_;
};

TEST(JacobianEvaluator, DifferencesHandleASystemWithOnlyMiscStates) {
  const Robertson robertson(true);
  // y2 is O(1) here, not the 1e-5 of the real reaction: Drake's increment is
  // absolute below |x| = 1, so a state of 1e-5 would be moved by 1e-3 of
  // itself and forward differences would lose the digits this test asks for.
  const VectorXd x = Eigen::Vector3d(0.5, 0.2, 0.3);
  int forward_evaluations = 0, central_evaluations = 0;
  const ForceJacobians exact = evaluate(robertson, JacobianScheme::kAnalytic, x);
  const ForceJacobians forward =
      evaluate(robertson, JacobianScheme::kForward, x, true, &forward_evaluations);
  const ForceJacobians central =
      evaluate(robertson, JacobianScheme::kCentral, x, true, &central_evaluations);
  // A dense 3x3 block: one colour per column.
  EXPECT_EQ(forward_evaluations, 4);
  EXPECT_EQ(central_evaluations, 6);
  EXPECT_LE(max_error(block_errors(forward, exact)), 1e-5);
  EXPECT_LE(max_error(block_errors(central, exact)), 1e-8);
}

TEST(JacobianEvaluator, DifferencesPlaceEveryBlockOfQVAndZ) {
  const Coupled coupled;
  const VectorXd x = (VectorXd(5) << 0.4, -1.3, 2.5, 0.8, 1.7).finished();
  const ForceJacobians exact = evaluate(coupled, JacobianScheme::kAnalytic, x);
  for (JacobianScheme scheme : {JacobianScheme::kForward, JacobianScheme::kCentral}) {
    int evaluations = 0;
    const std::array<double, 6> errors =
        block_errors(evaluate(coupled, scheme, x, true, &evaluations), exact);
    for (int k = 0; k < 6; ++k) {
      EXPECT_LE(errors[k], tolerance(scheme)) << to_string(scheme) << " " << kBlockNames[k];
    }
    JacobianEvaluator evaluator(coupled, scheme);
    // Row F1 holds q0, q1, v0 and v1: four colours at least. z (rows F0 and
    // fz) meets q0, q1 and v0 but not v1, whose colour it can share.
    EXPECT_EQ(evaluator.colours(), 4) << to_string(scheme);
  }
}

#ifndef NDEBUG
TEST(JacobianEvaluatorDeathTest, DebugBuildsCatchARateMovingOutsideThePattern) {
  // q1 has a colour of its own here, so f_z, outside its (broken) pattern,
  // moves while no perturbed column claims it. (A row that another column
  // of the same colour claims cannot be told apart: the check is a net, not
  // a proof.)
  const Coupled broken(true);
  JacobianEvaluator evaluator(broken, JacobianScheme::kForward);
  ForceJacobians J = broken.jacobian_pattern();
  const VectorXd x = (VectorXd(5) << 0.4, -1.3, 2.5, 0.8, 1.7).finished();
  EXPECT_DEATH(evaluator.evaluate(0.0, x, JacobianRequest{}, &J), "outside the Jacobian pattern");
}
#endif

TEST(JacobianEvaluator, RejectsSchemesTheSystemCannotProvide) {
  const Robertson no_analytic(false);
  try {
    JacobianEvaluator evaluator(no_analytic, JacobianScheme::kAnalytic);
    FAIL() << "analytic accepted without analytic Jacobians";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("robertson has no analytic Jacobians: use forward"),
              std::string::npos)
        << e.what();
  }
  try {
    JacobianEvaluator evaluator(no_analytic, JacobianScheme::kAutomatic);
    FAIL() << "automatic accepted without automatic Jacobians";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("robertson has no automatic-differentiation Jacobians"),
              std::string::npos)
        << e.what();
  }
  EXPECT_NO_THROW(JacobianEvaluator(no_analytic, JacobianScheme::kForward));
  EXPECT_NO_THROW(JacobianEvaluator(no_analytic, JacobianScheme::kCentral));
}

TEST(JacobianEvaluator, RejectsAJacobianWithAnotherStructure) {
  const ParticleSystem rope(make_rope(rope_spec()));
  JacobianEvaluator evaluator(rope, JacobianScheme::kForward);
  ForceJacobians J = empty_jacobians(rope.dimensions());
  EXPECT_THROW(evaluator.evaluate(0.0, rope.initial_state().x, JacobianRequest{}, &J),
               std::logic_error);
}

}  // namespace
}  // namespace stiffsim
