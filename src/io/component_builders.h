#pragma once
// The registry of component builders the scene loader dispatches to: per
// component type its allowed keys and the function that builds it. Adding a
// type is one entry here and its builder. Private to the scene loader.

#include <Eigen/Core>
#include <array>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "scene_reader.h"
#include "stiffsim/system.h"

namespace stiffsim {
namespace scene_file {

// Bounds the memory a scene can ask for (a 10^7-node cloth already needs
// gigabytes for its Jacobians); a typo like nodes: [10000, 10000] should be an
// error, not an out-of-memory kill.
constexpr long kMaxTotalNodes = 10'000'000;

// What every builder may need besides its own section.
struct BuildContext {
  Eigen::Vector3d gravity;
  std::filesystem::path base_dir;   // relative files are looked up here
  std::vector<std::string>* notes;  // what a loader ignored or assumed
  long* total_nodes;                // particle nodes so far, for kMaxTotalNodes
};

// Builds the component `name` from its section; `surface` receives its
// triangles in its own node numbering (empty where it has none).
using BuildComponent = std::unique_ptr<System> (*)(const Section& c, const std::string& name,
                                                   const BuildContext& context,
                                                   std::vector<std::array<int, 3>>* surface);

struct ComponentBuilder {
  std::string type;
  std::vector<std::string> keys;  // every key a component of this type may have
  BuildComponent build;
};

// Every component type, in the order messages list them.
const std::vector<ComponentBuilder>& component_builders();
// The builder of `type`, or null.
const ComponentBuilder* find_component_builder(const std::string& type);
std::vector<std::string> component_types();
// The keys of `type`'s components ({name, type} for an unknown type).
std::vector<std::string> component_keys(const std::string& type);
// The spring blocks of particle components (stretch, shear, bend) and
// their keys.
bool is_spring_block(const std::string& key);
std::vector<std::string> spring_keys();

// The builders (particle_builders.cc, urdf_builder.cc).
std::unique_ptr<System> build_cloth_component(const Section& c, const std::string& name,
                                              const BuildContext& context,
                                              std::vector<std::array<int, 3>>* surface);
std::unique_ptr<System> build_rope_component(const Section& c, const std::string& name,
                                             const BuildContext& context,
                                             std::vector<std::array<int, 3>>* surface);
std::unique_ptr<System> build_mesh_component(const Section& c, const std::string& name,
                                             const BuildContext& context,
                                             std::vector<std::array<int, 3>>* surface);
std::unique_ptr<System> build_urdf_component(const Section& c, const std::string& name,
                                             const BuildContext& context,
                                             std::vector<std::array<int, 3>>* surface);

}  // namespace scene_file
}  // namespace stiffsim
