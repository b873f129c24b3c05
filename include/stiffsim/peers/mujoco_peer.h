#pragma once
// MuJoCo as a peer for articulated trees: it loads the same URDF, with the
// same joint springs and dampers, gravity, initial state and fixed step, on
// a welded or a floating base, and integrates with its `implicit` or `RK4`
// integrator. Optional at build time: mujoco_available() is false and
// run_mujoco() throws without it.

#include <array>
#include <map>
#include <string>
#include <vector>

#include "stiffsim/peers/peer_run.h"

namespace stiffsim {

struct MujocoProblem {
  std::string urdf_path;
  // Empty: the URDF's root link is welded to the world (as load_urdf without
  // floating_base). Otherwise the root link, which gets a free joint to the
  // world as load_urdf's "floating_base" (a URDF joint of type floating,
  // added in memory; MuJoCo makes a free joint of it). Its state is in
  // stiffsim's floating-joint coordinates, which are MuJoCo's free joint's:
  // q = (origin in the world, unit quaternion w, x, y, z), v = (velocity of
  // the origin in the world, angular velocity in the body frame).
  std::string floating_base_link;
  std::array<double, 7> initial_base_q{0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0};
  std::array<double, 6> initial_base_v{};
  // stiffsim's 1-DOF joint names in its coordinate order; samples come back
  // in stiffsim's order: q (the base's 7, then every joint), then v (the
  // base's 6, then every joint).
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

class ArticulatedSystem;

// The problem of an exact ArticulatedSystem loaded from `urdf_path`: its
// floating base (a floating root, if any), 1-DOF joints in coordinate order,
// springs, total damping, gravity and initial state. Integrator, step, end
// time and samples are left at their defaults for the caller. Throws
// std::invalid_argument for what MuJoCo's URDF import cannot represent the
// same way (planar joints, a floating joint below the root, bushings, a
// root motion that moves).
MujocoProblem mujoco_problem(const ArticulatedSystem& system, const std::string& urdf_path);

// Runs the problem. Joint limits, contacts and MuJoCo's default armature are
// switched off so that the model is MODELS.md's; PeerRun::settings states
// what was set. A non-finite state (MuJoCo's warning of a bad qacc) ends the
// run as failed at that time.
PeerRun run_mujoco(const MujocoProblem& problem);

}  // namespace stiffsim
