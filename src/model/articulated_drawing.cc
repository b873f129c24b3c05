// ArticulatedSystem::draw (articulated.h).
#include "stiffsim/model/articulated.h"

namespace stiffsim {

bool ArticulatedSystem::draw(double t, const ConstVectorRef& q, const ConstVectorRef& v,
                             const DrawingRequest& request, ComponentDrawing* out) const {
  *out = ComponentDrawing{};
  out->name = name();
  // world_poses() runs the tree's own kinematics: for the compliant
  // formulation that tree is the forest of free bodies, whose q are their
  // frames' world poses, so it gives every body's frame in both.
  const std::vector<Pose<double>> world = world_poses(q);
  const int bodies = static_cast<int>(world.size());

  // The joints to draw, (parent, child, placement), parent -1 the world:
  // the tree's (a floating root is joined to nothing) and the compliant
  // formulation's bushings, which stand for the tree's joints.
  struct Joint {
    int parent, child;
    Eigen::Vector3d origin;  // of the joint frame in the parent's frame
  };
  std::vector<Joint> joints;
  for (int i = 0; i < bodies; ++i) {
    const TreeBody& b = model_.tree.bodies[i];
    if (b.parent < 0 && b.type == JointType::kFloating) continue;
    joints.push_back({b.parent, i, b.placement.translation()});
  }
  for (const Bushing& bu : options_.bushings) {
    joints.push_back({bu.parent, bu.child, bu.placement.translation()});
  }

  // Velocities from the point kinematics: each point is (body, point in its
  // frame), body -1 an anchor on the base.
  PointKinematics pk;
  std::vector<Eigen::Vector3d> velocities;
  auto velocity = [&](int body, const Eigen::Vector3d& local) -> Eigen::Vector3d {
    if (body < 0) return root_velocity(t);
    point_kinematics(t, body, local, q, v, &pk);
    return pk.p_dot;
  };
  std::vector<Eigen::Vector3d> points;
  for (int i = 0; i < bodies; ++i) {
    points.push_back(world[i].p);
    velocities.push_back(velocity(i, Eigen::Vector3d::Zero()));
  }
  std::vector<bool> has_child(bodies, false);
  for (const Joint& j : joints) {
    int from = j.parent;
    if (j.parent < 0) {
      from = static_cast<int>(points.size());
      points.push_back(j.origin);
      velocities.push_back(velocity(-1, Eigen::Vector3d::Zero()));
      out->fixed.push_back(from);
    } else {
      has_child[j.parent] = true;
    }
    out->segments.push_back({from, j.child});
  }
  for (int i = 0; i < bodies; ++i) {
    const Eigen::Vector3d& com = model_.tree.bodies[i].inertia.com;
    if (has_child[i] || com.isZero(0.0)) continue;
    out->segments.push_back({i, static_cast<int>(points.size())});
    points.push_back(world[i].p + 2.0 * (world[i].R * com));
    velocities.push_back(velocity(i, 2.0 * com));
  }
  // Where attachments hold a body away from its origin, the body reaches
  // out to the point: a box hung by a corner is drawn to the corner.
  for (const AttachmentPoint& h : request.hooks) {
    if (h.local.isZero(0.0)) continue;
    out->segments.push_back({h.element, static_cast<int>(points.size())});
    points.push_back(world[h.element].p + world[h.element].R * h.local);
    velocities.push_back(velocity(h.element, h.local));
  }
  // A moving base carries every point, the world anchors too.
  const Eigen::Vector3d base = root_displacement(t);
  out->points.resize(3, static_cast<Eigen::Index>(points.size()));
  out->velocities.resize(3, static_cast<Eigen::Index>(points.size()));
  for (size_t k = 0; k < points.size(); ++k) {
    out->points.col(static_cast<Eigen::Index>(k)) = points[k] + base;
    out->velocities.col(static_cast<Eigen::Index>(k)) = velocities[k];
  }
  return true;
}

}  // namespace stiffsim
