#include "stiffsim/model/particle_meshes.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <sstream>
#include <tuple>

#include "stiffsim/error.h"

namespace stiffsim {

namespace {

// A typo such as nodes: [100000, 100000] must fail with a message instead of
// trying to allocate 10^10 particles.
constexpr long kMaxNodes = 10'000'000;

// A triangle whose area is below this fraction of its longest edge squared is
// degenerate: its lumped masses and its normal are meaningless. Collinear
// vertices give exactly 0 in exact arithmetic and ~1e-16 in floating point.
constexpr double kDegenerateAreaRatio = 1e-12;

[[noreturn]] void fail(const std::string& component, const std::string& what) {
  throw InputError(component + ": " + what);
}

void check_positive(const std::string& component, const char* parameter, double value) {
  if (!(std::isfinite(value) && value > 0.0)) {
    fail(component,
         std::string(parameter) + " must be finite and > 0 (got " + format_number(value) + ")");
  }
}

void check_springs(const std::string& component, const char* kind,
                   const std::optional<SpringParameters>& p) {
  if (!p) return;
  if (!(std::isfinite(p->k) && p->k >= 0.0)) {
    fail(component,
         std::string(kind) + ".k must be finite and >= 0 (got " + format_number(p->k) + ")");
  }
  if (!(std::isfinite(p->c) && p->c >= 0.0)) {
    fail(component,
         std::string(kind) + ".c must be finite and >= 0 (got " + format_number(p->c) + ")");
  }
}

void check_common(const std::string& component, double drag, const Eigen::Vector3d& gravity) {
  if (!(std::isfinite(drag) && drag >= 0.0)) {
    fail(component, "drag must be finite and >= 0 (got " + format_number(drag) + ")");
  }
  if (!gravity.allFinite()) fail(component, "gravity must be finite");
}

void check_node_count(const std::string& component, long count) {
  if (count > kMaxNodes) {
    fail(component,
         std::to_string(count) + " nodes exceed the limit of " + std::to_string(kMaxNodes));
  }
}

void check_pinned(const std::string& component, const std::vector<int>& pinned, int nodes) {
  for (int p : pinned) {
    if (p < 0 || p >= nodes) {
      fail(component,
           "pinned node " + std::to_string(p) + " out of range [0, " + std::to_string(nodes) + ")");
    }
  }
}

// Rest length from the initial configuration (MODELS.md).
void add_spring(ParticleDescription* d, int a, int b, const SpringParameters& p) {
  Spring s;
  s.a = a;
  s.b = b;
  s.rest_length = (d->positions[b] - d->positions[a]).norm();
  s.k = p.k;
  s.c = p.c;
  d->springs.push_back(s);
}

}  // namespace

ParticleDescription make_cloth(const ClothSpec& spec) {
  const std::string& who = spec.name;
  if (spec.nx < 2 || spec.ny < 2) {
    fail(who, "nodes must be at least [2, 2] (got [" + std::to_string(spec.nx) + ", " +
                  std::to_string(spec.ny) + "])");
  }
  check_node_count(who, static_cast<long>(spec.nx) * spec.ny);
  check_positive(who, "size[0] (width)", spec.width);
  check_positive(who, "size[1] (height)", spec.height);
  check_positive(who, "total_mass", spec.total_mass);
  check_springs(who, "stretch", spec.stretch);
  check_springs(who, "shear", spec.shear);
  check_springs(who, "bend", spec.bend);
  check_common(who, spec.drag, spec.gravity);

  const int nx = spec.nx, ny = spec.ny, n = nx * ny;
  auto id = [nx](int i, int j) { return i + nx * j; };
  ParticleDescription d;
  d.name = spec.name;
  d.gravity = spec.gravity;
  d.drag = spec.drag;
  d.positions.resize(n);
  d.lattice.resize(n);
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      d.positions[id(i, j)] = {i * spec.width / (nx - 1), j * spec.height / (ny - 1), 0.0};
      d.lattice[id(i, j)] = {i, j};
    }
  }
  d.masses.assign(n, spec.total_mass / n);

  if (spec.stretch) {
    for (int j = 0; j < ny; ++j) {
      for (int i = 0; i < nx; ++i) {
        if (i + 1 < nx) add_spring(&d, id(i, j), id(i + 1, j), *spec.stretch);
        if (j + 1 < ny) add_spring(&d, id(i, j), id(i, j + 1), *spec.stretch);
      }
    }
  }
  if (spec.shear) {
    for (int j = 0; j + 1 < ny; ++j) {
      for (int i = 0; i + 1 < nx; ++i) {
        add_spring(&d, id(i, j), id(i + 1, j + 1), *spec.shear);
        add_spring(&d, id(i + 1, j), id(i, j + 1), *spec.shear);
      }
    }
  }
  if (spec.bend) {
    for (int j = 0; j < ny; ++j) {
      for (int i = 0; i < nx; ++i) {
        if (i + 2 < nx) add_spring(&d, id(i, j), id(i + 2, j), *spec.bend);
        if (j + 2 < ny) add_spring(&d, id(i, j), id(i, j + 2), *spec.bend);
      }
    }
  }

  d.pinned = spec.pinned ? *spec.pinned : std::vector<int>{nx * (ny - 1), nx * ny - 1};
  check_pinned(who, d.pinned, n);
  return d;
}

