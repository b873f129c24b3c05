// ParticleSystem::draw (particles.h).
#include <algorithm>
#include <cstdlib>
#include <set>
#include <utility>

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

}  // namespace

bool ParticleSystem::draw(double t, const ConstVectorRef& q, const ConstVectorRef& v,
                          const DrawingRequest& request, ComponentDrawing* out) const {
  *out = ComponentDrawing{};
  out->name = name();
  const int nodes = node_count();
  out->points.resize(3, nodes);
  out->velocities.resize(3, nodes);
  for (int n = 0; n < nodes; ++n) {
    const int dof = dof_of_node(n);
    if (dof >= 0) {
      out->points.col(n) = q.segment<3>(dof);
      out->velocities.col(n) = v.segment<3>(dof);
    } else {
      // Pins can move: where the path puts the node at t, as the forces saw it.
      out->points.col(n) = pinned_position(n, t);
      out->velocities.col(n) = pinned_velocity(n, t);
      out->fixed.push_back(n);
    }
  }
  EdgeSet edges;
  const std::vector<std::array<int, 3>>* triangles = request.triangles;
  // Triangles out of range are not this component's numbering: springs are
  // drawn instead.
  if (triangles != nullptr) {
    for (const auto& tri : *triangles) {
      if (*std::min_element(tri.begin(), tri.end()) < 0 ||
          *std::max_element(tri.begin(), tri.end()) >= nodes) {
        triangles = nullptr;
        break;
      }
    }
  }
  if (triangles != nullptr && !triangles->empty()) {
    out->triangles = *triangles;
    for (const auto& tri : *triangles) {
      edges.add(tri[0], tri[1]);
      edges.add(tri[1], tri[2]);
      edges.add(tri[2], tri[0]);
    }
  } else {
    // A rope's stretch springs join consecutive nodes; its bend springs (two
    // apart) would draw a second, confusing line along it.
    const std::vector<Spring>& springs = description().springs;
    for (const Spring& s : springs) {
      if (std::abs(s.a - s.b) == 1) edges.add(s.a, s.b);
    }
    if (edges.empty()) {
      for (const Spring& s : springs) edges.add(s.a, s.b);
    }
  }
  out->segments = edges.list();
  return true;
}

}  // namespace stiffsim
