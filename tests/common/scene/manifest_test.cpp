// Tests for scene manifests (loadManifest in manifest.h) and for loadScene's
// dispatch on the file extension (scene_loader.h).
//
// Each test writes its OBJ files and manifest into a fresh temp directory;
// expected positions and face IDs follow from those texts by hand. The real
// data (delfshaven.obj, Fox.glb, the HDR) is used through absolute paths or a
// copy, with the counts from shared/data/README.md.
#include "common/scene/manifest.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <fstream>
#include <map>
#include <set>
#include <string>

#include "common/core/error.h"
#include "common/scene/scene_loader.h"
#include "tests/common/support/scene_checks.h"
#include "tests/common/support/shared_data.h"
#include "tests/common/support/temp_dir.h"

namespace vistream {
namespace {

using testing::findObject;
using ::testing::HasSubstr;
using testing::inputErrorOf;
using ::testing::StartsWith;
namespace fs = std::filesystem;

using testing::kSharedData;

using testing::TempDir;

// Two faces (a quad and a triangle, three triangles) in object "A" near the origin.
const char* const kA = "o A\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\nf 1 2 3\n";
// Three faces in object "B" around (100, 0, 0).
const char* const kB =
    "o B\nv 100 0 0\nv 101 0 0\nv 100 1 0\nv 100 0 1\nf 1 2 3\nf 1 3 4\nf 1 4 2\n";
const std::vector<glm::dvec3> kBPositions{{100, 0, 0}, {101, 0, 0}, {100, 1, 0}, {100, 0, 1}};

// Every vertex an object's triangles use, in file coordinates.
std::vector<glm::dvec3> usedFilePositions(const Scene& scene, const Object& o) {
  std::set<uint32_t> used;
  for (const glm::uvec3& t : o.mesh.triangles) used.insert({t.x, t.y, t.z});
  std::vector<glm::dvec3> out;
  for (uint32_t i : used) out.push_back(scene.toFile(o.mesh.positions.at(i)));
  return out;
}

// True if every expected point is among `actual` (to `tol`) and the counts match.
bool samePointSet(const std::vector<glm::dvec3>& actual, const std::vector<glm::dvec3>& expected,
                  double tol) {
  if (actual.size() != expected.size()) return false;
  for (const glm::dvec3& e : expected) {
    if (std::none_of(actual.begin(), actual.end(),
                     [&](const glm::dvec3& a) { return glm::length(a - e) <= tol; }))
      return false;
  }
  return true;
}

std::string describe(const std::vector<glm::dvec3>& points) {
  std::string s;
  for (const glm::dvec3& p : points) s += fmt::format("({}, {}, {}) ", p.x, p.y, p.z);
  return s;
}

// ---- combining files ------------------------------------------------------------------

TEST(Manifest, OffsetsFaceIdsOfTheSecondFileByTheFacesOfTheFirst) {
  const TempDir dir;
  const fs::path a = dir.write("a.obj", kA), b = dir.write("b.obj", kB);
  const fs::path m = dir.write("street.json", R"({"geometry": ["a.obj", "b.obj"]})");
  const Scene scene = loadManifest(m);
  EXPECT_EQ(scene.faceCount, 5u);
  EXPECT_EQ(scene.triangleCount(), 6u);
  const Object* oa = findObject(scene, "A");
  const Object* ob = findObject(scene, "B");
  ASSERT_NE(oa, nullptr);
  ASSERT_NE(ob, nullptr);
  EXPECT_EQ(oa->mesh.faceIds, (std::vector<uint32_t>{0, 0, 1}));
  EXPECT_EQ(ob->mesh.faceIds, (std::vector<uint32_t>{2, 3, 4}));
  ASSERT_EQ(scene.sources.size(), 2u);
  EXPECT_TRUE(fs::equivalent(scene.sources[0], a));
  EXPECT_TRUE(fs::equivalent(scene.sources[1], b));
  EXPECT_EQ(scene.name, "street") << "the default name is the manifest's stem";
  EXPECT_EQ(scene.dynamicObjectCount(), 0u);
}

TEST(Manifest, KeepsFilePositionsOfEveryPartUnderTheCommonOrigin) {
  const TempDir dir;
  dir.write("a.obj", kA);
  dir.write("b.obj", kB);
  const Scene scene =
      loadManifest(dir.write("m.json", R"({"geometry": ["a.obj", "b.obj"], "name": "two"})"));
  EXPECT_EQ(scene.name, "two");
  const auto pa = usedFilePositions(scene, *findObject(scene, "A"));
  const auto pb = usedFilePositions(scene, *findObject(scene, "B"));
  EXPECT_TRUE(samePointSet(pa, {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}}, 1e-4)) << describe(pa);
  EXPECT_TRUE(samePointSet(pb, kBPositions, 1e-4)) << describe(pb);
  const Box3d bounds = scene.fileBounds();
  EXPECT_NEAR(bounds.lo.x, 0.0, 1e-4);
  EXPECT_NEAR(bounds.hi.x, 101.0, 1e-4);
}

TEST(Manifest, ResolvesGeometryPathsRelativeToTheManifest) {
  const TempDir dir;
  dir.write("models/b.obj", kB);
  const Scene scene =
      loadManifest(dir.write("scenes/m.json", R"({"geometry": ["../models/b.obj"]})"));
  EXPECT_EQ(scene.faceCount, 3u);
  ASSERT_NE(findObject(scene, "B"), nullptr);
}

TEST(Manifest, MarksEveryObjectOfADynamicFileDynamic) {
  const TempDir dir;
  dir.write("a.obj", kA);
  dir.write("b.obj", kB);
  const Scene scene = loadManifest(
      dir.write("m.json", R"({"geometry": ["a.obj", {"file": "b.obj", "dynamic": true}]})"));
  EXPECT_FALSE(findObject(scene, "A")->dynamic);
  EXPECT_TRUE(findObject(scene, "B")->dynamic);
  EXPECT_EQ(scene.dynamicObjectCount(), 1u);
  const FlatTriangles statics = flattenScene(scene, true);
  EXPECT_EQ(statics.size(), 3u) << "only A's three triangles are static";
}

TEST(Manifest, PrefixesObjectNamesWithTheEntryName) {
  const TempDir dir;
  dir.write("b.obj", kB);
  const Scene scene =
      loadManifest(dir.write("m.json", R"({"geometry": [{"file": "b.obj", "name": "cart"}]})"));
  ASSERT_EQ(scene.objects.size(), 1u);
  EXPECT_THAT(scene.objects[0].name, StartsWith("cart"));
  EXPECT_THAT(scene.objects[0].name, HasSubstr("B"));
}

TEST(Manifest, PlacesAFileByScaleThenTranslateInFileCoordinates) {
  const TempDir dir;
  dir.write("a.obj", kA);
  dir.write("b.obj", kB);
  const Scene scene = loadManifest(dir.write(
      "m.json",
      R"({"geometry": ["a.obj", {"file": "b.obj", "scale": 2, "translate": [10, 0, -5]}]})"));
  std::vector<glm::dvec3> expected;
  for (const glm::dvec3& p : kBPositions) expected.push_back(p * 2.0 + glm::dvec3(10, 0, -5));
  const auto pb = usedFilePositions(scene, *findObject(scene, "B"));
  EXPECT_TRUE(samePointSet(pb, expected, 1e-4)) << describe(pb);
  // The unplaced file stays where it was.
  const auto pa = usedFilePositions(scene, *findObject(scene, "A"));
  EXPECT_TRUE(samePointSet(pa, {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}}, 1e-4)) << describe(pa);
  // Object bounds follow the placed geometry.
  const Box3d bounds = scene.fileBounds();
  EXPECT_NEAR(bounds.hi.x, 212.0, 1e-3);
  EXPECT_NEAR(bounds.lo.z, -5.0, 1e-3);
}

