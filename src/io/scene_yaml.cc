#include "stiffsim/io/scene_yaml.h"

#include <yaml-cpp/depthguard.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <sstream>
#include <utility>

#include "stiffsim/error.h"
#include "stiffsim/integrators/integrator_factory.h"
#include "stiffsim/io/obj_mesh.h"
#include "stiffsim/model/articulated.h"
#include "stiffsim/model/compliant.h"
#include "stiffsim/model/particle_meshes.h"
#include "stiffsim/model/particles.h"
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
std::vector<std::string> newton_solve_names() { return {"auto", "chord", "krylov", "fresh", "recursive"}; }

namespace {

// Bounds the memory a scene can ask for (a 10^7-node cloth already needs
// gigabytes for its Jacobians); a typo like nodes: [10000, 10000] should be an
// error, not an out-of-memory kill.
constexpr long kMaxTotalNodes = 10'000'000;

// Likewise for the length of a run: at a microsecond a step, 10^9 steps of the
// smallest scene already take a quarter of an hour.
constexpr double kMaxSteps = 1e9;

std::vector<std::string> top_level_keys() {
  return {"gravity", "components", "attachments", "simulation"};
}

std::vector<std::string> component_types() { return {"cloth", "rope", "mesh", "urdf"}; }

std::vector<std::string> component_keys(const std::string& type) {
  if (type == "cloth") {
    return {"name",   "type",        "nodes", "size",   "total_mass", "stretch",
            "shear",  "bend",        "pinned", "moving_pins", "drag",  "masses",
            "velocities", "node_file"};
  }
  if (type == "rope") {
    return {"name",     "type",   "nodes",       "length", "total_mass", "origin",
            "direction", "stretch", "bend", "pinned", "moving_pins", "drag",
            "masses",   "velocities", "node_file"};
  }
  if (type == "mesh") {
    return {"name",   "type",        "file", "density", "stretch",    "bend",
            "pinned", "moving_pins", "drag", "masses",  "velocities", "node_file"};
  }
  if (type == "urdf") {
    return {"name",
            "type",
            "file",
            "formulation",
            "floating_base",
            "initial",
            "joint_stiffness",
            "joint_rest",
            "joint_damping",
            "drives",
            "root_motion",
            "bushing"};
  }
  return {"name", "type"};
}

bool is_spring_block(const std::string& key) {
  return key == "stretch" || key == "shear" || key == "bend";
}

std::vector<std::string> spring_keys() { return {"k", "c"}; }

std::vector<std::string> simulation_keys() {
  return {"integrator",
          "t_final",
          "step",
          "fixed_step",
          "error_estimate",
          "accuracy",
          "sample_period",
          "min_step",
          "jacobian",
          "linear_solver",
          "newton_form",
          "full_newton",
          "reuse",
          "definite_iteration_matrix",
          "error_estimator",
          "newton_solve"};
}

std::string join(const std::vector<std::string>& items, const std::string& separator = ", ") {
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

// The document being loaded and the --set values spliced into it. yaml-cpp
// marks nodes parsed from a --set value with positions inside that value,
// which would point into the scene file at the wrong place; node identity
// tells them apart.
class Document {
 public:
  explicit Document(std::string source) : source_(std::move(source)) {}

  const std::string& source() const { return source_; }

  void add_override(std::string text, const YAML::Node& value) {
    Override o{std::move(text), {}};
    collect_nodes(value, &o.nodes);
    overrides_.push_back(std::move(o));
  }

  std::string location(const YAML::Node& node) const {
    if (!node.IsDefined()) return source_;
    // Latest first: a later --set replaces what an earlier one put there.
    for (auto o = overrides_.rbegin(); o != overrides_.rend(); ++o) {
      for (const YAML::Node& n : o->nodes) {
        if (node.is(n)) return source_ + ": --set " + o->text;
      }
    }
    const YAML::Mark mark = node.Mark();
    if (mark.line < 0) return source_;
    return source_ + ":" + std::to_string(mark.line + 1) + ":" + std::to_string(mark.column + 1);
  }

  [[noreturn]] void fail(const YAML::Node& at, const std::string& context,
                         const std::string& what) const {
    std::string message = location(at);
    if (!context.empty()) message += ": " + context;
    throw InputError(message + ": " + what);
  }

  [[noreturn]] void fail_override(const std::string& text, const std::string& what) const {
    throw InputError(source_ + ": --set " + text + ": " + what);
  }

 private:
  struct Override {
    std::string text;
    std::vector<YAML::Node> nodes;
  };
  std::string source_;
  std::vector<Override> overrides_;
};

enum class Range { kFinite, kPositive, kNonNegative, kUnitInterval };

// A YAML map of the schema: its keys are checked when it is opened, so a typo
// is reported as an unknown key (with the alternatives) rather than as a
// missing key elsewhere.
class Section {
 public:
  Section(const Document& doc, YAML::Node map, std::string context, std::string prefix,
          const std::vector<std::string>& allowed)
      : doc_(doc), map_(std::move(map)), context_(std::move(context)), prefix_(std::move(prefix)) {
    if (!map_.IsMap()) {
      doc_.fail(
          map_, context_,
          (prefix_.empty() ? std::string("expected a map")
                           : "'" + prefix_.substr(0, prefix_.size() - 1) + "' must be a map") +
              " with keys " + join(allowed) + ", got " + node_kind(map_));
    }
    std::vector<std::string> seen;
    for (const auto& entry : map_) {
      const YAML::Node& key = entry.first;
      if (!key.IsScalar()) doc_.fail(key, context_, "keys must be plain names");
      const std::string& name = key.Scalar();
      if (!contains(allowed, name)) {
        doc_.fail(key, context_,
                  "unknown key '" + prefix_ + name + "' (expected one of: " + join(allowed) + ")");
      }
      if (contains(seen, name)) doc_.fail(key, context_, "duplicate key '" + prefix_ + name + "'");
      seen.push_back(name);
    }
  }

  const Document& doc() const { return doc_; }
  const std::string& context() const { return context_; }
  const YAML::Node& map() const { return map_; }
  std::string label(const std::string& key) const { return prefix_ + key; }

  // A key given with a null value (`bend: ~`, or --set cloth.bend=null) counts
  // as absent, so an override can remove an optional block.
  bool has(const std::string& key) const {
    const YAML::Node n = map_[key];
    return n.IsDefined() && !n.IsNull();
  }
  YAML::Node get(const std::string& key) const { return map_[key]; }
  YAML::Node require(const std::string& key) const {
    if (!has(key)) {
      // `total_mass:` with nothing after it is a value forgotten, not a key
      // forgotten: point at the key's line.
      for (const auto& entry : map_) {
        if (entry.first.Scalar() == key) {
          // An empty value may carry no position; its key always does.
          const bool placed = entry.second.Mark().line >= 0;
          doc_.fail(placed ? entry.second : entry.first, context_,
                    "required key '" + label(key) + "' has no value (null or empty)");
        }
      }
      doc_.fail(map_, context_, "missing required key '" + label(key) + "'");
    }
    return map_[key];
  }

  [[noreturn]] void fail(const YAML::Node& at, const std::string& what) const {
    doc_.fail(at, context_, what);
  }

  double number_value(const YAML::Node& n, const std::string& what, Range range) const {
    if (!n.IsScalar()) fail(n, what + " must be a number, got " + node_kind(n));
    std::string text = n.Scalar();
    std::string lower = text;
    std::transform(lower.begin(), lower.end(), lower.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    double value = 0.0;
    bool parsed = false;
    if (lower == ".inf" || lower == "+.inf" || lower == "-.inf" || lower == ".nan") {
      value = std::numeric_limits<double>::quiet_NaN();
      parsed = true;
    } else {
      // from_chars: locale-independent, and it rejects trailing garbage.
      const char* first = text.data();
      const char* last = text.data() + text.size();
      if (first != last && *first == '+') ++first;
      const auto result = std::from_chars(first, last, value);
      parsed = result.ec == std::errc() && result.ptr == last;
      if (result.ec == std::errc::result_out_of_range) {
        value = std::numeric_limits<double>::infinity();
        parsed = true;
      }
    }
    if (!parsed) fail(n, what + " must be a number, got '" + text + "'");
    if (!std::isfinite(value)) fail(n, what + " must be a finite number, got '" + text + "'");
    switch (range) {
      case Range::kFinite:
        break;
      case Range::kPositive:
        if (!(value > 0.0)) fail(n, what + " must be positive, got " + text);
        break;
      case Range::kNonNegative:
        if (!(value >= 0.0)) fail(n, what + " must be >= 0, got " + text);
        break;
      case Range::kUnitInterval:
        if (!(value > 0.0 && value <= 1.0)) fail(n, what + " must be in (0, 1], got " + text);
        break;
    }
    return value;
  }

  long integer_value(const YAML::Node& n, const std::string& what, long min, long max) const {
    const double value = number_value(n, what, Range::kFinite);
    if (std::floor(value) != value) fail(n, what + " must be an integer, got " + n.Scalar());
    if (value < static_cast<double>(min)) {
      fail(n, what + " must be at least " + std::to_string(min) + ", got " + n.Scalar());
    }
    if (value > static_cast<double>(max)) {
      fail(n, what + " must be at most " + std::to_string(max) + ", got " + n.Scalar());
    }
    return static_cast<long>(value);
  }

  double number(const std::string& key, Range range) const {
    return number_value(require(key), label(key), range);
  }
  double number_or(const std::string& key, Range range, double fallback) const {
    return has(key) ? number_value(get(key), label(key), range) : fallback;
  }
  long integer(const std::string& key, long min, long max) const {
    return integer_value(require(key), label(key), min, max);
  }

  YAML::Node list(const std::string& key, size_t size, const std::string& shape) const {
    const YAML::Node n = require(key);
    if (!n.IsSequence() || (size > 0 && n.size() != size)) {
      fail(n, label(key) + " must be a list " + shape + ", got " + node_kind(n) +
                  (n.IsSequence() ? " of " + std::to_string(n.size()) + " entries" : ""));
    }
    return n;
  }

  bool boolean_or(const std::string& key, bool fallback) const {
    if (!has(key)) return fallback;
    const YAML::Node n = get(key);
    bool value = false;
    if (!n.IsScalar() || !YAML::convert<bool>::decode(n, value)) {
      fail(n, label(key) + " must be true or false, got " + node_kind(n));
    }
    return value;
  }

  std::string text(const std::string& key) const {
    const YAML::Node n = require(key);
    if (!n.IsScalar() || n.Scalar().empty()) {
      fail(n, label(key) + " must be a non-empty string, got " + node_kind(n));
    }
    return n.Scalar();
  }

  std::string choice_or(const std::string& key, const std::vector<std::string>& choices,
                        const std::string& fallback) const {
    if (!has(key)) return fallback;
    const YAML::Node n = get(key);
    if (!n.IsScalar() || !contains(choices, n.Scalar())) {
      fail(n, label(key) + " must be one of " + join(choices) + ", got " + node_kind(n));
    }
    return n.Scalar();
  }

  Section section(const std::string& key, const std::vector<std::string>& allowed) const {
    return Section(doc_, get(key), context_, prefix_ + key + ".", allowed);
  }

 private:
  const Document& doc_;
  YAML::Node map_;
  std::string context_;
  std::string prefix_;
};

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
            bad(number, "unknown column '" + h + "' (expected some of: node, mass, vx, vy, vz, pinned)");
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
            bad(number, "node " + fields[k] + " is not a node index 0.." + std::to_string(nodes - 1));
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
    if (!v.IsSequence() || v.size() != 3) c.fail(v, what + " must be [vx, vy, vz], got " + node_kind(v));
    for (int k = 0; k < 3; ++k) {
      velocities()[i][k] = c.number_value(v[k], what + "[" + std::to_string(k) + "]", Range::kFinite);
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
      if (m.has(axes[a])) motion.displacement[a] = read_path(m, m.get(axes[a]), what + "." + axes[a]);
    }
    if (std::find(d->pinned.begin(), d->pinned.end(), motion.node) == d->pinned.end()) {
      d->pinned.push_back(motion.node);
    }
    d->pin_motions.push_back(std::move(motion));
  }
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

struct BuiltComponent {
  ParticleDescription description;
  std::vector<std::array<int, 3>> surface;
};

// Errors of the model builders know the component but not the file or line.
// They start with the component's name, which the context already gives
// ("components[0] (cloth): cloth: ..." would say it twice).
template <typename Build>
auto with_location(const Section& component, const std::string& name, const YAML::Node& at,
                   Build build) -> decltype(build()) {
  try {
    return build();
  } catch (const InputError& e) {
    std::string what = e.what();
    const std::string prefix = name + ": ";
    if (what.compare(0, prefix.size(), prefix) == 0) what.erase(0, prefix.size());
    component.fail(at, what);
  }
}
template <typename Build>
auto with_location(const Section& component, const std::string& name, Build build)
    -> decltype(build()) {
  return with_location(component, name, component.map(), build);
}

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
  for (auto [key, target] : {std::make_pair("origin", &spec.origin),
                             std::make_pair("direction", &spec.direction)}) {
    if (!c.has(key)) continue;
    const YAML::Node n = c.list(key, 3, "[x, y, z]");
    for (int i = 0; i < 3; ++i) {
      (*target)[i] = c.number_value(n[i], std::string(key) + "[" + std::to_string(i) + "]",
                                    Range::kFinite);
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

// Names go into CSV headers ("<name>/n3/x") and --set paths ("<name>.key"),
// so they must not contain the separators of either.
bool valid_component_name(const std::string& name) {
  return !name.empty() && std::all_of(name.begin(), name.end(), [](unsigned char c) {
    return std::isalnum(c) || c == '_' || c == '-';
  });
}

void read_simulation(const Section& top, SceneConfig* config) {
  if (!top.has("simulation")) return;
  const Section s(top.doc(), top.get("simulation"), "simulation", "", simulation_keys());
  config->integrator_name = s.choice_or("integrator", integrator_names(), config->integrator_name);
  config->simulation.t_final = s.number_or("t_final", Range::kPositive, config->simulation.t_final);
  config->integrator.max_step = s.number_or("step", Range::kPositive, config->integrator.max_step);
  // Even error control cannot take steps longer than `step`, so a run needs at
  // least t_final / step of them; beyond kMaxSteps that is a typo in an
  // exponent (step: 1e-310), and the run would never end.
  if (config->simulation.t_final / config->integrator.max_step > kMaxSteps) {
    std::ostringstream what;
    if (s.has("step")) {
      what << "step " << config->integrator.max_step << " would need more than " << kMaxSteps
           << " steps to reach t_final " << config->simulation.t_final;
    } else {
      what << "t_final " << config->simulation.t_final << " would need more than " << kMaxSteps
           << " steps of the default step " << config->integrator.max_step;
    }
    s.fail(s.has("step") ? s.get("step") : s.get("t_final"), what.str());
  }
  config->integrator.fixed_step = s.boolean_or("fixed_step", config->integrator.fixed_step);
  config->integrator.error_estimate =
      s.boolean_or("error_estimate", config->integrator.error_estimate);
  config->integrator.accuracy =
      s.number_or("accuracy", Range::kUnitInterval, config->integrator.accuracy);
  config->simulation.sample_period =
      s.number_or("sample_period", Range::kNonNegative, config->simulation.sample_period);
  config->integrator.min_step =
      s.number_or("min_step", Range::kNonNegative, config->integrator.min_step);
  if (config->integrator.min_step > config->integrator.max_step) {
    // Shortest round-trip form: "0.01", not std::to_string's "0.010000".
    std::ostringstream step;
    step << config->integrator.max_step;
    s.fail(s.get("min_step"),
           "min_step must not exceed step (" + step.str() + "), got " + s.get("min_step").Scalar());
  }
  ImplicitSettings& implicit = config->implicit;
  if (s.has("jacobian")) {
    implicit.jacobian = parse_jacobian_scheme(s.choice_or("jacobian", jacobian_scheme_names(), ""));
  }
  if (s.has("linear_solver")) {
    implicit.linear_solver =
        parse_linear_solver_kind(s.choice_or("linear_solver", linear_solver_names(), ""));
  }
  if (s.has("newton_form")) {
    implicit.newton_form = parse_newton_form(s.choice_or("newton_form", newton_form_names(), ""));
  }
  if (s.has("error_estimator")) {
    implicit.error_estimator =
        parse_error_estimator(s.choice_or("error_estimator", error_estimator_names(), ""));
  }
  if (s.has("newton_solve")) {
    implicit.newton_solve =
        parse_newton_solve(s.choice_or("newton_solve", newton_solve_names(), ""));
  }
  implicit.full_newton = s.boolean_or("full_newton", implicit.full_newton);
  implicit.reuse = s.boolean_or("reuse", implicit.reuse);
  implicit.definite_iteration_matrix =
      s.boolean_or("definite_iteration_matrix", implicit.definite_iteration_matrix);
}

// A per-joint setting given as one number for every 1-DOF joint or as a map
// joint name -> number; `index` maps the URDF's moving joint names to bodies.
std::vector<double> per_joint(const Section& c, const std::string& key, Range range,
                              const RigidTree& tree, double fallback) {
  std::vector<double> values(tree.bodies.size(), fallback);
  if (!c.has(key)) return values;
  const YAML::Node n = c.get(key);
  auto one_dof = [&](std::size_t i) { return joint_nv(tree.bodies[i].type) == 1; };
  if (n.IsScalar()) {
    const double x = c.number_value(n, c.label(key), range);
    for (std::size_t i = 0; i < values.size(); ++i) {
      if (one_dof(i)) values[i] = x;
    }
    return values;
  }
  if (!n.IsMap())
    c.fail(n,
           c.label(key) + " must be a number or a map joint name -> number, got " + node_kind(n));
  for (const auto& entry : n) {
    const std::string joint = entry.first.Scalar();
    const std::string what = c.label(key) + "." + joint;
    std::size_t i = 0;
    while (i < tree.bodies.size() && tree.bodies[i].joint != joint) ++i;
    if (i == tree.bodies.size()) {
      c.fail(entry.first, "unknown joint '" + joint + "' in " + c.label(key) +
                              " (not a moving joint of " + tree.file + ")");
    }
    if (!one_dof(i)) {
      c.fail(entry.first, what + ": joint '" + joint + "' is " +
                              joint_type_name(tree.bodies[i].type) +
                              "; only 1-DOF joints take this setting");
    }
    values[i] = c.number_value(entry.second, what, range);
  }
  return values;
}

int body_of_joint(const Section& c, const YAML::Node& key, const RigidTree& tree,
                  const std::string& where) {
  const std::string joint = key.Scalar();
  for (std::size_t i = 0; i < tree.bodies.size(); ++i) {
    if (tree.bodies[i].joint == joint) return static_cast<int>(i);
  }
  c.fail(key, "unknown joint '" + joint + "' in " + where + " (not a moving joint of " + tree.file +
                  ")");
}

// Values of one joint in `initial`: a number for a 1-DOF joint, a list of
// `size` numbers otherwise.
void read_joint_values(const Section& c, const YAML::Node& value, const std::string& what, int size,
                       Eigen::Ref<Eigen::VectorXd> out) {
  if (size == 1 && value.IsScalar()) {
    out[0] = c.number_value(value, what, Range::kFinite);
    return;
  }
  if (!value.IsSequence() || static_cast<int>(value.size()) != size) {
    c.fail(value, what + " must be " +
                      (size == 1 ? std::string("a number")
                                 : "a list of " + std::to_string(size) + " numbers") +
                      ", got " + node_kind(value));
  }
  for (int k = 0; k < size; ++k)
    out[k] = c.number_value(value[k], what + "[" + std::to_string(k) + "]", Range::kFinite);
}

// `drives`: a list of {joint, kp, kd, target} (JointDrive).
std::vector<JointDrive> read_drives(const Section& c, const RigidTree& tree) {
  std::vector<JointDrive> drives;
  if (!c.has("drives")) return drives;
  const YAML::Node list = c.get("drives");
  if (!list.IsSequence()) {
    c.fail(list, "drives must be a list of {joint, kp, kd, target}, got " + node_kind(list));
  }
  for (std::size_t k = 0; k < list.size(); ++k) {
    const std::string what = "drives[" + std::to_string(k) + "]";
    const Section d(c.doc(), list[k], c.context(), what + ".", {"joint", "kp", "kd", "target"});
    const YAML::Node joint = d.require("joint");
    std::size_t i = 0;
    while (i < tree.bodies.size() && tree.bodies[i].joint != joint.Scalar()) ++i;
    if (i == tree.bodies.size()) {
      d.fail(joint, "unknown joint '" + joint.Scalar() + "' in " + what +
                        " (not a moving joint of " + tree.file +
                        "; fixed joints are welded and take no drive)");
    }
    if (joint_nv(tree.bodies[i].type) != 1) {
      d.fail(joint, what + ": joint '" + joint.Scalar() + "' is " +
                        joint_type_name(tree.bodies[i].type) +
                        "; drives act on revolute and prismatic joints");
    }
    for (const JointDrive& other : drives) {
      if (other.body == static_cast<int>(i)) {
        d.fail(joint, what + ": joint '" + joint.Scalar() + "' already has a drive");
      }
    }
    JointDrive drive;
    drive.body = static_cast<int>(i);
    drive.kp = d.number("kp", Range::kNonNegative);
    drive.kd = d.number_or("kd", Range::kNonNegative, 0.0);
    drive.target = read_path(d, d.require("target"), what + ".target");
    drives.push_back(std::move(drive));
  }
  return drives;
}

// `root_motion`: {x, y, z}, each axis a path (read_path) of the base's
// displacement; keyframes are refused where they are written, since their
// rate jumps at every key (articulated.h, ArticulatedOptions::root_motion).
std::optional<std::array<ScalarPath, 3>> read_root_motion(const Section& c) {
  if (!c.has("root_motion")) return std::nullopt;
  const Section m(c.doc(), c.get("root_motion"), c.context(), "root_motion.", {"x", "y", "z"});
  std::array<ScalarPath, 3> paths{ScalarPath::constant(0.0), ScalarPath::constant(0.0),
                                  ScalarPath::constant(0.0)};
  const char* axes[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    if (!m.has(axes[a])) continue;
    const std::string what = std::string("root_motion.") + axes[a];
    paths[a] = read_path(m, m.get(axes[a]), what);
    if (!paths[a].has_continuous_rate()) {
      m.fail(m.get(axes[a]), what +
                                 " is keyframed; a base's path needs a continuous rate (a "
                                 "constant or a sinusoid): each key would jolt the joints "
                                 "with an impulse");
    }
  }
  return paths;
}

std::unique_ptr<System> build_urdf(const Section& c, const std::string& name,
                                   const Eigen::Vector3d& g, const std::filesystem::path& base_dir,
                                   std::vector<std::string>* notes) {
  const std::string file = c.text("file");
  std::filesystem::path resolved(file);
  if (resolved.is_relative()) resolved = base_dir / resolved;
  std::error_code error;
  if (!std::filesystem::is_regular_file(resolved, error)) {
    c.fail(c.get("file"), "URDF file '" + file + "' not found (looked for " +
                              resolved.lexically_normal().string() + ")");
  }
  UrdfOptions uo;
  uo.component_name = name;
  uo.floating_base = c.boolean_or("floating_base", false);
  RigidTree tree;
  try {
    tree = load_urdf(resolved.lexically_normal().string(), uo, notes);
  } catch (const InputError& e) {
    c.fail(c.get("file"), e.what());
  }
  const std::string formulation = c.choice_or("formulation", {"exact", "compliant"}, "exact");

  ArticulatedOptions o;
  o.gravity = g;
  const std::vector<double> k = per_joint(c, "joint_stiffness", Range::kNonNegative, tree, 0.0);
  const std::vector<double> rest = per_joint(c, "joint_rest", Range::kFinite, tree, 0.0);
  const std::vector<double> damping = per_joint(c, "joint_damping", Range::kNonNegative, tree, 0.0);
  o.joint_forces.resize(tree.bodies.size());
  for (std::size_t i = 0; i < tree.bodies.size(); ++i)
    o.joint_forces[i] = JointForce{k[i], rest[i], damping[i]};

  // Offsets of the exact formulation's coordinates, in which `initial` is given.
  std::vector<int> qo, vo;
  int nq = 0, nv = 0;
  for (const TreeBody& b : tree.bodies) {
    qo.push_back(nq);
    vo.push_back(nv);
    nq += joint_nq(b.type);
    nv += joint_nv(b.type);
  }
  o.initial_q = Eigen::VectorXd::Zero(nq);
  o.initial_v = Eigen::VectorXd::Zero(nv);
  for (std::size_t i = 0; i < tree.bodies.size(); ++i) {
    if (tree.bodies[i].type == JointType::kFloating) o.initial_q[qo[i] + 3] = 1.0;
  }
  if (c.has("initial")) {
    const Section init(c.doc(), c.get("initial"), c.context(), "initial.",
                       {"all_joints", "joints", "velocities"});
    if (init.has("all_joints")) {
      const double a = init.number("all_joints", Range::kFinite);
      for (std::size_t i = 0; i < tree.bodies.size(); ++i) {
        if (joint_nq(tree.bodies[i].type) == 1) o.initial_q[qo[i]] = a;
      }
    }
    for (const char* key : {"joints", "velocities"}) {
      if (!init.has(key)) continue;
      const YAML::Node m = init.get(key);
      const bool positions = std::string(key) == "joints";
      if (!m.IsMap())
        init.fail(m, init.label(key) + " must be a map joint name -> value, got " + node_kind(m));
      for (const auto& entry : m) {
        const int i = body_of_joint(init, entry.first, tree, init.label(key));
        const JointType type = tree.bodies[i].type;
        const int size = positions ? joint_nq(type) : joint_nv(type);
        Eigen::VectorXd& target = positions ? o.initial_q : o.initial_v;
        read_joint_values(init, entry.second, init.label(key) + "." + entry.first.Scalar(), size,
                          target.segment(positions ? qo[i] : vo[i], size));
      }
    }
  }
  o.drives = read_drives(c, tree);
  o.root_motion = read_root_motion(c);
  if (formulation == "exact") {
    if (c.has("bushing"))
      c.fail(c.get("bushing"), "bushing applies to formulation: compliant only");
    return with_location(c, name, [&] {
      return std::make_unique<ArticulatedSystem>(std::move(tree), std::move(o));
    });
  }
  if (!o.drives.empty()) {
    c.fail(c.get("drives"), "drives need formulation: exact (the compliant formulation's joints "
                            "are bushings)");
  }
  if (o.root_motion) {
    c.fail(c.get("root_motion"),
           "root_motion needs formulation: exact (the compliant "
           "formulation's bodies are free)");
  }
  BushingParameters bp;
  if (c.has("bushing")) {
    const Section b(c.doc(), c.get("bushing"), c.context(), "bushing.",
                    {"k_lin", "c_lin", "k_ang", "c_ang"});
    bp.k_lin = b.number_or("k_lin", Range::kNonNegative, bp.k_lin);
    bp.c_lin = b.number_or("c_lin", Range::kNonNegative, bp.c_lin);
    bp.k_ang = b.number_or("k_ang", Range::kNonNegative, bp.k_ang);
    bp.c_ang = b.number_or("c_ang", Range::kNonNegative, bp.c_ang);
  }
  return with_location(c, name, [&] { return make_compliant(tree, o, bp); });
}

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
                     tree.tree().file + "; links welded by fixed joints are merged into their parent)");
  }
  if (system.point_elements() == 0) {
    p.fail(link, what + ": component '" + component.Scalar() +
                     "' has a floating or planar joint or is compliant; attachments need an exact "
                     "tree of revolute and prismatic joints");
  }
  out.element = body;
  if (p.has("point")) out.local = vector3("point");
  return out;
}

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
    if (!type_node.IsScalar() || !contains(component_types(), type_node.Scalar())) {
      doc.fail(type_node, context,
               "unknown type " + node_kind(type_node) +
                   " (expected one of: " + join(component_types()) + ")");
    }
    const std::string type = type_node.Scalar();

