#pragma once
// What a picture of a scene needs at one instant: per drawable component,
// points in the world and the line segments between them. The Python module
// hands it to scripts/render, which only plots; the geometry (which nodes
// are pinned and where their paths put them, which springs or triangle
// edges to draw, where the bodies of a tree are) stays in the library.
//
// Particle components (cloth, rope, mesh): one point per node in node
// order, free nodes from the state and pinned ones where their motion puts
// them at t; segments are the edges of the component's surface triangles
// when it has a surface, else its springs between consecutive nodes (a
// rope's stretch springs, not its bend springs), else all its springs.
//
// Articulated components (URDF, exact or compliant): one point per body at
// its frame's origin (in body order), then one per joint anchored in the
// world (a root joint that is not floating, or a compliant bushing whose
// parent is the world) at the joint frame's origin, then one per leaf body
// whose centre of mass is off its origin, at origin + 2 (COM - origin): the
// far end of a uniform rod hung from its joint, so the last link of a chain
// is drawn too, then one per attachment point on a body away from its
// origin (a box hung by a corner reaches out to the corner); a base moved
// by a root motion carries them all. Segments: each joint's parent point
// (body origin or world anchor) to its child's origin, each leaf's origin
// to its tip and each body's origin to its attachment points.
//
// Components with no geometry (pure ODE systems) are left out.

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include "stiffsim/scene.h"

namespace stiffsim {

struct ComponentDrawing {
  std::string name;                          // the component's name
  int component = 0;                         // its index in the scene
  Eigen::Matrix3Xd points;                   // world positions, m
  // World velocities of the points, m/s: a node's; a tree's from its point
  // kinematics, an anchor's its base's.
  Eigen::Matrix3Xd velocities;
  std::vector<std::array<int, 2>> segments;  // pairs of point indices
  // The surface triangles drawn (in point numbering), where the component
  // has a valid surface; its segments are then their edges.
  std::vector<std::array<int, 3>> triangles;
  // Points held by the world: pinned nodes (moving or not), joint anchors.
  std::vector<int> fixed;
};

// The drawing of `scene` at time t and state x = [q; v; z]. `surfaces`, if
// given, holds per component its triangles in the component's node
// numbering (SceneConfig::surfaces); triangles out of a component's range
// are ignored in favour of its springs, as the VTK writer does. Throws
// InputError if x does not have the scene's size. Non-finite state values
// (the last row of a failed run) are drawn as they are.
std::vector<ComponentDrawing> draw_scene(
    const Scene& scene, const std::vector<std::vector<std::array<int, 3>>>& surfaces, double t,
    const Eigen::VectorXd& x);

}  // namespace stiffsim
