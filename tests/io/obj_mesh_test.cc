// Wavefront OBJ loading: the face syntaxes, negative indices, ignored
// keywords and the path:line error messages.

#include "stiffsim/io/obj_mesh.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <array>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include "stiffsim/error.h"
#include "stiffsim/model/particles.h"

namespace stiffsim {
namespace {

using Triangles = std::vector<std::array<int, 3>>;

std::string error_of(const std::string& text, const std::string& source = "test.obj") {
  try {
    parse_obj(text, source);
  } catch (const InputError& e) {
    return e.what();
  }
  return "(no InputError)";
}

TEST(ObjMesh, QuadsWithEveryIndexSyntaxAndIgnoredKeywordsBecomeTriangles) {
  // Two quads side by side, written as exporters do: header, mtllib, o/g,
  // usemtl, s, vt/vn, a curve keyword, and each face in a different syntax,
  // the second with negative (relative) indices.
  const std::string text =
      "# exported by some tool\n"
      "mtllib two.mtl\n"
      "o Two\n"
      "v 0 0 0\n"
      "v 1 0 0\n"
      "v 1 1 0 1.0\n"  // optional w
      "v 0 1 0\n"
      "vt 0 0\n"
      "vt 1 0\n"
      "vt 1 1\n"
      "vn 0 0 1\n"
      "g left\n"
      "usemtl Cloth\n"
      "s off\n"
      "f 1/1/1 2/2/1 3/3/1 4/1/1\n"
      "v 2 0 0\n"
      "v 2 1 0\n"
      "cstype bspline\n"
      "l 1 2\n"
      "p 3\n"
      "g right\n"
      "s 1\n"
      "f -5//1 -2//1 -1//1 -4//1\n"  // vertices 2 5 6 3
      "f 2/1 5/2 6/3\n"
      "f 2 5 6\n";
  const TriangleMesh mesh = parse_obj(text, "two.obj");
  ASSERT_EQ(mesh.vertices.size(), 6u);
  EXPECT_EQ(mesh.vertices[2], Eigen::Vector3d(1, 1, 0));
  EXPECT_EQ(mesh.vertices[5], Eigen::Vector3d(2, 1, 0));
  // Fans from the first corner, 0-based.
  EXPECT_EQ(mesh.triangles,
            (Triangles{{0, 1, 2}, {0, 2, 3}, {1, 4, 5}, {1, 5, 2}, {1, 4, 5}, {1, 4, 5}}));
}

TEST(ObjMesh, CommentsCrLfContinuationsAndPentagons) {
  const std::string text =
      "v 0 0 0 # origin\r\n"
      "v 1 0 0\r\n"
      "\r\n"
      "   \t\r\n"
      "v 1.5 1 0\r\n"
      "v +0.5 2 0\r\n"
      "v -5e-1 \\\r\n"
      "  1 0\r\n"
      "f 1 2 3 \\\n"
      "  4 5 # a pentagon\n";
  const TriangleMesh mesh = parse_obj(text, "p.obj");
  ASSERT_EQ(mesh.vertices.size(), 5u);
  EXPECT_EQ(mesh.vertices[3], Eigen::Vector3d(0.5, 2, 0));
  EXPECT_EQ(mesh.vertices[4], Eigen::Vector3d(-0.5, 1, 0));
  EXPECT_EQ(mesh.triangles, (Triangles{{0, 1, 2}, {0, 2, 3}, {0, 3, 4}}));
}

TEST(ObjMesh, MalformedLinesNameThePathAndLine) {
  const std::string head = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
  EXPECT_EQ(error_of(head + "v 1 2\n"),
            "test.obj:4: expected 3 numbers after 'v' (x y z, optionally w or r g b), got 2");
  EXPECT_EQ(error_of(head + "v 1 2 z\n"), "test.obj:4: expected a number after 'v', got 'z'");
  EXPECT_EQ(error_of(head + "v 1 2 nan\n"), "test.obj:4: vertex coordinate must be finite");
  EXPECT_EQ(error_of(head + "# note\nf 1 2 9\n", "sheet.obj"),
            "sheet.obj:5: face index 9 out of range (3 vertices)");
  EXPECT_EQ(error_of(head + "f 1 2 -4\n"), "test.obj:4: face index -4 out of range (3 vertices)");
  EXPECT_EQ(error_of(head + "f 0 1 2\n"), "test.obj:4: face index 0 out of range (3 vertices)");
  EXPECT_EQ(error_of(head + "f 1 2\n"),
            "test.obj:4: expected at least 3 vertices after 'f', got 2");
  EXPECT_EQ(error_of(head + "f 1 2 a\n"),
            "test.obj:4: expected a vertex index (v, v/vt, v//vn or v/vt/vn), got 'a'");
  EXPECT_EQ(error_of(head + "f 1 2 3/x\n"),
            "test.obj:4: expected v, v/vt, v//vn or v/vt/vn, got '3/x'");
  EXPECT_EQ(error_of(head + "f 1 2 3/1/1/1\n"),
            "test.obj:4: expected v, v/vt, v//vn or v/vt/vn, got '3/1/1/1'");
  // A continued statement is reported at the line where it starts.
  EXPECT_EQ(error_of(head + "f 1 \\\n 2 \\\n 7\n"),
            "test.obj:4: face index 7 out of range (3 vertices)");
  // A face may only use vertices defined before it.
  EXPECT_EQ(error_of("v 0 0 0\nv 1 0 0\nf 1 2 3\nv 0 1 0\n"),
            "test.obj:3: face index 3 out of range (2 vertices)");
}

TEST(ObjMesh, MeshWithoutFacesIsAnError) {
  EXPECT_EQ(error_of("v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2\n", "lines.obj"),
            "lines.obj: no faces ('f' lines): a surface mesh needs at least one");
  EXPECT_EQ(error_of("", "empty.obj"),
            "empty.obj: no faces ('f' lines): a surface mesh needs at least one");
}

TEST(ObjMesh, MissingFileSaysCannotOpen) {
  const std::string path = "/nonexistent/dir/sheet.obj";
  try {
    load_obj(path);
    FAIL() << "no InputError";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), path + ": cannot open file");
  }
}

