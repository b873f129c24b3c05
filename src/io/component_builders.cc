#include "component_builders.h"

namespace stiffsim {
namespace scene_file {

const std::vector<ComponentBuilder>& component_builders() {
  static const std::vector<ComponentBuilder> builders = {
      {"cloth",
       {"name", "type", "nodes", "size", "total_mass", "stretch", "shear", "bend", "pinned",
        "moving_pins", "drag", "masses", "velocities", "node_file"},
       build_cloth_component},
      {"rope",
       {"name", "type", "nodes", "length", "total_mass", "origin", "direction", "stretch", "bend",
        "pinned", "moving_pins", "drag", "masses", "velocities", "node_file"},
       build_rope_component},
      {"mesh",
       {"name", "type", "file", "density", "stretch", "bend", "pinned", "moving_pins", "drag",
        "masses", "velocities", "node_file"},
       build_mesh_component},
      {"urdf",
       {"name", "type", "file", "formulation", "floating_base", "initial", "joint_stiffness",
        "joint_rest", "joint_damping", "drives", "root_motion", "bushing"},
       build_urdf_component},
  };
  return builders;
}

const ComponentBuilder* find_component_builder(const std::string& type) {
  for (const ComponentBuilder& b : component_builders()) {
    if (b.type == type) return &b;
  }
  return nullptr;
}

std::vector<std::string> component_keys(const std::string& type) {
  const ComponentBuilder* builder = find_component_builder(type);
  return builder ? builder->keys : std::vector<std::string>{"name", "type"};
}

std::vector<std::string> component_types() {
  std::vector<std::string> types;
  for (const ComponentBuilder& b : component_builders()) types.push_back(b.type);
  return types;
}

}  // namespace scene_file
}  // namespace stiffsim