TEST(Manifest, PlacesAFileWithTranslateAlone) {
  const TempDir dir;
  dir.write("b.obj", kB);
  const Scene scene = loadManifest(
      dir.write("m.json", R"({"geometry": [{"file": "b.obj", "translate": [0.5, 7, 0]}]})"));
  std::vector<glm::dvec3> expected;
  for (const glm::dvec3& p : kBPositions) expected.push_back(p + glm::dvec3(0.5, 7, 0));
  const auto pb = usedFilePositions(scene, scene.objects.at(0));
  EXPECT_TRUE(samePointSet(pb, expected, 1e-4)) << describe(pb);
}

TEST(Manifest, PlacesAFile50KmOutWithSubMillimetrePrecision) {
  // LOADER BUG (reported, not fixed here): manifest.cpp reads "translate" as a
  // glm::vec3 of float, so 50000.1234567 becomes 50000.125 before it is
  // applied (1.6 mm off), although the placement is documented as "kept in
  // double" and scene.h promises sub-millimetre precision 50 km out.
  const TempDir dir;
  dir.write("b.obj", kB);
  const Scene scene = loadManifest(dir.write(
      "m.json",
      R"({"geometry": [{"file": "b.obj", "translate": [50000.1234567, 0, -49999.7654321]}]})"));
  std::vector<glm::dvec3> expected;
  for (const glm::dvec3& p : kBPositions)
    expected.push_back(p + glm::dvec3(50000.1234567, 0, -49999.7654321));
  const auto pb = usedFilePositions(scene, scene.objects.at(0));
  EXPECT_TRUE(samePointSet(pb, expected, 1e-4)) << describe(pb);
}