TEST(ObjMesh, LoadedSquareBuildsFiveStretchAndOneBendSpring) {
  const std::string path = testing::TempDir() + "stiffsim_square.obj";
  {
    std::ofstream out(path);
    out << "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1 4//1\n";
  }
  SurfaceMeshSpec spec;
  spec.mesh = load_obj(path);
  std::remove(path.c_str());
  spec.density = 2.0;
  spec.stretch = SpringParameters{50.0, 0.0};
  spec.bend = SpringParameters{1.0, 0.0};
  const ParticleDescription d = make_surface_mesh(spec);
  int stretch = 0, bend = 0;
  for (const Spring& s : d.springs) (s.k == 50.0 ? stretch : bend)++;
  EXPECT_EQ(stretch, 5);
  EXPECT_EQ(bend, 1);
  double total = 0;
  for (double m : d.masses) total += m;
  EXPECT_DOUBLE_EQ(total, 2.0);  // density * area
}

// The mesh keeps where each vertex and face was, so that make_surface_mesh's
// complaints about geometry (a degenerate face, an unused vertex) can send
// the user to the line.
TEST(ObjMesh, RecordsTheLineOfEveryVertexAndTriangle) {
  const TriangleMesh mesh =
      parse_obj("# a quad\nv 0 0 0\nv 1 0 0\n\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n", "q.obj");
  EXPECT_EQ(mesh.source, "q.obj");
  EXPECT_EQ(mesh.vertex_lines, (std::vector<int>{2, 3, 5, 6}));
  EXPECT_EQ(mesh.triangle_lines, (std::vector<int>{7, 7}));  // both halves of the quad

  TriangleMesh collinear = parse_obj("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", "c.obj");
  SurfaceMeshSpec spec;
  spec.name = "sheet";
  spec.mesh = collinear;
  try {
    make_surface_mesh(spec);
    FAIL() << "accepted a degenerate face";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("sheet: c.obj:4: triangle 0"), std::string::npos)
        << e.what();
  }
}

// Binary data is named as such, at the line where it starts.
TEST(ObjMesh, BinaryDataIsNotAText) {
  EXPECT_EQ(error_of(std::string("v 0 0 0\nsolid\0\1", 15)),
            "test.obj:2: not a text file (control byte 0x00): expected an OBJ mesh");
}

TEST(ObjMesh, ShippedSheetIsAUnitSquareHangingFromNodesZeroAndSeven) {
  const TriangleMesh mesh = load_obj(STIFFSIM_SOURCE_DIR "/models/meshes/sheet.obj");
  ASSERT_EQ(mesh.vertices.size(), 64u);
  EXPECT_EQ(mesh.triangles.size(), 2u * 7 * 7);
  // The pins the shipped scenes use: the two corners of the edge y = 0.
  EXPECT_EQ(mesh.vertices[0], Eigen::Vector3d(0, 0, 0));
  EXPECT_EQ(mesh.vertices[7], Eigen::Vector3d(1, 0, 0));
  EXPECT_EQ(mesh.vertices[63], Eigen::Vector3d(1, 1, 0));
  for (const auto& t : mesh.triangles) {
    const Eigen::Vector3d normal = (mesh.vertices[t[1]] - mesh.vertices[t[0]])
                                       .cross(mesh.vertices[t[2]] - mesh.vertices[t[0]]);
    EXPECT_GT(normal.z(), 0.0);  // consistently wound, facing +z
  }
  SurfaceMeshSpec spec;
  spec.mesh = mesh;
  spec.density = 0.2;
  spec.stretch = SpringParameters{1.0e3, 0.1};
  spec.bend = SpringParameters{1.0, 0.01};
  spec.pinned = {0, 7};
  const ParticleSystem sys(make_surface_mesh(spec));
  EXPECT_EQ(sys.dimensions().nv, 3 * 62);
  double total = 0;
  for (double m : sys.description().masses) total += m;
  EXPECT_NEAR(total, 0.2, 1e-12);  // density * 1 m^2
}

}  // namespace
}  // namespace stiffsim
