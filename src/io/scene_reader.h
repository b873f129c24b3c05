#pragma once
// The scene file's typed YAML reader (DESIGN.md section 9): the document
// with the --set values spliced into it, and Section, a map of the schema
// whose keys are checked when it is opened and whose values are read with
// their range, so every message names the file, the line and the key path.
// Private to the scene loader (src/io).

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "stiffsim/error.h"
#include "stiffsim/model/path.h"

namespace stiffsim {
namespace scene_file {

std::string join(const std::vector<std::string>& items, const std::string& separator = ", ");
bool contains(const std::vector<std::string>& items, const std::string& item);
std::string node_kind(const YAML::Node& node);
// Every node of a subtree, so messages can tell which values came from --set.
void collect_nodes(const YAML::Node& node, std::vector<YAML::Node>* out);

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

// A prescribed path: a number (constant), {keyframes: [[t, value], ...]}
// or {sinusoid: {offset, amplitude, frequency, phase}}.
ScalarPath read_path(const Section& c, const YAML::Node& n, const std::string& what);

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

}  // namespace scene_file
}  // namespace stiffsim