ParticleDescription make_rope(const RopeSpec& spec) {
  const std::string& who = spec.name;
  if (spec.nodes < 2)
    fail(who, "nodes must be at least 2 (got " + std::to_string(spec.nodes) + ")");
  check_node_count(who, spec.nodes);
  check_positive(who, "length", spec.length);
  check_positive(who, "total_mass", spec.total_mass);
  check_springs(who, "stretch", spec.stretch);
  check_springs(who, "bend", spec.bend);
  check_common(who, spec.drag, spec.gravity);

  if (!spec.origin.allFinite()) fail(who, "origin must be finite");
  if (!spec.direction.allFinite() || !(spec.direction.norm() > 0.0)) {
    fail(who, "direction must be a finite nonzero vector");
  }
  const Eigen::Vector3d u = spec.direction.normalized();
  const int n = spec.nodes;
  ParticleDescription d;
  d.name = spec.name;
  d.gravity = spec.gravity;
  d.drag = spec.drag;
  d.positions.resize(n);
  for (int i = 0; i < n; ++i) d.positions[i] = spec.origin + (i * spec.length / (n - 1)) * u;
  d.masses.assign(n, spec.total_mass / n);
  if (spec.stretch) {
    for (int i = 0; i + 1 < n; ++i) add_spring(&d, i, i + 1, *spec.stretch);
  }
  if (spec.bend) {
    for (int i = 0; i + 2 < n; ++i) add_spring(&d, i, i + 2, *spec.bend);
  }
  d.pinned = spec.pinned ? *spec.pinned : std::vector<int>{0};
  check_pinned(who, d.pinned, n);
  return d;
}

