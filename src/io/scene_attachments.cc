#include "scene_sections.h"
#include "stiffsim/model/articulated.h"
#include "stiffsim/model/particles.h"

namespace stiffsim {
namespace scene_file {
namespace {

// One end of an attachment: {component, node} on a particle component,
// {component, link, point} on a tree (point in the link's frame, default
// its origin), or {world: [x, y, z]}.
AttachmentPoint read_attachment_point(const Section& at, const std::string& key,
                                      const std::vector<std::string>& names,
                                      const std::vector<std::unique_ptr<System>>& components) {
  const std::string what = at.label(key);
  const Section p(at.doc(), at.require(key), at.context(), what + ".",
                  {"component", "node", "link", "point", "world"});
  AttachmentPoint out;
  auto vector3 = [&](const std::string& k) {
    const YAML::Node n = p.list(k, 3, "[x, y, z]");
    Eigen::Vector3d v;
    for (int i = 0; i < 3; ++i) {
      v[i] = p.number_value(n[i], what + "." + k + "[" + std::to_string(i) + "]", Range::kFinite);
    }
    return v;
  };
  if (p.has("world")) {
    for (const char* other : {"component", "node", "link", "point"}) {
      if (p.has(other)) p.fail(p.get(other), what + ": a world point takes no '" + other + "'");
    }
    out.local = vector3("world");
    return out;
  }
  const YAML::Node component = p.require("component");
  const auto found = std::find(names.begin(), names.end(), component.Scalar());
  if (!component.IsScalar() || found == names.end()) {
    p.fail(component, "unknown component '" + component.Scalar() + "' in " + what +
                          " (components: " + join(names) + ")");
  }
  out.component = static_cast<int>(found - names.begin());
  const System& system = *components[out.component];
  if (const auto* particles = dynamic_cast<const ParticleSystem*>(&system)) {
    if (p.has("link") || p.has("point")) {
      p.fail(p.has("link") ? p.get("link") : p.get("point"),
             what + ": component '" + component.Scalar() + "' is made of particles: give a node");
    }
    out.element = static_cast<int>(
        p.integer_value(p.require("node"), what + ".node", 0, particles->node_count() - 1));
    return out;
  }
  const auto& tree = dynamic_cast<const ArticulatedSystem&>(system);
  if (p.has("node")) {
    p.fail(p.get("node"), what + ": component '" + component.Scalar() +
                              "' is a URDF: give a link (and a point in its frame)");
  }
  const YAML::Node link = p.require("link");
  const std::vector<TreeBody>& bodies = tree.tree().bodies;
  int body = 0;
  while (body < static_cast<int>(bodies.size()) && bodies[body].link != link.Scalar()) ++body;
  if (body == static_cast<int>(bodies.size())) {
    p.fail(link, "unknown link '" + link.Scalar() + "' in " + what + " (not a moving link of " +
                     tree.tree().file +
                     "; links welded by fixed joints are merged into their parent)");
  }
  out.element = body;
  if (p.has("point")) out.local = vector3("point");
  return out;
}

}  // namespace

// `attachments`: a list of {name, a, b, k, c} (attachment.h).
std::vector<Attachment> read_attachments(const Section& top, const std::vector<std::string>& names,
                                         const std::vector<std::unique_ptr<System>>& components) {
  std::vector<Attachment> out;
  if (!top.has("attachments")) return out;
  const YAML::Node list = top.get("attachments");
  if (!list.IsSequence()) {
    top.fail(list, "attachments must be a list of {name, a, b, k, c}, got " + node_kind(list));
  }
  for (std::size_t i = 0; i < list.size(); ++i) {
    const std::string what = "attachments[" + std::to_string(i) + "]";
    const Section at(top.doc(), list[i], what, what + ".", {"name", "a", "b", "k", "c"});
    Attachment a;
    a.name = at.has("name") ? at.text("name") : what;
    a.a = read_attachment_point(at, "a", names, components);
    a.b = read_attachment_point(at, "b", names, components);
    if (a.a.component < 0 && a.b.component < 0) {
      at.fail(list[i], what + ": both ends are world points");
    }
    a.k = at.number("k", Range::kNonNegative);
    a.c = at.number_or("c", Range::kNonNegative, 0.0);
    out.push_back(std::move(a));
  }
  return out;
}

}  // namespace scene_file
}  // namespace stiffsim