    const Section c(doc, node, context, "", component_keys(type));
    if (type == "urdf") {
      components.push_back(build_urdf(c, name, gravity, base_dir, &config.notes));
      config.surfaces.emplace_back();
      continue;
    }
    BuiltComponent built;
    if (type == "cloth") {
      built = build_cloth(c, name, gravity);
    } else if (type == "rope") {
      built = build_rope(c, name, gravity);
    } else {
      built = build_mesh(c, name, gravity, base_dir);
    }
    read_node_data(c, base_dir, &built.description);
    read_moving_pins(c, &built.description);
    total_nodes += static_cast<long>(built.description.positions.size());
    if (total_nodes > kMaxTotalNodes) {
      doc.fail(node, context,
               "the scene has more than " + std::to_string(kMaxTotalNodes) + " nodes in total");
    }
    components.push_back(with_location(
        c, name, [&] { return std::make_unique<ParticleSystem>(std::move(built.description)); }));
    config.surfaces.push_back(std::move(built.surface));
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

std::vector<std::string> split(const std::string& text, char separator) {
  std::vector<std::string> parts;
  std::string part;
  std::istringstream stream(text);
  while (std::getline(stream, part, separator)) parts.push_back(part);
  if (!text.empty() && text.back() == separator) parts.push_back("");
  return parts;
}

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