TEST(Manifest, LoadsTheSameFileTwiceAsTwoPlacedCopies) {
  const TempDir dir;
  dir.write("b.obj", kB);
  const Scene scene =
      loadManifest(dir.write("m.json", R"({"geometry": [{"file": "b.obj", "name": "left"},
                                 {"file": "b.obj", "name": "right", "translate": [0, 0, 10]}]})"));
  EXPECT_EQ(scene.faceCount, 6u);
  ASSERT_EQ(scene.objects.size(), 2u);
  EXPECT_THAT(scene.objects[0].name, StartsWith("left"));
  EXPECT_THAT(scene.objects[1].name, StartsWith("right"));
  EXPECT_EQ(scene.objects[0].mesh.faceIds, (std::vector<uint32_t>{0, 1, 2}));
  EXPECT_EQ(scene.objects[1].mesh.faceIds, (std::vector<uint32_t>{3, 4, 5}));
  std::vector<glm::dvec3> moved;
  for (const glm::dvec3& p : kBPositions) moved.push_back(p + glm::dvec3(0, 0, 10));
  EXPECT_TRUE(samePointSet(usedFilePositions(scene, scene.objects[0]), kBPositions, 1e-4));
  EXPECT_TRUE(samePointSet(usedFilePositions(scene, scene.objects[1]), moved, 1e-4));
}

TEST(Manifest, KeepsEachFilesMaterialsOnItsOwnTriangles) {
  const TempDir dir;
  dir.write("red.mtl", "newmtl paint\nKd 1 0 0\n");
  dir.write("blue.mtl", "newmtl paint\nKd 0 0 1\n");
  dir.write("red.obj", "mtllib red.mtl\no R\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl paint\nf 1 2 3\n");
  dir.write("blue.obj", "mtllib blue.mtl\no U\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl paint\nf 1 2 3\n");
  const Scene scene = loadManifest(dir.write("m.json", R"({"geometry": ["red.obj", "blue.obj"]})"));
  const Object* r = findObject(scene, "R");
  const Object* u = findObject(scene, "U");
  ASSERT_NE(r, nullptr);
  ASSERT_NE(u, nullptr);
  EXPECT_EQ(scene.materials.at(r->mesh.materials.at(0)).diffuse, glm::vec3(1, 0, 0));
  EXPECT_EQ(scene.materials.at(u->mesh.materials.at(0)).diffuse, glm::vec3(0, 0, 1));
}

// ---- environment ----------------------------------------------------------------------

TEST(Manifest, DefaultsTheEnvironment) {
  const TempDir dir;
  dir.write("a.obj", kA);
  const Scene scene = loadManifest(dir.write("m.json", R"({"geometry": ["a.obj"]})"));
  EXPECT_EQ(scene.environment.sky, SkyMode::Auto);
  EXPECT_TRUE(scene.environment.hdrImage.empty());
  EXPECT_FLOAT_EQ(scene.environment.nearFieldRadius, 150.0f);
}

TEST(Manifest, ParsesEverySkyMode) {
  const TempDir dir;
  dir.write("a.obj", kA);
  const std::vector<std::pair<const char*, SkyMode>> modes{
      {"none", SkyMode::None}, {"open", SkyMode::Open}, {"auto", SkyMode::Auto}};
  for (const auto& [text, mode] : modes) {
    SCOPED_TRACE(text);
    const Scene scene = loadManifest(dir.write(
        std::string("sky_") + text + ".json",
        fmt::format(R"({{"geometry": ["a.obj"], "environment": {{"sky": "{}"}}}})", text)));
    EXPECT_EQ(scene.environment.sky, mode);
  }
}

