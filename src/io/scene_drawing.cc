#include "stiffsim/io/scene_drawing.h"

#include <algorithm>
#include <cstdlib>
#include <set>
#include <utility>

#include "stiffsim/error.h"
#include "stiffsim/model/articulated.h"
#include "stiffsim/model/particles.h"

namespace stiffsim {
namespace {

// Each undirected edge once, as (smaller, larger), in a fixed order so that
// drawings (and tests) do not depend on the order of the triangles.
class EdgeSet {
 public:
  void add(int a, int b) {
    if (a != b) edges_.insert({std::min(a, b), std::max(a, b)});
  }
  bool empty() const { return edges_.empty(); }
  std::vector<std::array<int, 2>> list() const {
    std::vector<std::array<int, 2>> out;
    out.reserve(edges_.size());
    for (const auto& e : edges_) out.push_back({e.first, e.second});
    return out;
  }

 private:
  std::set<std::pair<int, int>> edges_;
};

ComponentDrawing draw_particles(const ParticleSystem& system,
                                const std::vector<std::array<int, 3>>* triangles, double t,
                                const Eigen::VectorXd& x, int q_offset, int v_offset) {
  ComponentDrawing out;
  out.name = system.name();
  const int nodes = system.node_count();
  out.points.resize(3, nodes);
  out.velocities.resize(3, nodes);
  for (int n = 0; n < nodes; ++n) {
    const int dof = system.dof_of_node(n);
    if (dof >= 0) {
      out.points.col(n) = x.segment<3>(q_offset + dof);
      out.velocities.col(n) = x.segment<3>(v_offset + dof);
    } else {
      // Pins can move: where the path puts the node at t, as the forces saw it.
      out.points.col(n) = system.pinned_position(n, t);
      out.velocities.col(n) = system.pinned_velocity(n, t);
      out.fixed.push_back(n);
    }
  }
  EdgeSet edges;
  if (triangles != nullptr) {
    out.triangles = *triangles;
    for (const auto& tri : *triangles) {
      edges.add(tri[0], tri[1]);
      edges.add(tri[1], tri[2]);
      edges.add(tri[2], tri[0]);
    }
  } else {
    // A rope's stretch springs join consecutive nodes; its bend springs (two
    // apart) would draw a second, confusing line along it.
    const std::vector<Spring>& springs = system.description().springs;
    for (const Spring& s : springs) {
      if (std::abs(s.a - s.b) == 1) edges.add(s.a, s.b);
    }
    if (edges.empty()) {
      for (const Spring& s : springs) edges.add(s.a, s.b);
    }
  }
  out.segments = edges.list();
  return out;
}

ComponentDrawing draw_articulated(const ArticulatedSystem& system,
                                  const std::vector<AttachmentPoint>& hooks, double t,
                                  const Eigen::VectorXd& x, int q_offset, int v_offset) {
  ComponentDrawing out;
  out.name = system.name();
  const Eigen::VectorXd q = x.segment(q_offset, system.dimensions().nq);
  // world_poses() runs the tree's own kinematics: for the compliant
  // formulation that tree is the forest of free bodies, whose q are their
  // frames' world poses, so it gives every body's frame in both.
  const std::vector<Pose<double>> world = system.world_poses(q);
  const int bodies = static_cast<int>(world.size());

  // The joints to draw, (parent, child, placement), parent -1 the world:
  // the tree's (a floating root is joined to nothing) and the compliant
  // formulation's bushings, which stand for the tree's joints.
  struct Joint {
    int parent, child;
    Eigen::Vector3d origin;  // of the joint frame in the parent's frame
  };
  std::vector<Joint> joints;
  const RigidTree& tree = system.tree();
  for (int i = 0; i < bodies; ++i) {
    const TreeBody& b = tree.bodies[i];
    if (b.parent < 0 && b.type == JointType::kFloating) continue;
    joints.push_back({b.parent, i, b.placement.translation()});
  }
  for (const Bushing& bu : system.options().bushings) {
    joints.push_back({bu.parent, bu.child, bu.placement.translation()});
  }

  // Velocities from the point kinematics: each point is (body, point in its
  // frame), body -1 an anchor on the base.
  const Eigen::VectorXd v = x.segment(v_offset, system.dimensions().nv);
  PointKinematics pk;
  std::vector<Eigen::Vector3d> velocities;
  auto velocity = [&](int body, const Eigen::Vector3d& local) -> Eigen::Vector3d {
    if (body < 0) return system.root_velocity(t);
    system.point_kinematics(t, body, local, q, v, &pk);
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
      out.fixed.push_back(from);
    } else {
      has_child[j.parent] = true;
    }
    out.segments.push_back({from, j.child});
  }
  for (int i = 0; i < bodies; ++i) {
    const Eigen::Vector3d& com = tree.bodies[i].inertia.com;
    if (has_child[i] || com.isZero(0.0)) continue;
    out.segments.push_back({i, static_cast<int>(points.size())});
    points.push_back(world[i].p + 2.0 * (world[i].R * com));
    velocities.push_back(velocity(i, 2.0 * com));
  }
  // Where attachments hold a body away from its origin, the body reaches
  // out to the point: a box hung by a corner is drawn to the corner.
  for (const AttachmentPoint& h : hooks) {
    if (h.local.isZero(0.0)) continue;
    out.segments.push_back({h.element, static_cast<int>(points.size())});
    points.push_back(world[h.element].p + world[h.element].R * h.local);
    velocities.push_back(velocity(h.element, h.local));
  }
  // A moving base carries every point, the world anchors too.
  const Eigen::Vector3d base = system.root_displacement(t);
  out.points.resize(3, static_cast<Eigen::Index>(points.size()));
  out.velocities.resize(3, static_cast<Eigen::Index>(points.size()));
  for (size_t k = 0; k < points.size(); ++k) {
    out.points.col(static_cast<Eigen::Index>(k)) = points[k] + base;
    out.velocities.col(static_cast<Eigen::Index>(k)) = velocities[k];
  }
  return out;
}

}  // namespace

