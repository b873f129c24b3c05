#include "stiffsim/io/obj_mesh.h"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string_view>
#include <vector>

#include "stiffsim/error.h"

namespace stiffsim {

namespace {

bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v'; }

std::vector<std::string_view> split_tokens(std::string_view line) {
  std::vector<std::string_view> tokens;
  size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && is_space(line[i])) ++i;
    const size_t start = i;
    while (i < line.size() && !is_space(line[i])) ++i;
    if (i > start) tokens.push_back(line.substr(start, i - start));
  }
  return tokens;
}

// std::from_chars is locale independent (strtod would read "0,5" under a
// German locale) but rejects a leading '+', which some exporters write.
bool parse_double(std::string_view token, double* out) {
  if (!token.empty() && token.front() == '+') token.remove_prefix(1);
  const char* end = token.data() + token.size();
  const auto [ptr, ec] = std::from_chars(token.data(), end, *out);
  return ec == std::errc() && ptr == end;
}

bool parse_int(std::string_view token, long* out) {
  if (!token.empty() && token.front() == '+') token.remove_prefix(1);
  if (token.empty()) return false;
  const char* end = token.data() + token.size();
  const auto [ptr, ec] = std::from_chars(token.data(), end, *out);
  return ec == std::errc() && ptr == end;
}

class ObjParser {
 public:
  explicit ObjParser(const std::string& source) : source_(source) { mesh_.source = source; }

  [[noreturn]] void fail(int line, const std::string& what) const {
    throw InputError(source_ + ":" + std::to_string(line) + ": " + what);
  }

  void vertex(int line, const std::vector<std::string_view>& tokens) {
    // x y z, then an optional w, or r g b vertex colours (MeshLab, ZBrush).
    if (tokens.size() < 4 || tokens.size() > 7) {
      fail(line, "expected 3 numbers after 'v' (x y z, optionally w or r g b), got " +
                     std::to_string(tokens.size() - 1));
    }
    Eigen::Vector3d p;
    for (size_t i = 1; i < tokens.size(); ++i) {
      double value;
      if (!parse_double(tokens[i], &value)) {
        fail(line, "expected a number after 'v', got '" + std::string(tokens[i]) + "'");
      }
      if (i <= 3) {
        if (!std::isfinite(value)) fail(line, "vertex coordinate must be finite");
        p[i - 1] = value;
      }
    }
    mesh_.vertices.push_back(p);
    mesh_.vertex_lines.push_back(line);
  }

  // "v", "v/vt", "v//vn" or "v/vt/vn": only the vertex index matters, but the
  // others must still be integers so a garbled face is reported.
  int face_vertex(int line, std::string_view token) {
    std::string_view parts[3];
    int count = 0;
    size_t start = 0;
    while (true) {
      const size_t slash = token.find('/', start);
      if (count == 3)
        fail(line, "expected v, v/vt, v//vn or v/vt/vn, got '" + std::string(token) + "'");
      parts[count++] = token.substr(start, slash == std::string_view::npos ? slash : slash - start);
      if (slash == std::string_view::npos) break;
      start = slash + 1;
    }
    long index;
    if (!parse_int(parts[0], &index)) {
      fail(line,
           "expected a vertex index (v, v/vt, v//vn or v/vt/vn), got '" + std::string(token) + "'");
    }
    for (int i = 1; i < count; ++i) {
      long ignored;
      const bool optional_empty = parts[i].empty() && i == 1 && count == 3;  // v//vn
      if (!optional_empty && !parse_int(parts[i], &ignored)) {
        fail(line, "expected v, v/vt, v//vn or v/vt/vn, got '" + std::string(token) + "'");
      }
    }
    const long n = static_cast<long>(mesh_.vertices.size());
    // Negative indices count back from the last vertex defined so far.
    const long resolved = index > 0 ? index - 1 : n + index;
    if (index == 0 || resolved < 0 || resolved >= n) {
      fail(line, "face index " + std::to_string(index) + " out of range (" + std::to_string(n) +
                     " vertices)");
    }
    return static_cast<int>(resolved);
  }

  void face(int line, const std::vector<std::string_view>& tokens) {
    if (tokens.size() < 4) {
      fail(line,
           "expected at least 3 vertices after 'f', got " + std::to_string(tokens.size() - 1));
    }
    corners_.clear();
    for (size_t i = 1; i < tokens.size(); ++i) corners_.push_back(face_vertex(line, tokens[i]));
    // Polygons are fanned from their first corner: exact for the convex
    // (usually planar quad) faces that exporters write.
    for (size_t i = 1; i + 1 < corners_.size(); ++i) {
      mesh_.triangles.push_back({corners_[0], corners_[i], corners_[i + 1]});
      mesh_.triangle_lines.push_back(line);
    }
  }

  void logical_line(int line, std::string_view text) {
    const size_t hash = text.find('#');
    if (hash != std::string_view::npos) text = text.substr(0, hash);
    const std::vector<std::string_view> tokens = split_tokens(text);
    if (tokens.empty()) return;
    const std::string_view keyword = tokens[0];
    if (keyword == "v") {
      vertex(line, tokens);
    } else if (keyword == "f") {
      face(line, tokens);
    }
    // Everything else is ignored on purpose: vt, vn, vp, o, g, s, usemtl,
    // mtllib, l, p, and the many keywords tools add (cstype, deg, curv,
    // surf, bevel, lod, ...) carry nothing a particle surface needs.
  }

  TriangleMesh finish() {
    if (mesh_.triangles.empty()) {
      throw InputError(source_ + ": no faces ('f' lines): a surface mesh needs at least one");
    }
    return std::move(mesh_);
  }

 private:
  std::string source_;
  TriangleMesh mesh_;
  std::vector<int> corners_;
};

}  // namespace

TriangleMesh parse_obj(const std::string& text, const std::string& source_name) {
  ObjParser parser(source_name);
  std::string logical;  // a line joined with its backslash continuations
  int logical_start = 0;
  int line_number = 0;
  size_t pos = 0;
  while (pos < text.size()) {
    size_t end = text.find('\n', pos);
    if (end == std::string::npos) end = text.size();
    std::string_view line(text.data() + pos, end - pos);
    pos = end + 1;
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    // A binary file (an STL, a zip) named as an OBJ would otherwise end in a
    // puzzling "no faces" or number error somewhere down the file.
    for (const char ch : line) {
      const auto byte = static_cast<unsigned char>(ch);
      if ((byte < 0x20 && !is_space(ch)) || byte == 0x7f) {
        char hex[8];
        std::snprintf(hex, sizeof hex, "0x%02x", byte);
        parser.fail(line_number, std::string("not a text file (control byte ") + hex +
                                     "): expected an OBJ mesh");
      }
    }
    if (logical.empty()) logical_start = line_number;
    if (!line.empty() && line.back() == '\\') {
      logical.append(line.data(), line.size() - 1);
      logical.push_back(' ');
      continue;
    }
    logical.append(line.data(), line.size());
    // Errors name the line where the statement starts.
    parser.logical_line(logical_start, logical);
    logical.clear();
  }
  if (!logical.empty()) parser.logical_line(logical_start, logical);
  return parser.finish();
}

TriangleMesh load_obj(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path + ": cannot open file");
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) throw InputError(path + ": cannot read file");
  return parse_obj(text.str(), path);
}

}  // namespace stiffsim
