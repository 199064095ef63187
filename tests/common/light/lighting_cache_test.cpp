#include "common/light/lighting_cache.h"

#include <gtest/gtest.h>

#include <fstream>

#include "common/light/environment_light.h"
#include "tests/common/support/box_scenes.h"
#include "tests/common/support/temp_dir.h"

namespace vistream {
namespace {

// A floor with one box on it, a textured material on the box.
Scene boxOnFloor(const std::filesystem::path& dir) {
  Scene s;
  s.name = "box on floor";
  s.sources = {dir / "scene.obj"};
  s.materials = {Material::diffuseColour("floor", glm::vec3(0.6f)), Material::named("brick")};
  s.materials[1].baseColorTexture = "brick.pgm";
  testing::addGround(s, -20, -20, 20, 20);
  testing::addBox(s, "box", {-2, 0, -2}, {2, 3, 2});
  Object& box = s.objects.back();
  box.mesh.materials.assign(box.mesh.triangles.size(), 1u);
  box.mesh.texcoords.assign(box.mesh.positions.size(), glm::vec2(0.25f));
  finalizeScene(s);
  return s;
}

void writeGreyTexture(const std::filesystem::path& file, int side, uint8_t grey) {
  std::ofstream out(file, std::ios::binary | std::ios::trunc);
  out << "P5\n" << side << " " << side << "\n255\n";
  for (int i = 0; i < side * side; ++i) out.put(char(grey));
}

struct CacheFixture : ::testing::Test {
  testing::TempDir dir;
  Scene scene;
  FlatTriangles triangles;
  EnvironmentLight light = EnvironmentLight::of(Environment{});
  LightingOptions options;

  CacheFixture() {
    writeGreyTexture(dir.path() / "brick.pgm", 4, 200);
    scene = boxOnFloor(dir.path());
    triangles = flattenScene(scene, true);
    options.aoRays = 8;
  }
  LightingLoad load() {
    return loadOrBakeLighting(scene, triangles, light, options, dir.path() / "cache");
  }
};

TEST_F(CacheFixture, TheSecondLoadReadsTheFirstBakeBack) {
  const LightingLoad first = load();
  EXPECT_FALSE(first.fromCache);
  ASSERT_TRUE(std::filesystem::exists(first.file));
  const LightingLoad second = load();
  EXPECT_TRUE(second.fromCache);
  EXPECT_EQ(second.file, first.file);
  EXPECT_EQ(second.grid.level, first.grid.level);
  EXPECT_EQ(second.grid.first, first.grid.first);
  EXPECT_EQ(second.grid.colours, first.grid.colours);
}

TEST_F(CacheFixture, AFlippedOrTruncatedFileIsBakedAgainWithTheSameColours) {
  const LightingLoad first = load();
  const auto size = std::filesystem::file_size(first.file);
  for (const bool truncate : {false, true}) {
    if (truncate) {
      std::filesystem::resize_file(first.file, size / 2);
    } else {
      std::fstream f(first.file, std::ios::in | std::ios::out | std::ios::binary);
      f.seekp(std::streamoff(size - 12));
      f.put('\x5a');
    }
    const LightingLoad again = load();
    EXPECT_FALSE(again.fromCache) << (truncate ? "truncated" : "flipped");
    EXPECT_EQ(again.grid.colours, first.grid.colours);
    EXPECT_EQ(std::filesystem::file_size(first.file), size);  // rewritten whole
  }
}

TEST_F(CacheFixture, TheKeyFollowsGeometryMaterialsTexturesAndOptions) {
  const uint64_t key = lightingKey(scene, triangles, options);
  EXPECT_EQ(lightingKey(scene, triangles, options), key);

  Scene moved = scene;
  moved.objects.back().mesh.positions[0].y += 0.5f;
  EXPECT_NE(lightingKey(moved, flattenScene(moved, true), options), key);

  Scene recoloured = scene;
  recoloured.materials[0].diffuse = glm::vec3(0.5f);
  EXPECT_NE(lightingKey(recoloured, triangles, options), key);

  Scene remapped = scene;
  remapped.objects.back().mesh.texcoords[0] = glm::vec2(0.75f);
  EXPECT_NE(lightingKey(remapped, triangles, options), key);

  LightingOptions more = options;
  more.aoRays = 16;
  EXPECT_NE(lightingKey(scene, triangles, more), key);

  writeGreyTexture(dir.path() / "brick.pgm", 8, 40);  // a new texture under the old name
  EXPECT_NE(lightingKey(scene, triangles, options), key);
}

TEST_F(CacheFixture, AnEmbeddedImageIsKeyedByItsBytes) {
  scene.materials[1].baseColorImage = std::make_shared<const std::vector<uint8_t>>(4, 1);
  const uint64_t key = lightingKey(scene, triangles, options);
  scene.materials[1].baseColorImage = std::make_shared<const std::vector<uint8_t>>(4, 2);
  EXPECT_NE(lightingKey(scene, triangles, options), key);
}

TEST_F(CacheFixture, ADirectoryThatCannotBeWrittenStillBakes) {
  const auto blocker = dir.path() / "not-a-dir";
  std::ofstream(blocker) << "a file where the cache directory should be";
  const LightingLoad l = loadOrBakeLighting(scene, triangles, light, options, blocker / "cache");
  EXPECT_FALSE(l.fromCache);
  EXPECT_TRUE(l.file.empty());
  EXPECT_EQ(l.grid.size(), triangles.size());
}

}  // namespace
}  // namespace vistream