std::vector<ComponentDrawing> draw_scene(
    const Scene& scene, const std::vector<std::vector<std::array<int, 3>>>& surfaces, double t,
    const Eigen::VectorXd& x) {
  const Dimensions dims = scene.dimensions();
  if (x.size() != dims.nx()) {
    throw InputError("drawing scene '" + scene.name() + "': state of size " +
                     std::to_string(x.size()) + ", expected " + std::to_string(dims.nx()));
  }
  std::vector<ComponentDrawing> out;
  for (int i = 0; i < scene.component_count(); ++i) {
    const System& component = scene.component(i);
    const int q_offset = scene.offsets(i).nq;
    const int v_offset = dims.nq + scene.offsets(i).nv;
    if (const auto* particles = dynamic_cast<const ParticleSystem*>(&component)) {
      const std::vector<std::array<int, 3>>* triangles = nullptr;
      if (i < static_cast<int>(surfaces.size()) && !surfaces[i].empty()) {
        triangles = &surfaces[i];
        const int nodes = particles->node_count();
        for (const auto& tri : *triangles) {
          if (*std::min_element(tri.begin(), tri.end()) < 0 ||
              *std::max_element(tri.begin(), tri.end()) >= nodes) {
            triangles = nullptr;  // not this component's numbering: draw springs instead
            break;
          }
        }
      }
      out.push_back(draw_particles(*particles, triangles, t, x, q_offset, v_offset));
      out.back().component = i;
    } else if (const auto* articulated = dynamic_cast<const ArticulatedSystem*>(&component)) {
      std::vector<AttachmentPoint> hooks;
      for (const Attachment& at : scene.attachments()) {
        for (const AttachmentPoint* p : {&at.a, &at.b}) {
          if (p->component == i) hooks.push_back(*p);
        }
      }
      out.push_back(draw_articulated(*articulated, hooks, t, x, q_offset, v_offset));
      out.back().component = i;
    }
  }
  return out;
}

}  // namespace stiffsim
