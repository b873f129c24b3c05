#pragma once
// What a picture of one component needs at one instant (System::draw):
// points in the world, their velocities, the line segments between them,
// and which points the world holds. The geometry (which nodes are pinned
// and where their paths put them, which springs or triangle edges to draw,
// where the bodies of a tree are) belongs to the system that knows it; the
// scene's drawing (io/scene_drawing.h) collects it, and the writers and
// scripts/render only plot it.

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include "stiffsim/attachment.h"

namespace stiffsim {

struct ComponentDrawing {
  std::string name;         // the component's name
  int component = 0;        // its index in the scene
  Eigen::Matrix3Xd points;  // world positions, m
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

// What a system is asked to draw beside its state: the points of it that
// attachments hold (AttachmentPoint::element and local), and its surface
// triangles in its own node numbering (may be empty or out of range: the
// system then draws what it has instead).
struct DrawingRequest {
  std::vector<AttachmentPoint> hooks;
  const std::vector<std::array<int, 3>>* triangles = nullptr;
};

}  // namespace stiffsim
