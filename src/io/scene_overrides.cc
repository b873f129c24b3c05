#include <sstream>

#include "component_builders.h"
#include "scene_sections.h"

namespace stiffsim {
namespace scene_file {
namespace {

std::vector<std::string> split(const std::string& text, char separator) {
  std::vector<std::string> parts;
  std::string part;
  std::istringstream stream(text);
  while (std::getline(stream, part, separator)) parts.push_back(part);
  if (!text.empty() && text.back() == separator) parts.push_back("");
  return parts;
}

}  // namespace

// Splices one --set PATH=VALUE into the document. The path is checked against
// the schema here, so a mistyped key names the --set that holds it.
void apply_override(YAML::Node root, const std::string& text, Document* doc) {
  const size_t equals = text.find('=');
  if (equals == std::string::npos || equals == 0) {
    doc->fail_override(text, "expected PATH=VALUE, e.g. cloth.stretch.k=1e6");
  }
  const std::string path = text.substr(0, equals);
  YAML::Node value;
  try {
    value = YAML::Load(text.substr(equals + 1));
  } catch (const YAML::Exception& e) {
    doc->fail_override(text, "the value is not valid YAML (" + e.msg + ")");
  }
  const std::vector<std::string> keys = split(path, '.');
  for (const std::string& key : keys) {
    if (key.empty()) doc->fail_override(text, "empty key in path '" + path + "'");
  }

  YAML::Node target;  // the map that receives the last key
  size_t first_key = 1;
  if (keys[0] == "gravity" || keys[0] == "attachments") {
    if (keys.size() != 1) {
      doc->fail_override(text, keys[0] + " is set whole, e.g. gravity=[0,0,-1] or attachments=[]");
    }
    target.reset(root);
    first_key = 0;
  } else if (keys[0] == "simulation") {
    if (keys.size() != 2 || !contains(simulation_keys(), keys[1])) {
      doc->fail_override(
          text, "unknown key '" + path + "' (simulation keys: " + join(simulation_keys()) + ")");
    }
    target.reset(root);
    first_key = 0;
  } else if (keys[0] == "components") {
    doc->fail_override(text, "address components by name: <name>.<key>=VALUE");
  } else {
    const YAML::Node list = root["components"];
    std::vector<std::string> names;
    bool found = false;
    if (list.IsSequence()) {
      for (size_t i = 0; i < list.size(); ++i) {
        if (!list[i].IsMap()) continue;
        const YAML::Node name = list[i]["name"];
        if (!name.IsScalar()) continue;
        if (name.Scalar() == keys[0] && !found) {
          target.reset(list[i]);
          found = true;
        }
        names.push_back(name.Scalar());
      }
    }
    if (!found) {
      doc->fail_override(text,
                         "unknown key '" + keys[0] + "': no component has that name (" +
                             (names.empty() ? "no components" : "components: " + join(names)) +
                             "; other keys: gravity, simulation.<key>)");
    }
    if (keys.size() < 2)
      doc->fail_override(text, "name a key of the component, e.g. " + keys[0] + ".total_mass=0.5");
    const YAML::Node type = target["type"];
    const std::vector<std::string> allowed =
        component_keys(type.IsScalar() ? type.Scalar() : std::string());
    if (!contains(allowed, keys[1])) {
      doc->fail_override(text, "unknown key '" + path + "' (component '" + keys[0] +
                                   "' keys: " + join(allowed) + ")");
    }
    const bool urdf = type.IsScalar() && type.Scalar() == "urdf";
    if (urdf) {
      // initial.all_joints, initial.joints.<joint>, initial.velocities.<joint>,
      // bushing.<k_lin|c_lin|k_ang|c_ang>, joint_stiffness.<joint> (and
      // joint_rest, joint_damping); joint names are checked against the URDF
      // when the component is built.
      const bool per_joint_map =
          keys[1] == "joint_stiffness" || keys[1] == "joint_rest" || keys[1] == "joint_damping";
      bool ok = keys.size() == 2 || (per_joint_map && keys.size() == 3);
      if (keys[1] == "bushing" && keys.size() == 3) {
        ok = contains({"k_lin", "c_lin", "k_ang", "c_ang"}, keys[2]);
      }
      if (keys[1] == "initial" && keys.size() >= 3) {
        ok = (keys.size() == 3 && keys[2] == "all_joints") ||
             (keys.size() == 4 && (keys[2] == "joints" || keys[2] == "velocities"));
      }
      if (!ok) {
        doc->fail_override(text, "unknown key '" + path +
                                     "' (urdf paths: initial.all_joints, initial.joints.<joint>, "
                                     "initial.velocities.<joint>, bushing.k_lin|c_lin|k_ang|c_ang, "
                                     "joint_stiffness|joint_rest|joint_damping[.<joint>])");
      }
    }
    const size_t depth = urdf ? keys.size() : is_spring_block(keys[1]) ? 3 : 2;
    if (keys.size() > depth) {
      doc->fail_override(text, "unknown key '" + path + "' ('" + keys[0] + "." + keys[1] +
                                   "' has no key '" + keys[depth] + "')");
    }
    if (!urdf && keys.size() == 3 && !contains(spring_keys(), keys[2])) {
      doc->fail_override(text,
                         "unknown key '" + path + "' (spring keys: " + join(spring_keys()) + ")");
    }
  }

  // Walk down, creating the maps an optional block needs (cloth.shear.k=10
  // on a cloth without shear springs adds them).
  for (size_t i = first_key; i + 1 < keys.size(); ++i) {
    const YAML::Node next = target[keys[i]];
    if (!next.IsDefined() || next.IsNull()) {
      target[keys[i]] = YAML::Node(YAML::NodeType::Map);
    } else if (!next.IsMap()) {
      doc->fail_override(text, "'" + keys[i] + "' is not a map in the scene, cannot set '" +
                                   keys[i + 1] + "' inside it");
    }
    YAML::Node child = target[keys[i]];
    target.reset(child);
  }
  target[keys.back()] = value;
  doc->add_override(text, value);
}

}  // namespace scene_file
}  // namespace stiffsim