TEST(Manifest, ReadsSkyColourAndNearFieldRadius) {
  const TempDir dir;
  dir.write("a.obj", kA);
  const Scene scene =
      loadManifest(dir.write("m.json", R"({"geometry": ["a.obj"], "near_field_radius": 80.5,
                   "environment": {"sky": "open", "sky_color": [0.1, 0.2, 0.3]}})"));
  EXPECT_FLOAT_EQ(scene.environment.nearFieldRadius, 80.5f);
  EXPECT_EQ(scene.environment.skyColor, glm::vec3(0.1f, 0.2f, 0.3f));
  EXPECT_EQ(scene.environment.sky, SkyMode::Open);
}

TEST(Manifest, ResolvesTheHdrPathRelativeToTheManifest) {
  const TempDir dir;
  dir.write("a.obj", kA);
  const fs::path copy = dir.path() / "sky" / "beach.hdr";
  fs::create_directories(copy.parent_path());
  fs::copy_file(kSharedData / "spiaggia_di_mondello_1k.hdr", copy);
  const Scene scene = loadManifest(
      dir.write("scenes/m.json",
                R"({"geometry": ["../a.obj"], "environment": {"hdr": "../sky/beach.hdr"}})"));
  ASSERT_FALSE(scene.environment.hdrImage.empty());
  EXPECT_TRUE(fs::equivalent(scene.environment.hdrImage, copy));
}

TEST(Manifest, AcceptsAnAbsoluteHdrPath) {
  const TempDir dir;
  dir.write("a.obj", kA);
  const fs::path hdr = fs::absolute(kSharedData / "spiaggia_di_mondello_1k.hdr");
  const Scene scene = loadManifest(dir.write(
      "m.json", fmt::format(R"({{"geometry": ["a.obj"], "environment": {{"hdr": "{}"}}}})",
                            hdr.generic_string())));
  EXPECT_TRUE(fs::equivalent(scene.environment.hdrImage, hdr));
}

// ---- errors: InputError naming the manifest and the key ----------------------------------

// Writes `text` as a manifest beside a.obj and returns the loader's message.
std::string manifestError(const TempDir& dir, const std::string& text) {
  dir.write("a.obj", kA);
  const fs::path m = dir.write("bad.json", text);
  return inputErrorOf([&] { loadManifest(m); });
}

// Checks that the manifest `text` is rejected with a message naming each of `words`.
void expectRejectedNaming(const TempDir& dir, const std::string& text,
                          std::initializer_list<const char*> words) {
  const std::string msg = manifestError(dir, text);
  for (const char* word : words) EXPECT_THAT(msg, HasSubstr(word));
}

TEST(Manifest, RejectsAnUnknownTopLevelKey) {
  const TempDir dir;
  expectRejectedNaming(dir, R"({"geometry": ["a.obj"], "geometery": []})",
                       {"bad.json", "geometery"});
}

TEST(Manifest, RejectsAnUnknownKeyInTheEnvironment) {
  const TempDir dir;
  expectRejectedNaming(dir, R"({"geometry": ["a.obj"], "environment": {"skye": "open"}})",
                       {"bad.json", "skye"});
}

TEST(Manifest, RejectsAnUnknownKeyInAGeometryEntry) {
  const TempDir dir;
  expectRejectedNaming(dir, R"({"geometry": ["a.obj", {"file": "a.obj", "dynamc": true}]})",
                       {"bad.json", "geometry[1]", "dynamc"});
}

TEST(Manifest, RejectsMissingOrEmptyGeometry) {
  const TempDir dir;
  for (const char* text :
       {R"({"name": "nothing"})", R"({"geometry": []})", R"({"geometry": "a.obj"})"}) {
    SCOPED_TRACE(text);
    expectRejectedNaming(dir, text, {"bad.json", "geometry"});
  }
}

