#pragma once
// URDF files read with urdfdom into a RigidTree (MODELS.md): links, inertials,
// joints (revolute, continuous, prismatic, fixed, floating, planar), joint
// damping. Fixed joints weld their child into the parent exactly (mass, COM
// and inertia combined). What does not affect the dynamics (visual and
// collision geometry, materials, transmissions, gazebo blocks, joint limits,
// mimic joints, safety controllers, calibration, friction) is ignored and
// said once per file in `notes`; being ignored, it is never an error
// either, so revolute and prismatic joints need no <limit> (as in Drake and
// MuJoCo; urdfdom alone would require one).

#include <string>
#include <vector>

#include "stiffsim/model/rigid_tree.h"

namespace stiffsim {

struct UrdfOptions {
  std::string component_name;  // RigidTree::name; the robot name when empty
  bool floating_base = false;  // a floating joint "floating_base" between world and root
};

// Reads `path`. Throws InputError naming the file and the element (link or
// joint) for: a missing or unreadable file, broken XML, what urdfdom rejects
// (its message passed on), a cycle or several roots, a joint type outside
// the supported set, a zero axis, a non-finite number, a negative mass, a
// link's inertia tensor that is not positive semidefinite (about its COM; a
// point mass on a fixed joint is fine), a moving body with mass whose
// tensor about its COM, the links welded to it included, is not positive
// definite (then M(q) is positive definite at every q), and a moving
// subtree without mass (it would make M singular). Cycles and links with
// two parents are found before urdfdom sees the file. `notes` (may be null)
// receives one line per file listing what was ignored.
RigidTree load_urdf(const std::string& path, const UrdfOptions& options,
                    std::vector<std::string>* notes);

// The same from text in memory; `source_name` names it in messages.
RigidTree parse_urdf(const std::string& xml, const std::string& source_name,
                     const UrdfOptions& options, std::vector<std::string>* notes);

}  // namespace stiffsim
