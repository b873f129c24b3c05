#pragma once
// MuJoCo as a peer for articulated chains: it loads the same URDF, with the
// same joint springs and dampers, gravity, initial joint positions and fixed
// step, and integrates with its `implicit` or `RK4` integrator. Optional at
// build time: mujoco_available() is false and run_mujoco() throws without it.

#include <map>
#include <string>
#include <vector>

#include "stiffsim/peers/peer_run.h"

namespace stiffsim {

struct MujocoProblem {
  std::string urdf_path;
  // stiffsim's 1-DOF joint names in its coordinate order; samples come back
  // in this order (q of every joint, then v of every joint).
  std::vector<std::string> joints;
  std::vector<double> initial_q, initial_v;  // per joint of `joints`
  std::vector<double> stiffness, rest, damping;  // per joint: total damping (URDF's + scene's)
  double gravity[3] = {0.0, 0.0, -9.81};
  std::string integrator = "implicit";  // implicit | RK4 (| Euler)
  double step = 1e-3;
  double t_final = 1.0;
  std::vector<double> sample_times;  // ascending, multiples of step where possible
};

bool mujoco_available();

// Runs the problem. Joint limits, contacts and MuJoCo's default armature are
// switched off so that the model is MODELS.md's; PeerRun::settings states
// what was set. A non-finite state (MuJoCo's warning of a bad qacc) ends the
// run as failed at that time.
PeerRun run_mujoco(const MujocoProblem& problem);

}  // namespace stiffsim
