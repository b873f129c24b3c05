#include "stiffsim/io/scene_yaml.h"

#include <yaml-cpp/depthguard.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <utility>

#include "component_builders.h"
#include "scene_reader.h"
#include "scene_sections.h"
#include "stiffsim/error.h"
#include "stiffsim/model/urdf.h"

namespace stiffsim {

std::vector<std::string> jacobian_scheme_names() {
  return {"analytic", "forward", "central", "automatic"};
}
std::vector<std::string> linear_solver_names() {
  return {"auto", "dense", "dense-lu", "dense-ldlt", "cholmod", "umfpack"};
}
std::vector<std::string> newton_form_names() { return {"mass-matrix", "generic"}; }
std::vector<std::string> error_estimator_names() { return {"trapezoid", "doubling"}; }
std::vector<std::string> newton_tolerance_names() { return {"step-error", "accuracy"}; }
std::vector<std::string> preconditioner_precision_names() { return {"single", "double"}; }
std::vector<std::string> newton_solve_names() {
  return {"auto", "chord", "krylov", "fresh", "recursive"};
}

namespace {

using namespace scene_file;

std::vector<std::string> top_level_keys() {
  return {"gravity", "components", "attachments", "simulation"};
}

Eigen::Vector3d read_gravity(const Section& top) {
  if (!top.has("gravity")) return Eigen::Vector3d(0.0, 0.0, -9.81);
  const YAML::Node n = top.list("gravity", 3, "[gx, gy, gz]");
  Eigen::Vector3d g;
  for (int i = 0; i < 3; ++i) {
    g[i] = top.number_value(n[i], "gravity[" + std::to_string(i) + "]", Range::kFinite);
  }
  return g;
}

// Names go into CSV headers ("<name>/n3/x") and --set paths ("<name>.key"),
// so they must not contain the separators of either.
bool valid_component_name(const std::string& name) {
  return !name.empty() && std::all_of(name.begin(), name.end(), [](unsigned char c) {
    return std::isalnum(c) || c == '_' || c == '-';
  });
}

SceneConfig build_scene(const YAML::Node& root, const Document& doc,
                        const std::filesystem::path& base_dir, const std::string& scene_name) {
  const Section top(doc, root, "", "", top_level_keys());
  const Eigen::Vector3d gravity = read_gravity(top);

  SceneConfig config;
  config.source = doc.source();
  read_simulation(top, &config);

  const YAML::Node list = top.require("components");
  if (!list.IsSequence() || list.size() == 0) {
    top.fail(list, "components must be a non-empty list, got " + node_kind(list));
  }
  std::vector<std::unique_ptr<System>> components;
  std::vector<std::string> names;
  long total_nodes = 0;
  const BuildContext build_context{gravity, base_dir, &config.notes, &total_nodes};
  for (size_t i = 0; i < list.size(); ++i) {
    const YAML::Node node = list[i];
    std::string context = "components[" + std::to_string(i) + "]";
    if (!node.IsMap()) doc.fail(node, context, "expected a map, got " + node_kind(node));
    const YAML::Node name_node = node["name"];
    if (!name_node.IsDefined() || name_node.IsNull()) {
      doc.fail(node, context, "missing required key 'name'");
    }
    if (!name_node.IsScalar()) {
      doc.fail(name_node, context, "name must be a string, got " + node_kind(name_node));
    }
    const std::string name = name_node.Scalar();
    context += " (" + name + ")";
    if (!valid_component_name(name)) {
      doc.fail(name_node, context,
               "name must be non-empty and use only letters, digits, '_' and '-' (it appears in "
               "CSV columns and --set paths)");
    }
    if (contains(top_level_keys(), name)) {
      doc.fail(name_node, context,
               "name '" + name + "' is reserved (it would be ambiguous in --set paths)");
    }
    const auto previous = std::find(names.begin(), names.end(), name);
    if (previous != names.end()) {
      doc.fail(name_node, context,
               "duplicate component name '" + name + "' (also components[" +
                   std::to_string(previous - names.begin()) + "])");
    }
    names.push_back(name);

    const YAML::Node type_node = node["type"];
    if (!type_node.IsDefined() || type_node.IsNull()) {
      doc.fail(node, context,
               "missing required key 'type' (expected one of: " + join(component_types()) + ")");
    }
    const ComponentBuilder* builder =
        type_node.IsScalar() ? find_component_builder(type_node.Scalar()) : nullptr;
    if (builder == nullptr) {
      doc.fail(type_node, context,
               "unknown type " + node_kind(type_node) +
                   " (expected one of: " + join(component_types()) + ")");
    }
    const Section c(doc, node, context, "", builder->keys);
    config.surfaces.emplace_back();
    components.push_back(builder->build(c, name, build_context, &config.surfaces.back()));
  }
  std::vector<Attachment> attachments = read_attachments(top, names, components);
  try {
    config.scene =
        std::make_unique<Scene>(scene_name, std::move(components), std::move(attachments));
  } catch (const InputError& e) {
    throw InputError(doc.source() + ": " + e.what());
  }
  return config;
}

// Binary data (a mesh or an archive named as the scene) makes yaml-cpp
// report an odd escape or indentation problem; name the first byte YAML does
// not allow instead: C0 controls other than tab, LF and CR, and DEL.
void check_text(const std::string& text, const std::string& source_name) {
  int line = 1, column = 1;
  for (const char ch : text) {
    const auto byte = static_cast<unsigned char>(ch);
    if ((byte < 0x20 && ch != '\t' && ch != '\n' && ch != '\r') || byte == 0x7f) {
      char hex[8];
      std::snprintf(hex, sizeof hex, "0x%02x", byte);
      throw InputError(source_name + ":" + std::to_string(line) + ":" + std::to_string(column) +
                       ": not a text file (control byte " + hex + "): expected a YAML scene");
    }
    if (ch == '\n') {
      ++line;
      column = 1;
    } else {
      ++column;
    }
  }
}

// yaml-cpp's parser messages describe its state ("end of map not found"); say
// what the user most likely has to fix. A tab in the indentation is reported
// at its own line, since yaml-cpp stops somewhere after it.
std::string malformed_yaml(const std::string& text, const std::string& source_name,
                           const YAML::ParserException& e) {
  std::istringstream lines(text);
  int number = 0;
  for (std::string line; std::getline(lines, line);) {
    ++number;
    const size_t indent = line.find_first_not_of(" \t");
    const size_t tab = line.find('\t');
    if (tab != std::string::npos && tab < indent && indent != std::string::npos &&
        number <= e.mark.line + 1) {
      return source_name + ":" + std::to_string(number) + ":" + std::to_string(tab + 1) +
             ": malformed YAML: a tab indents this line (YAML indentation must use spaces)";
    }
  }
  std::string hint;
  if (e.msg == YAML::ErrorMsg::END_OF_SEQ_FLOW) {
    hint = " (a '[' is not closed by ']')";
  } else if (e.msg == YAML::ErrorMsg::END_OF_MAP_FLOW) {
    hint = " (a '{' is not closed by '}')";
  } else if (e.msg == YAML::ErrorMsg::END_OF_MAP || e.msg == YAML::ErrorMsg::END_OF_SEQ) {
    hint = " (check the indentation of this line against the lines above)";
  }
  return source_name + ":" + std::to_string(e.mark.line + 1) + ":" +
         std::to_string(e.mark.column + 1) + ": malformed YAML: " + e.msg + hint;
}

}  // namespace

SceneConfig parse_scene(const std::string& text, const std::string& source_name,
                        const std::vector<std::string>& overrides) {
  Document doc(source_name);
  check_text(text, source_name);
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::DeepRecursion& e) {
    // yaml-cpp 0.7 gives this the message "bad file"; say what it means.
    throw InputError(source_name + ":" + std::to_string(e.mark.line + 1) + ":" +
                     std::to_string(e.mark.column + 1) + ": malformed YAML: nested too deeply (" +
                     std::to_string(e.depth()) + " levels of lists and maps)");
  } catch (const YAML::ParserException& e) {
    throw InputError(malformed_yaml(text, source_name, e));
  } catch (const YAML::Exception& e) {
    throw InputError(source_name + ": malformed YAML: " + e.what());
  }
  if (!root.IsDefined() || root.IsNull()) {
    throw InputError(source_name + ": empty scene (expected a map with keys " +
                     join(top_level_keys()) + ")");
  }
  if (!root.IsMap()) {
    doc.fail(
        root, "",
        "the scene must be a map with keys " + join(top_level_keys()) + ", got " + node_kind(root));
  }
  const std::filesystem::path source_path(source_name);
  std::string scene_name = source_path.stem().string();
  if (scene_name.empty()) scene_name = "scene";
  try {
    for (const std::string& o : overrides) apply_override(root, o, &doc);
    return build_scene(root, doc, source_path.parent_path(), scene_name);
  } catch (const YAML::Exception& e) {
    // A shape the checks above did not anticipate; still the user's input.
    throw InputError(source_name + ": " + e.what());
  }
}