TEST(Manifest, RejectsAGeometryEntryThatIsNeitherAPathNorAnObject) {
  const TempDir dir;
  for (const char* text : {R"({"geometry": ["a.obj", 42]})", R"({"geometry": ["a.obj", null]})",
                           R"({"geometry": ["a.obj", ["a.obj"]]})"}) {
    SCOPED_TRACE(text);
    expectRejectedNaming(dir, text, {"bad.json", "geometry[1]"});
  }
}

TEST(Manifest, RejectsAGeometryObjectWithoutAFile) {
  const TempDir dir;
  expectRejectedNaming(dir, R"({"geometry": [{"dynamic": true}]})", {"geometry[0]", "file"});
}

TEST(Manifest, RejectsBadValuesInAGeometryEntry) {
  const TempDir dir;
  const std::vector<std::pair<const char*, const char*>> cases{
      {R"({"geometry": [{"file": "a.obj", "dynamic": "yes"}]})", "dynamic"},
      {R"({"geometry": [{"file": "a.obj", "scale": -1}]})", "scale"},
      {R"({"geometry": [{"file": "a.obj", "scale": 0}]})", "scale"},
      {R"({"geometry": [{"file": "a.obj", "translate": [1, 2]}]})", "translate"},
      {R"({"geometry": [{"file": "a.obj", "translate": "up"}]})", "translate"},
      {R"({"geometry": [{"file": "a.obj", "name": 7}]})", "name"},
  };
  for (const auto& [text, key] : cases) {
    SCOPED_TRACE(text);
    expectRejectedNaming(dir, text, {"geometry[0]", key});
  }
}

TEST(Manifest, RejectsABadSkyValue) {
  const TempDir dir;
  for (const char* text : {R"({"geometry": ["a.obj"], "environment": {"sky": "cloudy"}})",
                           R"({"geometry": ["a.obj"], "environment": {"sky": true}})"}) {
    SCOPED_TRACE(text);
    expectRejectedNaming(dir, text, {"bad.json", "sky"});
  }
}

TEST(Manifest, RejectsBadEnvironmentValues) {
  const TempDir dir;
  const std::vector<std::pair<const char*, const char*>> cases{
      {R"({"geometry": ["a.obj"], "environment": {"sky_color": [1, 2]}})", "sky_color"},
      {R"({"geometry": ["a.obj"], "environment": {"hdr": 5}})", "hdr"},
      {R"({"geometry": ["a.obj"], "environment": "sunny"})", "environment"},
      {R"({"geometry": ["a.obj"], "near_field_radius": -3})", "near_field_radius"},
      {R"({"geometry": ["a.obj"], "near_field_radius": "far"})", "near_field_radius"},
  };
  for (const auto& [text, key] : cases) {
    SCOPED_TRACE(text);
    expectRejectedNaming(dir, text, {"bad.json", key});
  }
}

TEST(Manifest, RejectsASceneNameThatIsNotAString) {
  // LOADER BUG (reported, not fixed here): a non-string top-level "name" is
  // silently replaced by the file stem, while every other mistyped value (an
  // entry's "name" included) is rejected; the header says a typo must not
  // silently change a scene.
  const TempDir dir;
  expectRejectedNaming(dir, R"({"name": 7, "geometry": ["a.obj"]})", {"bad.json", "name"});
}

TEST(Manifest, RejectsAMissingHdrFile) {
  const TempDir dir;
  expectRejectedNaming(dir, R"({"geometry": ["a.obj"], "environment": {"hdr": "nowhere.hdr"}})",
                       {"bad.json", "hdr", "nowhere.hdr"});
}

TEST(Manifest, RejectsAMissingGeometryFileNamingIt) {
  const TempDir dir;
  expectRejectedNaming(dir, R"({"geometry": ["a.obj", "lost.obj"]})", {"lost.obj"});
}

TEST(Manifest, PassesOnTheErrorOfABrokenGeometryFile) {
  const TempDir dir;
  dir.write("broken.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n");
  expectRejectedNaming(dir, R"({"geometry": ["a.obj", "broken.obj"]})", {"broken.obj:4:"});
}

TEST(Manifest, RejectsInvalidJson) {
  const TempDir dir;
  for (const char* text :
       {R"({"geometry": ["a.obj",]})", "", "not json at all", R"({"geometry": ["a.obj"])"}) {
    SCOPED_TRACE(text);
    expectRejectedNaming(dir, text, {"bad.json"});
  }
}

