// Tests for the OBJ loader (loadObj, loadObjFromMemory in scene_loader.h).
//
// Expected values come from the OBJ text written in each test (positions,
// face order, line numbers counted by hand) and, for delfshaven.obj, from the
// counts published in shared/data/README.md.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <cmath>
#include <fstream>
#include <map>
#include <numbers>
#include <random>
#include <set>
#include <string>

#include "common/core/error.h"
#include "common/scene/scene_loader.h"
#include "tests/common/support/scene_checks.h"
#include "tests/common/support/shared_data.h"
#include "tests/common/support/temp_dir.h"

namespace vistream {
namespace {

using testing::expectNear;
using ::testing::HasSubstr;
using testing::inputErrorOf;

using testing::TempDir;
namespace fs = std::filesystem;

using testing::kSharedData;

// One triangle of a loaded scene, in file coordinates.
struct FileTriangle {
  size_t object;
  uint32_t faceId;
  uint32_t material;
  glm::dvec3 v[3];
};

std::vector<FileTriangle> fileTriangles(const Scene& scene) {
  std::vector<FileTriangle> out;
  for (size_t o = 0; o < scene.objects.size(); ++o) {
    const TriangleMesh& m = scene.objects[o].mesh;
    for (size_t t = 0; t < m.triangles.size(); ++t) {
      FileTriangle ft{o, m.faceIds[t], m.materials[t], {}};
      for (int k = 0; k < 3; ++k) ft.v[k] = scene.toFile(m.positions[m.triangles[t][k]]);
      out.push_back(ft);
    }
  }
  return out;
}

double area(const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c) {
  return 0.5 * glm::length(glm::cross(b - a, c - a));
}

// The unit normal (a, b, c) winds around, by the right-hand rule.
glm::dvec3 normal(const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c) {
  return glm::normalize(glm::cross(b - a, c - a));
}

// Expects face f of the scene to be one triangle whose corners, in order, are
// the vertices faces[f] lists by their 1-based position in `vertices` (the
// file's `v` lines, with relative indices resolved by hand).
void expectFacesUseVertices(const Scene& scene, const std::vector<glm::dvec3>& vertices,
                            const std::vector<std::array<int, 3>>& faces) {
  std::map<uint32_t, FileTriangle> byFace;
  for (const FileTriangle& t : fileTriangles(scene)) byFace.emplace(t.faceId, t);
  ASSERT_EQ(byFace.size(), faces.size());
  for (uint32_t f = 0; f < faces.size(); ++f)
    for (int k = 0; k < 3; ++k) {
      SCOPED_TRACE("face " + std::to_string(f) + " corner " + std::to_string(k));
      expectNear(byFace.at(f).v[k], vertices.at(size_t(faces[f][size_t(k)] - 1)), 1e-9);
    }
}

// ---- faces and face IDs -----------------------------------------------------

TEST(ObjLoader, SplitsAQuadIntoTwoTrianglesSharingOneFaceId) {
  const Scene scene =
      loadObjFromMemory("v 0 0 0\nv 2 0 0\nv 2 3 0\nv 0 3 0\nf 1 2 3 4\n", "quad.obj");
  EXPECT_EQ(scene.faceCount, 1u);
  const auto tris = fileTriangles(scene);
  ASSERT_EQ(tris.size(), 2u);
  double total = 0.0;
  for (const FileTriangle& t : tris) {
    EXPECT_EQ(t.faceId, 0u);
    total += area(t.v[0], t.v[1], t.v[2]);
    // The quad winds counter-clockwise seen from +z; its triangles must too.
    expectNear(normal(t.v[0], t.v[1], t.v[2]), {0, 0, 1}, 1e-9);
  }
  EXPECT_NEAR(total, 6.0, 1e-9);
}

TEST(ObjLoader, NumbersFacesByFLineOrderNotByTriangleAcrossObjects) {
  const Scene scene = loadObjFromMemory(
      "o Wall\n"
      "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
      "f 1 2 3 4\n"  // face 0: a quad, two triangles
      "o Roof\n"
      "v 0 0 1\nv 1 0 1\nv 0 1 1\nv 1 1 1\n"
      "f 5 6 7\n"   // face 1
      "f 6 8 7\n",  // face 2
      "two.obj");
  EXPECT_EQ(scene.faceCount, 3u);
  ASSERT_EQ(scene.objects.size(), 2u);
  EXPECT_EQ(scene.objects[0].name, "Wall");
  EXPECT_EQ(scene.objects[1].name, "Roof");
  EXPECT_EQ(scene.objects[0].mesh.faceIds, (std::vector<uint32_t>{0, 0}));
  EXPECT_EQ(scene.objects[1].mesh.faceIds, (std::vector<uint32_t>{1, 2}));
  // Face 2 is the triangle (1,0,1) (1,1,1) (0,1,1).
  for (const FileTriangle& t : fileTriangles(scene)) {
    if (t.faceId != 2) continue;
    expectNear(t.v[0], {1, 0, 1}, 1e-9);
    expectNear(t.v[1], {1, 1, 1}, 1e-9);
    expectNear(t.v[2], {0, 1, 1}, 1e-9);
  }
}

TEST(ObjLoader, MakesObjectsOfGGroupsToo) {
  const Scene scene = loadObjFromMemory(
      "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
      "g walls\nf 1 2 3\n"
      "g roofs\nf 3 2 1\nf 1 3 2\n",
      "groups.obj");
  ASSERT_EQ(scene.objects.size(), 2u);
  EXPECT_EQ(scene.objects[0].name, "walls");
  EXPECT_EQ(scene.objects[1].name, "roofs");
  EXPECT_EQ(scene.objects[1].mesh.faceIds, (std::vector<uint32_t>{1, 2}));
}

TEST(ObjLoader, GivesEveryObjectANameEvenWithoutOLines) {
  const Scene scene = loadObjFromMemory("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "anon.obj");
  ASSERT_EQ(scene.objects.size(), 1u);
  EXPECT_FALSE(scene.objects[0].name.empty());
  EXPECT_FALSE(scene.objects[0].dynamic) << "OBJ geometry is static";
}

TEST(ObjLoader, TriangulatesAConcavePolygonFaceUnderOneFaceId) {
  // An L-shaped hexagon in the XZ plane (area 3), then a triangle.
  const Scene scene = loadObjFromMemory(
      "v 0 0 0\nv 0 0 -2\nv 1 0 -2\nv 1 0 -1\nv 2 0 -1\nv 2 0 0\n"
      "f 1 2 3 4 5 6\n"
      "f 1 2 3\n",
      "ell.obj");
  EXPECT_EQ(scene.faceCount, 2u);
  double lArea = 0.0;
  int lTriangles = 0;
  for (const FileTriangle& t : fileTriangles(scene)) {
    if (t.faceId != 0) continue;
    ++lTriangles;
    lArea += area(t.v[0], t.v[1], t.v[2]);
    // The hexagon's own winding has normal -y (its first corner: (0,0,-2) x
    // (1,0,0) = (0,-2,0)); every triangle must keep it.
    expectNear(normal(t.v[0], t.v[1], t.v[2]), {0, -1, 0}, 1e-9);
  }
  EXPECT_EQ(lTriangles, 4);
  EXPECT_NEAR(lArea, 3.0, 1e-9);
}

TEST(ObjLoader, ResolvesRelativeNegativeIndices) {
  const Scene scene = loadObjFromMemory(
      "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
      "f -3 -2 -1\n"  // vertices 1 2 3
      "v 5 0 0\nv 6 0 0\nv 5 1 0\n"
      "f -3 -2 -1\n"  // vertices 4 5 6
      "f -6 2 -1\n",  // vertices 1 2 6
      "relative.obj");
  expectFacesUseVertices(scene, {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {5, 0, 0}, {6, 0, 0}, {5, 1, 0}},
                         {{{1, 2, 3}}, {{4, 5, 6}}, {{1, 2, 6}}});
}

TEST(ObjLoader, ReadsEveryVertexIndexForm) {
  const Scene scene = loadObjFromMemory(
      "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
      "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
      "vn 0 0 1\n"
      "f 1/1 2/2 3/3\n"
      "f 1//1 3//1 4//1\n"
      "f 1/1/1 2/2/1 4/4/1\n"
      "f 2 3 4\n",
      "forms.obj");
  expectFacesUseVertices(scene, {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}},
                         {{{1, 2, 3}}, {{1, 3, 4}}, {{1, 2, 4}}, {{2, 3, 4}}});
}

TEST(ObjLoader, IgnoresCommentsBlankLinesAndCarriageReturns) {
  const Scene scene = loadObjFromMemory(
      "# a comment\r\n\r\nv 0 0 0\r\nv 1 0 0 # trailing\r\nv 0 1 0\r\n\tf 1 2 3\r\n", "crlf.obj");
  ASSERT_EQ(scene.triangleCount(), 1u);
  const FileTriangle t = fileTriangles(scene).at(0);
  expectNear(t.v[1], {1, 0, 0}, 1e-9);
}

TEST(ObjLoader, AcceptsATrailingCommentOnAFaceLine) {
  // LOADER BUG (reported, not fixed here): the line scan strips the comment,
  // but tinyobjloader then reads '#' as a face index and the load fails with
  // "Failed parse `f' line" (no file:line prefix), while the same comment
  // after a `v` line is accepted.
  const std::string msg = inputErrorOf([] {
    const Scene scene =
        loadObjFromMemory("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3 # the only face\n", "tail.obj");
    EXPECT_EQ(scene.faceCount, 1u);
    EXPECT_EQ(scene.triangleCount(), 1u);
  });
  EXPECT_EQ(msg, "<no InputError thrown>");
}

TEST(ObjLoader, AcceptsExplicitPlusSignsOnCoordinates) {
  // LOADER BUG (reported, not fixed here): std::from_chars rejects a leading
  // '+', so "v +1 0 0" (valid C float syntax, read fine by tinyobjloader) is
  // refused as "not a finite number".
  const std::string msg = inputErrorOf([] {
    const Scene scene = loadObjFromMemory("v +1 0 0\nv 2 0 0\nv 1 +1.5e0 0\nf 1 2 3\n", "plus.obj");
    const FileTriangle t = fileTriangles(scene).at(0);
    expectNear(t.v[0], {1, 0, 0}, 1e-9);
    expectNear(t.v[2], {1, 1.5, 0}, 1e-9);
  });
  EXPECT_EQ(msg, "<no InputError thrown>");
}

TEST(ObjLoader, AcceptsVertexColoursAndWeightsAfterTheCoordinates) {
  const Scene scene = loadObjFromMemory(
      "v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\nv 0 0 1 1.0\nf 1 2 3\nf 1 2 4\n", "extra.obj");
  ASSERT_EQ(scene.triangleCount(), 2u);
  expectFacesUseVertices(scene, {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}},
                         {{{1, 2, 3}}, {{1, 2, 4}}});
}

TEST(ObjLoader, KeepsTexcoordsPerVertexWhenTheFileHasThem) {
  // LOADER BUG (reported, not fixed here; possibly a known gap): scene.h says
  // TriangleMesh::texcoords is "per vertex, empty if the source had none", but
  // the OBJ loader never reads `vt`, so texcoords stay empty.
  const Scene scene = loadObjFromMemory(
      "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n", "uv.obj");
  // Here every vertex's uv equals its xy.
  testing::expectTexcoordsEqualFileXy(scene, scene.objects.at(0).mesh);
}

// ---- errors: the message names the file and the line to blame ----------------

TEST(ObjLoader, RejectsANanCoordinateNamingItsLine) {
  const std::string msg = inputErrorOf([] {
    loadObjFromMemory("v 0 0 0\nv 1 0 0\n# the next one is bad\nv 0 nan 0\nf 1 2 3\n", "nan.obj");
  });
  EXPECT_THAT(msg, HasSubstr("nan.obj:4:"));
}

TEST(ObjLoader, RejectsAnInfiniteCoordinateNamingItsLine) {
  const std::string msg =
      inputErrorOf([] { loadObjFromMemory("v 0 0 0\nv inf 0 0\nv 0 1 0\nf 1 2 3\n", "inf.obj"); });
  EXPECT_THAT(msg, HasSubstr("inf.obj:2:"));
  const std::string huge = inputErrorOf(
      [] { loadObjFromMemory("v 0 0 0\nv 1 0 0\nv 0 1e999 0\nf 1 2 3\n", "huge.obj"); });
  EXPECT_THAT(huge, HasSubstr("huge.obj:3:"));
}

TEST(ObjLoader, RejectsAnUnparsableCoordinateNamingItsLine) {
  for (const char* bad : {"1.2.3", "abc", "1,5", "0x"}) {
    SCOPED_TRACE(bad);
    const std::string text = std::string("v 0 0 0\nv 1 0 0\nv 0 ") + bad + " 0\nf 1 2 3\n";
    EXPECT_THAT(inputErrorOf([&] { loadObjFromMemory(text, "garbled.obj"); }),
                HasSubstr("garbled.obj:3:"));
  }
}

TEST(ObjLoader, RejectsAVertexWithTooFewCoordinates) {
  EXPECT_THAT(inputErrorOf([] { loadObjFromMemory("v 0 0 0\nv 1 0\nf 1 2 1\n", "short.obj"); }),
              HasSubstr("short.obj:2:"));
}

TEST(ObjLoader, RejectsAFaceWithTwoVerticesNamingItsLine) {
  const std::string msg = inputErrorOf(
      [] { loadObjFromMemory("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2\n", "line.obj"); });
  EXPECT_THAT(msg, HasSubstr("line.obj:5:"));
}

TEST(ObjLoader, RejectsIndexZeroNamingItsLine) {
  const std::string msg =
      inputErrorOf([] { loadObjFromMemory("v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 0 1 2\n", "zero.obj"); });
  EXPECT_THAT(msg, HasSubstr("zero.obj:5:"));
}

TEST(ObjLoader, RejectsAnOutOfRangeIndexNamingItsLine) {
  const std::string msg = inputErrorOf([] {
    loadObjFromMemory("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 4\nf 3 2 1\n", "range.obj");
  });
  EXPECT_THAT(msg, HasSubstr("range.obj:5:"));
  // A vertex defined after the face does not make a forward reference valid
  // for a relative index.
  const std::string rel =
      inputErrorOf([] { loadObjFromMemory("v 0 0 0\nv 1 0 0\nf -1 -2 -3\nv 0 1 0\n", "rel.obj"); });
  EXPECT_THAT(rel, HasSubstr("rel.obj:3:"));
}

TEST(ObjLoader, RejectsAMalformedIndexToken) {
  EXPECT_THAT(
      inputErrorOf([] { loadObjFromMemory("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n", "token.obj"); }),
      HasSubstr("token.obj:4:"));
}

TEST(ObjLoader, RejectsEmptyAndWhitespaceOnlyFiles) {
  EXPECT_THAT(inputErrorOf([] { loadObjFromMemory("", "empty.obj"); }), HasSubstr("empty.obj"));
  EXPECT_THAT(inputErrorOf([] { loadObjFromMemory("  \n\t\r\n\n", "blank.obj"); }),
              HasSubstr("blank.obj"));
}

TEST(ObjLoader, RejectsAFileWithVerticesButNoFaces) {
  EXPECT_THAT(inputErrorOf([] { loadObjFromMemory("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "cloud.obj"); }),
              HasSubstr("cloud.obj"));
}

TEST(ObjLoader, RejectsAMissingPathAndADirectory) {
  const TempDir dir;
  const fs::path missing = dir.path() / "nothing_here.obj";
  EXPECT_THAT(inputErrorOf([&] { loadObj(missing); }), HasSubstr(missing.string()));
  const fs::path sub = dir.path() / "folder.obj";
  fs::create_directory(sub);
  EXPECT_THAT(inputErrorOf([&] { loadObj(sub); }), HasSubstr(sub.string()));
}

TEST(ObjLoader, NamesTheFileOnDiskInLineErrors) {
  const TempDir dir;
  const fs::path p = dir.write("broken.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 7\n");
  EXPECT_THAT(inputErrorOf([&] { loadObj(p); }), HasSubstr("broken.obj:5:"));
}

TEST(ObjLoader, NeverThrowsAnythingButInputErrorOnGarbage) {
  // Random mutations of a valid file and random bytes: each either loads or
  // throws InputError, never crashes or throws something else.
  const std::string valid =
      "mtllib x.mtl\no A\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n"
      "usemtl m\nf 1/1/1 2/1/1 3/1/1 4/1/1\ng B\nf -1 -2 -3\n";
  const std::string alphabet = "vfontg/-.0123456789e \n#\r\tx";
  std::mt19937 rng(7);
  int loaded = 0, rejected = 0;
  for (int k = 0; k < 400; ++k) {
    std::string text = valid;
    if (k % 4 == 3) {
      text.assign(size_t(rng() % 200), ' ');
      for (char& c : text) c = char(rng() % 256);
    } else {
      const int edits = 1 + int(rng() % 4);
      for (int e = 0; e < edits; ++e) {
        const size_t at = rng() % text.size();
        switch (rng() % 3) {
          case 0:
            text[at] = alphabet[rng() % alphabet.size()];
            break;
          case 1:
            text.insert(at, 1, alphabet[rng() % alphabet.size()]);
            break;
          default:
            text.erase(at, 1);
            break;
        }
      }
    }
    try {
      const Scene s = loadObjFromMemory(text, "fuzz.obj");
      ++loaded;
      for (const Object& o : s.objects) {
        ASSERT_EQ(o.mesh.faceIds.size(), o.mesh.triangles.size());
        for (const glm::uvec3& t : o.mesh.triangles)
          ASSERT_LT(glm::max(t.x, glm::max(t.y, t.z)), o.mesh.positions.size());
        for (uint32_t f : o.mesh.faceIds) ASSERT_LT(f, s.faceCount);
      }
    } catch (const InputError&) {
      ++rejected;
    }
  }
  EXPECT_GT(loaded, 0);
  EXPECT_GT(rejected, 0);
}

// ---- degenerate triangles ------------------------------------------------------

TEST(ObjLoader, CountsDegenerateTrianglesAndKeepsThem) {
  const Scene scene = loadObjFromMemory(
      "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\n"
      "f 1 2 3\n"   // fine
      "f 1 1 2\n"   // repeated index
      "f 1 2 4\n",  // three collinear points
      "degenerate.obj");
  EXPECT_EQ(scene.triangleCount(), 3u);
  EXPECT_EQ(scene.faceCount, 3u);
  EXPECT_EQ(scene.diagnostics.repeatedVertexTriangles, 1u);
  EXPECT_EQ(scene.diagnostics.zeroAreaTriangles, 1u);
  EXPECT_EQ(scene.diagnostics.degenerateTriangles, 2u);
  std::set<uint32_t> faces;
  for (const FileTriangle& t : fileTriangles(scene)) faces.insert(t.faceId);
  EXPECT_EQ(faces, (std::set<uint32_t>{0, 1, 2}));
  // Flattening marks exactly the two degenerate ones.
  const FlatTriangles flat = flattenScene(scene);
  ASSERT_EQ(flat.size(), 3u);
  for (size_t i = 0; i < flat.size(); ++i)
    EXPECT_EQ(flat.degenerate[i], flat.faceIds[i] == 0 ? 0 : 1) << "face " << flat.faceIds[i];
}

// ---- precision far from the origin ---------------------------------------------

TEST(ObjLoader, KeepsSubMillimetrePrecision50KmFromTheOrigin) {
  // A 1 cm right triangle and a large one, all about 50 km out.
  const glm::dvec3 p[6] = {{50000.1234567, 12.3456789, -49999.7654321},
                           {50000.1334567, 12.3456789, -49999.7654321},
                           {50000.1234567, 12.3556789, -49999.7654321},
                           {49000.0000001, 0.0, -49000.0},
                           {51000.0, 0.0, -49000.0},
                           {50000.0, 40.0, -51000.0}};
  std::string text;
  for (const glm::dvec3& v : p) text += fmt::format("v {:.7f} {:.7f} {:.7f}\n", v.x, v.y, v.z);
  text += "f 1 2 3\nf 4 5 6\n";
  const Scene scene = loadObjFromMemory(text, "far.obj");
  const auto tris = fileTriangles(scene);
  ASSERT_EQ(tris.size(), 2u);
  const FileTriangle& tiny = tris[0].faceId == 0 ? tris[0] : tris[1];
  const FileTriangle& big = tris[0].faceId == 0 ? tris[1] : tris[0];
  for (int k = 0; k < 3; ++k) {
    expectNear(tiny.v[k], p[k], 1e-4);
    expectNear(big.v[k], p[3 + k], 1e-4);
  }
  // The tiny triangle keeps its shape: 1 cm legs, right angle, area 0.5 cm^2.
  EXPECT_NEAR(glm::length(tiny.v[1] - tiny.v[0]), 0.01, 1e-5);
  EXPECT_NEAR(glm::length(tiny.v[2] - tiny.v[0]), 0.01, 1e-5);
  EXPECT_NEAR(glm::dot(tiny.v[1] - tiny.v[0], tiny.v[2] - tiny.v[0]), 0.0, 1e-8);
  EXPECT_NEAR(area(tiny.v[0], tiny.v[1], tiny.v[2]), 0.5e-4, 1e-6);
  EXPECT_EQ(scene.diagnostics.degenerateTriangles, 0u);
  // File bounds agree with the file to the same precision.
  const Box3d b = scene.fileBounds();
  expectNear(b.lo, {49000.0000001, 0.0, -51000.0}, 1e-3);
  expectNear(b.hi, {51000.0, 40.0, -49000.0}, 1e-3);
}

// ---- materials -----------------------------------------------------------------

TEST(ObjLoader, AppliesDiffuseColoursFromUsemtl) {
  const Scene scene = loadObjFromMemory(
      "mtllib colours.mtl\n"
      "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n"
      "usemtl red\nf 1 2 3\n"
      "usemtl green\nf 2 4 3\nf 1 2 4\n"
      "usemtl red\nf 1 4 3\n",
      "painted.obj", "newmtl green\nKd 0 1 0\n\nnewmtl red\nKd 1 0 0\n");
  std::map<uint32_t, glm::vec3> colourOfFace;
  for (const FileTriangle& t : fileTriangles(scene)) {
    ASSERT_LT(t.material, scene.materials.size());
    colourOfFace[t.faceId] = scene.materials[t.material].diffuse;
  }
  ASSERT_EQ(colourOfFace.size(), 4u);
  EXPECT_EQ(colourOfFace[0], glm::vec3(1, 0, 0));
  EXPECT_EQ(colourOfFace[1], glm::vec3(0, 1, 0));
  EXPECT_EQ(colourOfFace[2], glm::vec3(0, 1, 0));
  EXPECT_EQ(colourOfFace[3], glm::vec3(1, 0, 0));
}

TEST(ObjLoader, ReadsTheMtllibBesideTheFile) {
  const TempDir dir;
  dir.write("lib.mtl", "newmtl blue\nKd 0 0 1\n");
  const fs::path p =
      dir.write("scene.obj", "mtllib lib.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl blue\nf 1 2 3\n");
  const Scene scene = loadObj(p);
  const auto tris = fileTriangles(scene);
  ASSERT_EQ(tris.size(), 1u);
  EXPECT_EQ(scene.materials.at(tris[0].material).diffuse, glm::vec3(0, 0, 1));
  EXPECT_EQ(scene.materials.at(tris[0].material).name, "blue");
  EXPECT_EQ(scene.name, "scene");
  ASSERT_EQ(scene.sources.size(), 1u);
  EXPECT_EQ(scene.sources[0], p);
}

TEST(ObjLoader, LoadsWithDefaultMaterialsWhenTheMtllibIsMissing) {
  const TempDir dir;
  const fs::path p = dir.write("bare.obj",
                               "mtllib gone.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                               "usemtl nowhere\nf 1 2 3\n");
  const Scene scene = loadObj(p);
  ASSERT_EQ(scene.triangleCount(), 1u);
  ASSERT_FALSE(scene.materials.empty());
  EXPECT_LT(scene.objects[0].mesh.materials[0], scene.materials.size());
}

// ---- hostile files: limits, index overflow, float range ----------------------------

// A regular `n`-gon of radius 10 in the z = 0 plane, written once, and
// `faces` faces that each use all of its vertices: (n - 2) * faces triangles.
std::string manyVertexFaces(size_t faces, size_t n) {
  std::string text;
  for (size_t k = 0; k < n; ++k) {
    const double a = 2.0 * std::numbers::pi * double(k) / double(n);
    text += fmt::format("v {:.17g} {:.17g} 0\n", 10.0 * std::cos(a), 10.0 * std::sin(a));
  }
  std::string face = "f";
  for (size_t k = 1; k <= n; ++k) face += " " + std::to_string(k);
  face += "\n";
  for (size_t f = 0; f < faces; ++f) text += face;
  return text;
}

SceneLimits triangleLimitOf(uint64_t triangles) {
  return {triangles, kDefaultMaxSceneFileBytes};
}

TEST(ObjLoader, RejectsMoreTrianglesThanTheLimitNamingCountLimitAndFlag) {
  // 10 faces of 255 vertices: 10 * 253 = 2530 triangles.
  const std::string text = manyVertexFaces(10, 255);
  const std::string msg =
      inputErrorOf([&] { loadObjFromMemory(text, "fan.obj", {}, triangleLimitOf(2529)); });
  EXPECT_THAT(msg, HasSubstr("fan.obj"));
  EXPECT_THAT(msg, HasSubstr("2530 triangles, more than the limit of 2529"));
  EXPECT_THAT(msg, HasSubstr("--max-scene-triangles"));
  EXPECT_THROW(loadObjFromMemory(text, "fan.obj", {}, triangleLimitOf(2529)), SceneLimitError);
}

TEST(ObjLoader, LoadsExactlyAtTheTriangleLimit) {
  const Scene scene =
      loadObjFromMemory(manyVertexFaces(10, 255), "fan.obj", {}, triangleLimitOf(2530));
  EXPECT_EQ(scene.triangleCount(), 2530u);
  EXPECT_EQ(scene.faceCount, 10u);
}

TEST(ObjLoader, StopsCheckingAtTheFaceThatCrossesTheLimit) {
  // The file of the issue: 20,000 faces of 255 vertices (5,060,000 triangles,
  // 1 GB and 6.7 s to load). A bad vertex after the faces is never reached:
  // the scan stops at the face past the limit, before any parsing, and the
  // message still reports the whole file's count.
  const std::string text = manyVertexFaces(20000, 255) + "v nan 0 0\n";
  const std::string msg =
      inputErrorOf([&] { loadObjFromMemory(text, "issue.obj", {}, triangleLimitOf(1000000)); });
  EXPECT_THAT(msg, HasSubstr("issue.obj: 5060000 triangles, more than the limit of 1000000"));
}

TEST(ObjLoader, CapsVerticesAtThreePerAllowedTriangle) {
  std::string text;
  for (int i = 0; i < 100; ++i) text += fmt::format("v {} 0 0\n", i);
  text += "f 1 2 3\n";
  EXPECT_THAT(inputErrorOf([&] { loadObjFromMemory(text, "cloud.obj", {}, triangleLimitOf(33)); }),
              HasSubstr("cloud.obj: 100 vertices, more than the limit of 99"));
  EXPECT_EQ(loadObjFromMemory(text, "cloud.obj", {}, triangleLimitOf(34)).triangleCount(), 1u);
}

TEST(ObjLoader, NamesTheTrianglesWhenTheVertexCapTripsFirstButBothAreOver) {
  // The 4 `v` lines come first and pass the cap of 3 (limit 1 triangle)
  // before the quad's 2 triangles are read: the message names the triangles.
  const std::string msg = inputErrorOf([] {
    loadObjFromMemory("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n", "quad.obj", {},
                      triangleLimitOf(1));
  });
  EXPECT_THAT(msg, HasSubstr("quad.obj: 2 triangles, more than the limit of 1"));
}

TEST(ObjLoader, RejectsAFileLargerThanTheFileSizeLimit) {
  const std::string text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";  // 32 bytes
  ASSERT_EQ(text.size(), 32u);
  const TempDir dir;
  const fs::path p = dir.write("small.obj", text);
  const std::string msg = inputErrorOf([&] { loadObj(p, {kDefaultMaxSceneTriangles, 31}); });
  EXPECT_THAT(msg, HasSubstr("small.obj"));
  EXPECT_THAT(msg, HasSubstr("32 bytes, more than the limit of 31 bytes"));
  EXPECT_EQ(loadObj(p, {kDefaultMaxSceneTriangles, 32}).triangleCount(), 1u);
  EXPECT_THAT(inputErrorOf([&] {
                loadObjFromMemory(text, "mem.obj", {}, {kDefaultMaxSceneTriangles, 31});
              }),
              HasSubstr("mem.obj: the file has 32 bytes"));
}

TEST(ObjLoader, RefusesAMaterialLibraryThatIsNotARegularFile) {
  // `mtllib /dev/zero` used to read forever.
  const TempDir dir;
  const fs::path p =
      dir.write("zero.obj", "mtllib /dev/zero\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  EXPECT_THAT(inputErrorOf([&] { loadObj(p); }), HasSubstr("/dev/zero: is not a regular file"));
}

TEST(ObjLoader, RejectsTheMostNegativeIndexNamingItsLine) {
  // -(-9223372036854775808) overflows long long: the scan must compare
  // without negating.
  const std::string msg = inputErrorOf([] {
    loadObjFromMemory("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -9223372036854775808\n", "llmin.obj");
  });
  EXPECT_THAT(msg, HasSubstr("llmin.obj:4:"));
  EXPECT_THAT(msg,
              HasSubstr("relative face index -9223372036854775808 refers before the first vertex"));
}

TEST(ObjLoader, RejectsTexcoordAndNormalIndicesBeyondInt) {
  // tinyobjloader reads these with atoi, undefined outside int.
  for (const char* vertex :
       {"3/-9223372036854775808", "3/1/99999999999999999999", "3//2147483648", "3/-2147483649"}) {
    SCOPED_TRACE(vertex);
    const std::string text =
        std::string("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\nf 1/1/1 2/1/1 ") + vertex + "\n";
    const std::string msg = inputErrorOf([&] { loadObjFromMemory(text, "wide.obj"); });
    EXPECT_THAT(msg, HasSubstr("wide.obj:6:"));
    EXPECT_THAT(msg, HasSubstr("index out of range"));
  }
}

TEST(ObjLoader, RejectsACoordinateThatOverflowsFloatNamingItsLine) {
  // 1e308 is a finite double; relative to the origin (5e307) it is no float.
  const std::string msg = inputErrorOf(
      [] { loadObjFromMemory("v 0 1 0\nv 1e308 0 0\nv 0 0 0\nf 1 2 3\n", "far.obj"); });
  EXPECT_THAT(msg, HasSubstr("far.obj:2: vertex 2"));
  EXPECT_THAT(msg, HasSubstr("single precision"));
}

TEST(ObjLoader, RejectsAnUnusedVertexThatOverflowsFloat) {
  // Not referenced by any face, but it still moves the origin.
  const std::string msg = inputErrorOf([] {
    loadObjFromMemory("v 0 0 0\nv 1 0 0\nv 0 1 0\n# far away\nv 0 0 -1e300\nf 1 2 3\n",
                      "unused.obj");
  });
  EXPECT_THAT(msg, HasSubstr("unused.obj:5: vertex 4 (0, 0, -1e+300)"));
  EXPECT_THAT(msg, HasSubstr("single precision"));
}

TEST(ObjLoader, KeepsAFloatFarFromZeroThatIsNearTheLocalOrigin) {
  // 3e38 is close to FLT_MAX, but the local origin sits there: local
  // coordinates are small, and the file coordinates come back exactly.
  const Scene scene =
      loadObjFromMemory("v 3e38 0 0\nv 3e38 1 0\nv 3e38 0 1\nf 1 2 3\n", "edge.obj");
  ASSERT_EQ(scene.triangleCount(), 1u);
  EXPECT_EQ(scene.fileBounds().lo.x, 3e38);
  EXPECT_EQ(scene.fileBounds().hi.z, 1.0);
}

// ---- real data: delfshaven.obj ---------------------------------------------------

class Delfshaven : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { scene_ = new Scene(loadObj(kSharedData / "delfshaven.obj")); }
  static void TearDownTestSuite() {
    delete scene_;
    scene_ = nullptr;
  }
  static const Scene* scene_;
};
const Scene* Delfshaven::scene_ = nullptr;

// shared/data/README.md: 853 buildings, 38,772 triangles, one triangle per face.
constexpr size_t kDelfshavenBuildings = 853;
constexpr size_t kDelfshavenTriangles = 38772;

TEST_F(Delfshaven, HasTheBuildingAndTriangleCountsOfTheDataReadme) {
  EXPECT_EQ(scene_->objects.size(), kDelfshavenBuildings);
  EXPECT_EQ(scene_->triangleCount(), kDelfshavenTriangles);
  EXPECT_EQ(scene_->faceCount, kDelfshavenTriangles);
  std::set<std::string> names;
  for (const Object& o : scene_->objects) names.insert(o.name);
  EXPECT_EQ(names.size(), kDelfshavenBuildings) << "object names are distinct";
  EXPECT_EQ(scene_->dynamicObjectCount(), 0u);
}

TEST_F(Delfshaven, UsesEveryFaceIdExactlyOnce) {
  std::vector<int> uses(scene_->faceCount, 0);
  for (const Object& o : scene_->objects) {
    ASSERT_EQ(o.mesh.faceIds.size(), o.mesh.triangles.size());
    for (uint32_t f : o.mesh.faceIds) {
      ASSERT_LT(f, uses.size());
      ++uses[f];
    }
  }
  for (size_t f = 0; f < uses.size(); ++f) ASSERT_EQ(uses[f], 1) << "face " << f;
}

TEST_F(Delfshaven, IsYUpWithTheGroundAtZeroAndCentredOnItsFootprint) {
  const Box3d b = scene_->fileBounds();
  EXPECT_NEAR(b.lo.y, 0.0, 1e-3);
  EXPECT_GT(b.hi.y, 5.0) << "buildings rise along +y";
  EXPECT_LT(b.hi.y, 200.0);
  // Footprint of several hundred metres in x and z, centred on the origin.
  EXPECT_GT(b.extent().x, 100.0);
  EXPECT_GT(b.extent().z, 100.0);
  EXPECT_NEAR(b.center().x, 0.0, 0.01);
  EXPECT_NEAR(b.center().z, 0.0, 0.01);
}

TEST_F(Delfshaven, KeepsObjectBoundsAroundTheirTriangles) {
  for (const Object& o : scene_->objects) {
    for (const glm::vec3& p : o.mesh.positions) ASSERT_TRUE(o.bounds.contains(p)) << o.name;
  }
}

}  // namespace
}  // namespace vistream
