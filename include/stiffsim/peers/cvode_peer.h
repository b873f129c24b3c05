#pragma once
// SUNDIALS CVODE (BDF, Newton, direct linear solver) as a peer integrator for
// any stiffsim System, for the work-precision reports. Optional at build
// time: cvode_available() is false and run_cvode() throws without SUNDIALS.

#include <vector>

#include "stiffsim/peers/peer_run.h"
#include "stiffsim/state.h"
#include "stiffsim/system.h"

namespace stiffsim {

struct CvodeOptions {
  double relative_tolerance = 1e-6;
  double absolute_tolerance = 1e-8;
  double max_step = 0.0;  // 0: CVODE's default (unbounded)
  int max_order = 5;      // BDF order limit
};

bool cvode_available();

// Integrates x' = (N(q) v, M(q)^-1 F, f_z) from `initial` through every time in
// `sample_times` (ascending, > initial.t), returning x at each. Systems with a
// constant diagonal mass matrix and N = I get the analytic Jacobian
// [[0, I], [M^-1 K, M^-1 D]] (complete: request.complete) in the force
// Jacobians' sparse pattern, factored by KLU; others use CVODE's dense
// difference-quotient Jacobian and dense LU. PeerRun::settings says which.
// A CVODE failure (error test or convergence failures at the minimum step) is
// returned as failed with CVODE's message, never thrown.
PeerRun run_cvode(const System& system, const State& initial, const std::vector<double>& sample_times,
                  const CvodeOptions& options);

}  // namespace stiffsim