TEST(Manifest, RejectsJsonThatIsNotAnObject) {
  const TempDir dir;
  for (const char* text : {R"(["a.obj"])", "42", R"("a.obj")"}) {
    SCOPED_TRACE(text);
    expectRejectedNaming(dir, text, {"bad.json"});
  }
}

TEST(Manifest, RejectsAManifestThatIncludesAManifest) {
  const TempDir dir;
  dir.write("a.obj", kA);
  dir.write("inner.json", R"({"geometry": ["a.obj"]})");
  for (const char* text : {R"({"geometry": ["a.obj", "inner.json"]})",
                           R"({"geometry": ["a.obj", {"file": "inner.JSON"}]})"}) {
    SCOPED_TRACE(text);
    expectRejectedNaming(dir, text, {"bad.json", "geometry[1]"});
  }
}

TEST(Manifest, LimitsTheTrianglesOfAllPartsTogether) {
  // a.obj and b.obj have 3 triangles each: 6 in all.
  const TempDir dir;
  dir.write("a.obj", kA);
  dir.write("b.obj", kB);
  const fs::path m = dir.write("pair.json", R"({"geometry": ["a.obj", "b.obj"]})");
  const std::string msg = inputErrorOf([&] {
    loadManifest(m, SceneLimits{5, kDefaultMaxSceneFileBytes});
  });
  EXPECT_THAT(msg, StartsWith(m.string() + ": geometry[1]: "));
  EXPECT_THAT(msg, HasSubstr("b.obj: 3 triangles, more than the limit of 2"));
  EXPECT_THAT(msg,
              HasSubstr("the scene's limit is 5 triangles and the files before this one have 3"));
  EXPECT_THAT(msg, HasSubstr("--max-scene-triangles"));
  EXPECT_EQ(loadManifest(m, SceneLimits{6, kDefaultMaxSceneFileBytes}).triangleCount(), 6u);
}

TEST(Manifest, PassesTheLimitsOnThroughLoadScene) {
  const TempDir dir;
  dir.write("a.obj", kA);
  const fs::path m = dir.write("one.json", R"({"geometry": ["a.obj"]})");
  EXPECT_THROW(loadScene(m, SceneLimits{2, kDefaultMaxSceneFileBytes}), SceneLimitError);
  EXPECT_EQ(loadScene(m, SceneLimits{3, kDefaultMaxSceneFileBytes}).triangleCount(), 3u);
}

TEST(Manifest, RejectsJsonNestedDeeperThanTheLimit) {
  const TempDir dir;
  expectRejectedNaming(dir,
                       R"({"geometry": ["a.obj"], "name": )" + std::string(20000, '[') +
                           std::string(20000, ']') + "}",
                       {"bad.json:1: JSON nesting depth exceeds the limit of 256"});
}

TEST(Manifest, RejectsAPlacementThatPushesPositionsBeyondFloatRange) {
  // Each file is fine on its own; scaled by 1e300 about the file origin, the
  // triangle spans 1e300 m and no float holds its corners' offsets.
  const TempDir dir;
  expectRejectedNaming(dir, R"({"geometry": [{"file": "a.obj", "name": "huge", "scale": 1e300}]})",
                       {"bad.json: geometry[0]: placing", "single precision"});
}

TEST(Manifest, RejectsAMissingManifest) {
  const TempDir dir;
  const fs::path m = dir.path() / "absent.json";
  EXPECT_THAT(inputErrorOf([&] { loadManifest(m); }), HasSubstr("absent.json"));
}

// ---- real data ----------------------------------------------------------------------------

