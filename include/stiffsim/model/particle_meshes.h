#pragma once
// Builders of particle descriptions from the shapes MODELS.md defines: cloth
// grids, ropes and triangle meshes (stretch springs on edges, bend springs
// across interior edges).

#include <Eigen/Core>
#include <array>
#include <optional>
#include <string>
#include <vector>

#include "stiffsim/model/particles.h"

namespace stiffsim {

struct SpringParameters {
  double k = 0.0;  // N/m
  double c = 0.0;  // N s/m
};

struct ClothSpec {
  std::string name = "cloth";
  int nx = 2, ny = 2;
  double width = 1.0, height = 1.0;
  double total_mass = 1.0;
  std::optional<SpringParameters> stretch, shear, bend;  // absent: no such springs
  std::optional<std::vector<int>> pinned;                // absent: the two corners of row ny-1
  double drag = 0.0;
  Eigen::Vector3d gravity{0.0, 0.0, -9.81};
};

struct RopeSpec {
  std::string name = "rope";
  int nodes = 2;
  double length = 1.0;
  double total_mass = 1.0;
  std::optional<SpringParameters> stretch, bend;
  std::optional<std::vector<int>> pinned;  // absent: node 0
  double drag = 0.0;
  Eigen::Vector3d gravity{0.0, 0.0, -9.81};
  // Node 0's position and the direction the rope is laid out in (any
  // nonzero length; normalized).
  Eigen::Vector3d origin = Eigen::Vector3d::Zero(), direction = Eigen::Vector3d::UnitX();
};

struct TriangleMesh {
  std::vector<Eigen::Vector3d> vertices;
  std::vector<std::array<int, 3>> triangles;  // 0-based vertex indices
  // Where the mesh came from, when it was read from a file (load_obj fills
  // these): make_surface_mesh's errors about a face or a vertex then name the
  // file and line to fix, not only an index after triangulation. Empty for
  // meshes built in memory.
  std::string source;
  std::vector<int> vertex_lines;    // per vertex, its 1-based line in `source`
  std::vector<int> triangle_lines;  // per triangle, the line of its face
};

struct SurfaceMeshSpec {
  std::string name = "mesh";
  TriangleMesh mesh;
  double density = 1.0;  // kg/m^2; node mass = density * (sum of adjacent areas) / 3
  std::optional<SpringParameters> stretch, bend;
  std::vector<int> pinned;
  double drag = 0.0;
  Eigen::Vector3d gravity{0.0, 0.0, -9.81};
};

// Each throws InputError naming the component when a parameter is out of
// range (non-positive sizes, masses or counts, pinned index out of range).
ParticleDescription make_cloth(const ClothSpec& spec);
ParticleDescription make_rope(const RopeSpec& spec);
ParticleDescription make_surface_mesh(const SurfaceMeshSpec& spec);

}  // namespace stiffsim
