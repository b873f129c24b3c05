#include "scene_reader.h"

namespace stiffsim {
namespace scene_file {

std::string join(const std::vector<std::string>& items, const std::string& separator) {
  std::string out;
  for (size_t i = 0; i < items.size(); ++i) {
    if (i > 0) out += separator;
    out += items[i];
  }
  return out;
}

bool contains(const std::vector<std::string>& items, const std::string& item) {
  return std::find(items.begin(), items.end(), item) != items.end();
}

std::string node_kind(const YAML::Node& node) {
  switch (node.Type()) {
    case YAML::NodeType::Map:
      return "map";
    case YAML::NodeType::Sequence:
      return "list";
    case YAML::NodeType::Scalar:
      return "'" + node.Scalar() + "'";
    default:
      return "nothing";
  }
}

// Every node of a subtree, so messages can tell which values came from --set.
void collect_nodes(const YAML::Node& node, std::vector<YAML::Node>* out) {
  out->push_back(node);
  if (node.IsMap()) {
    for (const auto& entry : node) {
      out->push_back(entry.first);
      collect_nodes(entry.second, out);
    }
  } else if (node.IsSequence()) {
    for (const auto& item : node) collect_nodes(item, out);
  }
}

// A prescribed path: a number (constant), {keyframes: [[t, value], ...]}
// or {sinusoid: {offset, amplitude, frequency, phase}}.
ScalarPath read_path(const Section& c, const YAML::Node& n, const std::string& what) {
  if (n.IsScalar()) return ScalarPath::constant(c.number_value(n, what, Range::kFinite));
  const Section p(c.doc(), n, c.context(), what + ".", {"keyframes", "sinusoid"});
  if (p.has("keyframes") == p.has("sinusoid")) {
    p.fail(n, what + " must be a number or a map with one of keyframes, sinusoid");
  }
  if (p.has("sinusoid")) {
    const Section s(c.doc(), p.get("sinusoid"), c.context(), what + ".sinusoid.",
                    {"offset", "amplitude", "frequency", "phase"});
    return ScalarPath::sinusoid(s.number_or("offset", Range::kFinite, 0.0),
                                s.number("amplitude", Range::kFinite),
                                s.number("frequency", Range::kNonNegative),
                                s.number_or("phase", Range::kFinite, 0.0), what);
  }
  const YAML::Node keys = p.get("keyframes");
  const std::string label = what + ".keyframes";
  if (!keys.IsSequence() || keys.size() == 0) {
    p.fail(keys, label + " must be a non-empty list of [t, value] pairs, got " + node_kind(keys));
  }
  std::vector<double> times, values;
  for (std::size_t k = 0; k < keys.size(); ++k) {
    const YAML::Node& key = keys[k];
    const std::string item = label + "[" + std::to_string(k) + "]";
    if (!key.IsSequence() || key.size() != 2) {
      p.fail(key, item + " must be a pair [t, value], got " + node_kind(key));
    }
    times.push_back(p.number_value(key[0], item + ".t", Range::kFinite));
    values.push_back(p.number_value(key[1], item + ".value", Range::kFinite));
    if (k > 0 && !(times[k] > times[k - 1])) {
      p.fail(key[0], item + ": keyframe times must increase, got t = " + key[0].Scalar() +
                         " after t = " + keys[k - 1][0].Scalar());
    }
  }
  return ScalarPath::keyframes(std::move(times), std::move(values), label);
}

}  // namespace scene_file
}  // namespace stiffsim
