#pragma once
// Wavefront OBJ surface meshes as modelling tools write them: v, vt, vn,
// faces with v, v/vt, v//vn, v/vt/vn and negative (relative) indices,
// polygons fan-triangulated; o, g, usemtl, mtllib, s, l, p lines and comments
// ignored.

#include <string>

#include "stiffsim/model/particle_meshes.h"

namespace stiffsim {

// Throws InputError "<path>:<line>: <what was expected>" on malformed input,
// or "<path>: cannot open" when the file is missing.
TriangleMesh load_obj(const std::string& path);
TriangleMesh parse_obj(const std::string& text, const std::string& source_name);

}  // namespace stiffsim
