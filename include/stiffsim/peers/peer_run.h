#pragma once
// The result of running a scene with another tool (a "peer" of the reports:
// SUNDIALS CVODE, MuJoCo), in stiffsim's own coordinates so that the reports
// measure every method's error the same way.

#include <Eigen/Core>
#include <string>
#include <vector>

namespace stiffsim {

struct PeerRun {
  std::string method;    // e.g. "cvode-bdf-klu", "mujoco-implicit", "mujoco-rk4"
  std::string settings;  // every setting that matters, stated in the reports
  std::vector<double> times;             // sample times reached, ascending
  std::vector<Eigen::VectorXd> samples;  // x = (q, v) at those times, stiffsim's coordinates
  double wall_seconds = 0.0;             // the integration alone (not setup)
  long steps = 0;
  long rhs_evaluations = 0;
  long jacobian_evaluations = 0;
  long linear_setups = 0;  // factorizations
  bool failed = false;     // stopped before the last sample time
  std::string message;     // why, when failed
};

}  // namespace stiffsim
