// The particle components of a scene file: cloth grids, ropes and OBJ
// meshes, with their springs, pins, per-node data and moving pins.

#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>

#include "component_builders.h"
#include "stiffsim/io/obj_mesh.h"
#include "stiffsim/model/particle_meshes.h"
#include "stiffsim/model/particles.h"

namespace stiffsim {
namespace scene_file {

bool is_spring_block(const std::string& key) {
  return key == "stretch" || key == "shear" || key == "bend";
}

std::vector<std::string> spring_keys() { return {"k", "c"}; }

namespace {

std::optional<SpringParameters> read_springs(const Section& component, const std::string& key) {
  if (!component.has(key)) return std::nullopt;
  const Section block = component.section(key, spring_keys());
  SpringParameters springs;
  springs.k = block.number("k", Range::kNonNegative);
  springs.c = block.number_or("c", Range::kNonNegative, 0.0);
  return springs;
}

std::vector<int> read_pinned(const Section& component, long node_count) {
  const YAML::Node n = component.get("pinned");
  if (!n.IsSequence()) {
    component.fail(n, "pinned must be a list of node indices, got " + node_kind(n));
  }
  std::vector<int> pinned;
  for (size_t i = 0; i < n.size(); ++i) {
    const long index =
        component.integer_value(n[i], "pinned[" + std::to_string(i) + "]", 0, node_count - 1);
    if (std::find(pinned.begin(), pinned.end(), index) != pinned.end()) {
      component.fail(n[i], "pinned lists node " + std::to_string(index) + " twice");
    }
    pinned.push_back(static_cast<int>(index));
  }
  return pinned;
}

// Per-node data: `node_file` (a CSV with a header naming some of node,
// mass, vx, vy, vz, pinned; one row per node it sets), then `masses` and
// `velocities`, each a list for every node or a map node -> value, which
// override the file. A node's mass replaces what the component gave it.
void read_node_data(const Section& c, const std::filesystem::path& base_dir,
                    ParticleDescription* d) {
  const long nodes = static_cast<long>(d->positions.size());
  auto velocities = [&]() -> std::vector<Eigen::Vector3d>& {
    if (d->velocities.empty()) d->velocities.assign(nodes, Eigen::Vector3d::Zero());
    return d->velocities;
  };
  if (c.has("node_file")) {
    const std::string file = c.text("node_file");
    std::filesystem::path resolved(file);
    if (resolved.is_relative()) resolved = base_dir / resolved;
    std::ifstream in(resolved);
    if (!in) {
      c.fail(c.get("node_file"), "node file '" + file + "' not found (looked for " +
                                     resolved.lexically_normal().string() + ")");
    }
    const std::string where = resolved.lexically_normal().string();
    auto bad = [&](int line, const std::string& what) {
      c.fail(c.get("node_file"), where + ":" + std::to_string(line) + ": " + what);
    };
    std::string line;
    int number = 0;
    std::vector<std::string> header;
    while (std::getline(in, line)) {
      ++number;
      if (!line.empty() && line.back() == '\r') line.pop_back();
      if (line.empty() || line[0] == '#') continue;
      std::vector<std::string> fields;
      std::stringstream split_line(line);
      for (std::string f; std::getline(split_line, f, ',');) {
        f.erase(0, f.find_first_not_of(" \t"));
        f.erase(f.find_last_not_of(" \t") + 1);
        fields.push_back(f);
      }
      if (header.empty()) {
        header = fields;
        for (const std::string& h : header) {
          if (!contains({"node", "mass", "vx", "vy", "vz", "pinned"}, h)) {
            bad(number,
                "unknown column '" + h + "' (expected some of: node, mass, vx, vy, vz, pinned)");
          }
        }
        if (!contains(header, std::string("node"))) bad(number, "the header has no 'node' column");
        continue;
      }
      if (fields.size() != header.size()) {
        bad(number, std::to_string(fields.size()) + " fields, expected " +
                        std::to_string(header.size()) + " (as the header)");
      }
      long node = -1;
      std::vector<double> values(header.size());
      for (std::size_t k = 0; k < header.size(); ++k) {
        double& value = values[k];
        const char* first = fields[k].data();
        const auto result = std::from_chars(first, first + fields[k].size(), value);
        if (result.ec != std::errc() || result.ptr != first + fields[k].size() ||
            !std::isfinite(value)) {
          bad(number, "column '" + header[k] + "': '" + fields[k] + "' is not a finite number");
        }
        if (header[k] == "node") {
          if (value != std::floor(value) || value < 0 || value >= nodes) {
            bad(number,
                "node " + fields[k] + " is not a node index 0.." + std::to_string(nodes - 1));
          }
          node = static_cast<long>(value);
        }
      }
      for (std::size_t k = 0; k < header.size(); ++k) {
        const double value = values[k];
        if (header[k] == "mass") {
          if (!(value > 0.0)) bad(number, "mass must be positive, got " + fields[k]);
          d->masses[node] = value;
        } else if (header[k] == "vx" || header[k] == "vy" || header[k] == "vz") {
          velocities()[node][header[k][1] - 'x'] = value;
        } else if (header[k] == "pinned" && value != 0.0 &&
                   std::find(d->pinned.begin(), d->pinned.end(), node) == d->pinned.end()) {
          d->pinned.push_back(static_cast<int>(node));
        }
      }
    }
  }
  // A list of one entry per node, or a map node -> entry.
  auto each = [&](const std::string& key, const auto& apply) {
    if (!c.has(key)) return;
    const YAML::Node n = c.get(key);
    if (n.IsSequence()) {
      if (static_cast<long>(n.size()) != nodes) {
        c.fail(n, key + " lists " + std::to_string(n.size()) + " nodes; the component has " +
                      std::to_string(nodes) + " (or give a map node -> value)");
      }
      for (long i = 0; i < nodes; ++i) apply(i, n[i], key + "[" + std::to_string(i) + "]");
    } else if (n.IsMap()) {
      for (const auto& entry : n) {
        const long i = c.integer_value(entry.first, key + " node", 0, nodes - 1);
        apply(i, entry.second, key + "." + entry.first.Scalar());
      }
    } else {
      c.fail(n, key + " must be a list (every node) or a map node -> value, got " + node_kind(n));
    }
  };
  each("masses", [&](long i, const YAML::Node& v, const std::string& what) {
    d->masses[i] = c.number_value(v, what, Range::kPositive);
  });
  each("velocities", [&](long i, const YAML::Node& v, const std::string& what) {
    if (!v.IsSequence() || v.size() != 3)
      c.fail(v, what + " must be [vx, vy, vz], got " + node_kind(v));
    for (int k = 0; k < 3; ++k) {
      velocities()[i][k] =
          c.number_value(v[k], what + "[" + std::to_string(k) + "]", Range::kFinite);
    }
  });
}

// `moving_pins`: a list of {node, x, y, z}, each axis a path (read_path)
// of the node's displacement from where the component puts it; a moving
// node is pinned whether or not `pinned` lists it.
void read_moving_pins(const Section& c, ParticleDescription* d) {
  if (!c.has("moving_pins")) return;
  const YAML::Node list = c.get("moving_pins");
  if (!list.IsSequence()) {
    c.fail(list, "moving_pins must be a list of {node, x, y, z}, got " + node_kind(list));
  }
  const long nodes = static_cast<long>(d->positions.size());
  for (std::size_t k = 0; k < list.size(); ++k) {
    const std::string what = "moving_pins[" + std::to_string(k) + "]";
    const Section m(c.doc(), list[k], c.context(), what + ".", {"node", "x", "y", "z"});
    PinMotion motion;
    const YAML::Node node = m.require("node");
    motion.node = static_cast<int>(m.integer_value(node, what + ".node", 0, nodes - 1));
    for (const PinMotion& other : d->pin_motions) {
      if (other.node == motion.node) {
        m.fail(node, what + ": node " + std::to_string(motion.node) + " already moves");
      }
    }
    const char* axes[3] = {"x", "y", "z"};
    for (int a = 0; a < 3; ++a) {
      if (m.has(axes[a]))
        motion.displacement[a] = read_path(m, m.get(axes[a]), what + "." + axes[a]);
    }
    if (std::find(d->pinned.begin(), d->pinned.end(), motion.node) == d->pinned.end()) {
      d->pinned.push_back(motion.node);
    }
    d->pin_motions.push_back(std::move(motion));
  }
}

struct BuiltComponent {
  ParticleDescription description;
  std::vector<std::array<int, 3>> surface;
};

BuiltComponent build_cloth(const Section& c, const std::string& name, const Eigen::Vector3d& g) {
  ClothSpec spec;
  spec.name = name;
  const YAML::Node nodes = c.list("nodes", 2, "[nx, ny]");
  const long nx = c.integer_value(nodes[0], "nodes[0]", 2, kMaxTotalNodes);
  const long ny = c.integer_value(nodes[1], "nodes[1]", 2, kMaxTotalNodes);
  if (nx * ny > kMaxTotalNodes) {
    c.fail(nodes, "nodes " + std::to_string(nx) + " x " + std::to_string(ny) + " = " +
                      std::to_string(nx * ny) + " exceeds the limit of " +
                      std::to_string(kMaxTotalNodes) + " nodes");
  }
  spec.nx = static_cast<int>(nx);
  spec.ny = static_cast<int>(ny);
  const YAML::Node size = c.list("size", 2, "[width, height] in metres");
  spec.width = c.number_value(size[0], "size[0]", Range::kPositive);
  spec.height = c.number_value(size[1], "size[1]", Range::kPositive);
  spec.total_mass = c.number("total_mass", Range::kPositive);
  spec.stretch = read_springs(c, "stretch");
  spec.shear = read_springs(c, "shear");
  spec.bend = read_springs(c, "bend");
  if (c.has("pinned")) spec.pinned = read_pinned(c, nx * ny);
  spec.drag = c.number_or("drag", Range::kNonNegative, 0.0);
  spec.gravity = g;

  BuiltComponent built;
  built.description = with_location(c, name, [&] { return make_cloth(spec); });
  // Two triangles per grid cell, counter-clockwise seen from +z.
  for (int j = 0; j + 1 < spec.ny; ++j) {
    for (int i = 0; i + 1 < spec.nx; ++i) {
      const int a = i + spec.nx * j, b = a + 1, d = a + spec.nx, e = d + 1;
      built.surface.push_back({a, b, e});
      built.surface.push_back({a, e, d});
    }
  }
  return built;
}

BuiltComponent build_rope(const Section& c, const std::string& name, const Eigen::Vector3d& g) {
  RopeSpec spec;
  spec.name = name;
  spec.nodes = static_cast<int>(c.integer("nodes", 2, kMaxTotalNodes));
  spec.length = c.number("length", Range::kPositive);
  spec.total_mass = c.number("total_mass", Range::kPositive);
  for (auto [key, target] :
       {std::make_pair("origin", &spec.origin), std::make_pair("direction", &spec.direction)}) {
    if (!c.has(key)) continue;
    const YAML::Node n = c.list(key, 3, "[x, y, z]");
    for (int i = 0; i < 3; ++i) {
      (*target)[i] =
          c.number_value(n[i], std::string(key) + "[" + std::to_string(i) + "]", Range::kFinite);
    }
    if (std::string(key) == "direction" && !(target->norm() > 0.0)) {
      c.fail(n, "direction must not be zero");
    }
  }
  spec.stretch = read_springs(c, "stretch");
  spec.bend = read_springs(c, "bend");
  if (c.has("pinned")) spec.pinned = read_pinned(c, spec.nodes);
  spec.drag = c.number_or("drag", Range::kNonNegative, 0.0);
  spec.gravity = g;
  BuiltComponent built;
  built.description = with_location(c, name, [&] { return make_rope(spec); });
  return built;
}

BuiltComponent build_mesh(const Section& c, const std::string& name, const Eigen::Vector3d& g,
                          const std::filesystem::path& base_dir) {
  SurfaceMeshSpec spec;
  spec.name = name;
  const std::string file = c.text("file");
  std::filesystem::path resolved(file);
  if (resolved.is_relative()) resolved = base_dir / resolved;
  std::error_code error;
  if (std::filesystem::is_directory(resolved, error)) {
    c.fail(c.get("file"), "mesh file '" + file + "' is a directory (" +
                              resolved.lexically_normal().string() + "), expected an OBJ file");
  }
  if (!std::filesystem::is_regular_file(resolved, error)) {
    c.fail(c.get("file"), "mesh file '" + file + "' not found (looked for " +
                              resolved.lexically_normal().string() + ")");
  }
  try {
    spec.mesh = load_obj(resolved.lexically_normal().string());
  } catch (const InputError& e) {
    c.fail(c.get("file"), e.what());
  }
  const long vertices = static_cast<long>(spec.mesh.vertices.size());
  if (vertices > kMaxTotalNodes) {
    c.fail(c.get("file"), "mesh '" + file + "' has " + std::to_string(vertices) +
                              " vertices; the limit is " + std::to_string(kMaxTotalNodes));
  }
  spec.density = c.number("density", Range::kPositive);
  spec.stretch = read_springs(c, "stretch");
  spec.bend = read_springs(c, "bend");
  if (c.has("pinned")) spec.pinned = read_pinned(c, vertices);
  spec.drag = c.number_or("drag", Range::kNonNegative, 0.0);
  spec.gravity = g;
  BuiltComponent built;
  built.surface = spec.mesh.triangles;
  // Errors about the mesh's faces and vertices name the OBJ file and line
  // themselves; the scene's part is the line that loads it.
  built.description =
      with_location(c, name, c.get("file"), [&] { return make_surface_mesh(spec); });
  return built;
}

// Per-node data and moving pins apply to every particle component alike.
std::unique_ptr<System> finish_particles(const Section& c, const std::string& name,
                                         const BuildContext& context, BuiltComponent built,
                                         std::vector<std::array<int, 3>>* surface) {
  read_node_data(c, context.base_dir, &built.description);
  read_moving_pins(c, &built.description);
  *context.total_nodes += static_cast<long>(built.description.positions.size());
  if (*context.total_nodes > kMaxTotalNodes) {
    c.fail(c.map(),
           "the scene has more than " + std::to_string(kMaxTotalNodes) + " nodes in total");
  }
  *surface = std::move(built.surface);
  return with_location(
      c, name, [&] { return std::make_unique<ParticleSystem>(std::move(built.description)); });
}

}  // namespace

std::unique_ptr<System> build_cloth_component(const Section& c, const std::string& name,
                                              const BuildContext& context,
                                              std::vector<std::array<int, 3>>* surface) {
  return finish_particles(c, name, context, build_cloth(c, name, context.gravity), surface);
}

std::unique_ptr<System> build_rope_component(const Section& c, const std::string& name,
                                             const BuildContext& context,
                                             std::vector<std::array<int, 3>>* surface) {
  return finish_particles(c, name, context, build_rope(c, name, context.gravity), surface);
}

std::unique_ptr<System> build_mesh_component(const Section& c, const std::string& name,
                                             const BuildContext& context,
                                             std::vector<std::array<int, 3>>* surface) {
  return finish_particles(c, name, context, build_mesh(c, name, context.gravity, context.base_dir),
                          surface);
}

}  // namespace scene_file
}  // namespace stiffsim