SceneConfig load_scene(const std::string& path, const std::vector<std::string>& overrides) {
  std::string extension = std::filesystem::path(path).extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (extension == ".urdf") {
    // A bare URDF is a scene with one exact urdf component named after the
    // file, welded root, every joint at 0; --set reaches it by that name.
    const std::filesystem::path p(path);
    std::string name = p.stem().string();
    for (char& ch : name) {
      if (!std::isalnum(static_cast<unsigned char>(ch)) && ch != '_' && ch != '-') ch = '_';
    }
    if (name.empty() || contains(top_level_keys(), name)) name = "robot";
    // The URDF's own errors name the file alone: the scene around it is
    // made up here and has no lines to point at.
    load_urdf(path, UrdfOptions{name, false}, nullptr);
    YAML::Emitter scene;
    scene << YAML::BeginMap << YAML::Key << "components" << YAML::Value << YAML::BeginSeq
          << YAML::BeginMap << YAML::Key << "name" << YAML::Value << name << YAML::Key << "type"
          << YAML::Value << "urdf" << YAML::Key << "file" << YAML::Value << p.filename().string()
          << YAML::EndMap << YAML::EndSeq << YAML::EndMap;
    return parse_scene(scene.c_str(), path, overrides);
  }
  std::error_code error;
  if (std::filesystem::is_directory(path, error)) {
    throw InputError(path + ": is a directory, expected a scene file");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path + ": cannot open");
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) throw InputError(path + ": read error");
  return parse_scene(text.str(), path, overrides);
}

}  // namespace stiffsim