TEST(Manifest, CombinesDelfshavenWithAPlacedDynamicFox) {
  const TempDir dir;
  const fs::path city = fs::absolute(kSharedData / "delfshaven.obj");
  const fs::path fox = fs::absolute(kSharedData / "Fox.glb");
  const Scene scene = loadManifest(
      dir.write("harbour.json", fmt::format(R"({{"name": "harbour walk",
                      "geometry": ["{}", {{"file": "{}", "dynamic": true, "name": "fox",
                                           "translate": [0, 0, 5], "scale": 0.01}}],
                      "environment": {{"sky": "open"}}}})",
                                            city.generic_string(), fox.generic_string())));
  // shared/data/README.md: 853 buildings with 38,772 triangles; a fox of 576.
  constexpr uint32_t kCityFaces = 38772, kFoxFaces = 576;
  EXPECT_EQ(scene.name, "harbour walk");
  EXPECT_EQ(scene.faceCount, kCityFaces + kFoxFaces);
  EXPECT_EQ(scene.triangleCount(), size_t(kCityFaces + kFoxFaces));
  EXPECT_EQ(scene.objects.size(), 853u + 1u);
  EXPECT_EQ(scene.dynamicObjectCount(), 1u);
  EXPECT_EQ(scene.environment.sky, SkyMode::Open);
  const Object& foxObject = scene.objects.back();
  EXPECT_TRUE(foxObject.dynamic);
  EXPECT_THAT(foxObject.name, StartsWith("fox"));
  std::set<uint32_t> foxFaces(foxObject.mesh.faceIds.begin(), foxObject.mesh.faceIds.end());
  ASSERT_EQ(foxFaces.size(), kFoxFaces);
  EXPECT_EQ(*foxFaces.begin(), kCityFaces);
  EXPECT_EQ(*foxFaces.rbegin(), kCityFaces + kFoxFaces - 1);
  // Skin, nodes and clips come along, with joints still naming valid nodes.
  ASSERT_EQ(scene.skins.size(), 1u);
  EXPECT_EQ(foxObject.skin, 0);
  for (int32_t j : scene.skins[0].joints) EXPECT_LT(size_t(j), scene.nodes.size());
  EXPECT_EQ(scene.animations.size(), 3u);
  // The fox's POSITION accessor spans x [-12.59, 12.59], y [-0.122, 78.91],
  // z [-88.10, 66.62] (its min/max in Fox.glb); scaled by 0.01, moved 5 along z.
  Box3d foxBox;
  for (const glm::vec3& p : foxObject.mesh.positions) foxBox.extend(scene.toFile(p));
  EXPECT_NEAR(foxBox.lo.x, -0.12592718, 1e-4);
  EXPECT_NEAR(foxBox.hi.y, 0.78907188, 1e-4);
  EXPECT_NEAR(foxBox.lo.z, 5.0 - 0.88095001, 1e-4);
  EXPECT_NEAR(foxBox.hi.z, 5.0 + 0.66624869, 1e-4);
  // The city is where the OBJ put it: ground at y = 0, centred in x.
  Box3d cityBox;
  for (const Object& o : scene.objects)
    if (!o.dynamic)
      for (const glm::vec3& p : o.mesh.positions) cityBox.extend(scene.toFile(p));
  EXPECT_NEAR(cityBox.lo.y, 0.0, 1e-3);
  EXPECT_NEAR(cityBox.center().x, 0.0, 0.01);
}

// ---- loadScene dispatch -------------------------------------------------------------------

TEST(LoadScene, ReadsObjFilesWhateverTheCaseOfTheExtension) {
  const TempDir dir;
  for (const char* name : {"lower.obj", "UPPER.OBJ"}) {
    SCOPED_TRACE(name);
    const Scene scene = loadScene(dir.write(name, kB));
    EXPECT_EQ(scene.faceCount, 3u);
    ASSERT_NE(findObject(scene, "B"), nullptr);
  }
}

TEST(LoadScene, ReadsGlbFiles) {
  const Scene scene = loadScene(kSharedData / "Fox.glb");
  EXPECT_EQ(scene.triangleCount(), 576u);
  EXPECT_EQ(scene.animations.size(), 3u);
}

TEST(LoadScene, ReadsJsonManifests) {
  const TempDir dir;
  dir.write("a.obj", kA);
  dir.write("b.obj", kB);
  const Scene scene = loadScene(dir.write("m.json", R"({"geometry": ["a.obj", "b.obj"]})"));
  EXPECT_EQ(scene.faceCount, 5u);
  EXPECT_EQ(scene.objects.size(), 2u);
}

TEST(LoadScene, RejectsUnknownExtensionsNamingTheFile) {
  const TempDir dir;
  for (const char* name : {"model.ply", "model.obj.bak", "model", "model.fbx"}) {
    SCOPED_TRACE(name);
    const fs::path p = dir.write(name, kA);  // valid OBJ text: the extension alone decides
    EXPECT_THAT(inputErrorOf([&] { loadScene(p); }), HasSubstr(name));
  }
}

}  // namespace
}  // namespace vistream