ParticleDescription make_surface_mesh(const SurfaceMeshSpec& spec) {
  const std::string& who = spec.name;
  const TriangleMesh& mesh = spec.mesh;
  check_positive(who, "density", spec.density);
  check_springs(who, "stretch", spec.stretch);
  check_springs(who, "bend", spec.bend);
  check_common(who, spec.drag, spec.gravity);
  check_node_count(who, static_cast<long>(mesh.vertices.size()));
  if (mesh.triangles.empty()) fail(who, "mesh has no triangles");
  const int n = static_cast<int>(mesh.vertices.size());
  // "<file>:<line>: " of a vertex or a triangle's face when the mesh was read
  // from a file, so the user is sent to the line to fix.
  auto at_line = [&](const std::vector<int>& lines, size_t i) {
    if (mesh.source.empty() || i >= lines.size()) return std::string();
    return mesh.source + ":" + std::to_string(lines[i]) + ": ";
  };
  auto at_vertex = [&](int i) { return at_line(mesh.vertex_lines, static_cast<size_t>(i)); };
  auto at_triangle = [&](size_t t) { return at_line(mesh.triangle_lines, t); };
  for (int i = 0; i < n; ++i) {
    if (!mesh.vertices[i].allFinite()) {
      fail(who, at_vertex(i) + "vertex " + std::to_string(i) + " has a non-finite coordinate");
    }
  }

  ParticleDescription d;
  d.name = spec.name;
  d.gravity = spec.gravity;
  d.drag = spec.drag;
  d.positions = mesh.vertices;
  d.masses.assign(n, 0.0);

  // One record per (triangle, edge): sorting brings the triangles that share
  // an edge together.
  struct EdgeUse {
    int lo, hi, opposite, triangle;
  };
  std::vector<EdgeUse> uses;
  uses.reserve(3 * mesh.triangles.size());
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    const std::array<int, 3>& tri = mesh.triangles[t];
    const std::string tag = at_triangle(t) + "triangle " + std::to_string(t) + " (vertices " +
                            std::to_string(tri[0]) + ", " + std::to_string(tri[1]) + ", " +
                            std::to_string(tri[2]) + ")";
    for (int v : tri) {
      if (v < 0 || v >= n) {
        fail(who, tag + ": vertex index out of range [0, " + std::to_string(n) + ")");
      }
    }
    const Eigen::Vector3d& p0 = mesh.vertices[tri[0]];
    const Eigen::Vector3d& p1 = mesh.vertices[tri[1]];
    const Eigen::Vector3d& p2 = mesh.vertices[tri[2]];
    const double area = 0.5 * (p1 - p0).cross(p2 - p0).norm();
    const double longest =
        std::max({(p1 - p0).squaredNorm(), (p2 - p1).squaredNorm(), (p0 - p2).squaredNorm()});
    if (!(area > kDegenerateAreaRatio * longest)) fail(who, tag + " has zero area (degenerate)");
    for (int v : tri) d.masses[v] += spec.density * area / 3.0;
    for (int e = 0; e < 3; ++e) {
      const int a = tri[e], b = tri[(e + 1) % 3], opposite = tri[(e + 2) % 3];
      uses.push_back({std::min(a, b), std::max(a, b), opposite, static_cast<int>(t)});
    }
  }
  for (int i = 0; i < n; ++i) {
    if (d.masses[i] == 0.0) {
      fail(who, at_vertex(i) + "vertex " + std::to_string(i) + " (OBJ vertex " +
                    std::to_string(i + 1) + ") belongs to no triangle, so it would have no mass");
    }
  }
  std::sort(uses.begin(), uses.end(), [](const EdgeUse& x, const EdgeUse& y) {
    return std::tie(x.lo, x.hi, x.triangle) < std::tie(y.lo, y.hi, y.triangle);
  });

  // Stretch springs first (one per unique edge, in edge order), then bend
  // springs across the interior edges, so the springs of each kind are
  // contiguous.
  std::vector<std::pair<int, int>> bend_pairs;
  for (size_t first = 0; first < uses.size();) {
    size_t last = first + 1;
    while (last < uses.size() && uses[last].lo == uses[first].lo &&
           uses[last].hi == uses[first].hi) {
      ++last;
    }
    if (spec.stretch) add_spring(&d, uses[first].lo, uses[first].hi, *spec.stretch);
    // Edges shared by more than two triangles (non-manifold) get no bend
    // spring: there is no single pair of opposite vertices.
    if (last - first == 2) {
      const EdgeUse& x = uses[first];
      const EdgeUse& y = uses[first + 1];
      if (x.opposite == y.opposite) {
        const std::string first_at = at_triangle(x.triangle);
        fail(who, at_triangle(y.triangle) + "triangles " + std::to_string(x.triangle) + " and " +
                      std::to_string(y.triangle) + " are the same triangle (vertices " +
                      std::to_string(x.lo) + ", " + std::to_string(x.hi) + ", " +
                      std::to_string(x.opposite) + ")" +
                      (first_at.empty()
                           ? std::string()
                           : "; the first is at " + first_at.substr(0, first_at.size() - 2)));
      }
      bend_pairs.emplace_back(x.opposite, y.opposite);
    }
    first = last;
  }
  if (spec.bend) {
    for (const auto& [a, b] : bend_pairs) add_spring(&d, a, b, *spec.bend);
  }

  d.pinned = spec.pinned;
  check_pinned(who, d.pinned, n);
  return d;
}

}  // namespace stiffsim
