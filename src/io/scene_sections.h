#pragma once
// The scene file's top-level sections beside the components: the
// simulation settings, the attachments between components, and the --set
// engine that splices values into the document. Private to the scene loader.

#include <memory>
#include <string>
#include <vector>

#include "scene_reader.h"
#include "stiffsim/attachment.h"
#include "stiffsim/io/scene_yaml.h"
#include "stiffsim/system.h"

namespace stiffsim {
namespace scene_file {

// The keys of `simulation`.
std::vector<std::string> simulation_keys();
void read_simulation(const Section& top, SceneConfig* config);

// `attachments`: a list of {name, a, b, k, c} (attachment.h).
std::vector<Attachment> read_attachments(const Section& top, const std::vector<std::string>& names,
                                         const std::vector<std::unique_ptr<System>>& components);

// Splices one --set PATH=VALUE into the document. The path is checked against
// the schema here, so a mistyped key names the --set that holds it.
void apply_override(YAML::Node root, const std::string& text, Document* doc);

}  // namespace scene_file
}  // namespace stiffsim
