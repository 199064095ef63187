#include "common/light/texture.h"

#include <gtest/gtest.h>

#include <fstream>

#include "common/scene/scene_loader.h"
#include "tests/common/support/temp_dir.h"

namespace vistream {
namespace {

// A 4 x 2 texture: columns 0..3 of row 0 are red, green, blue, white; row 1
// is black everywhere.
Texture stripes() {
  const glm::vec3 r(1, 0, 0), g(0, 1, 0), b(0, 0, 1), w(1, 1, 1), k(0, 0, 0);
  return Texture::fromLinear(4, 2, {r, g, b, w, k, k, k, k});
}

void expectColour(const glm::vec3& got, const glm::vec3& want) {
  EXPECT_NEAR(got.r, want.r, 1e-6f);
  EXPECT_NEAR(got.g, want.g, 1e-6f);
  EXPECT_NEAR(got.b, want.b, 1e-6f);
}

TEST(Texture, TheWholeMeanIsTheMeanOfEveryTexel) {
  expectColour(stripes().mean(), glm::vec3(2, 2, 2) / 8.0f);
  expectColour(stripes().mean({0, 0}, {1, 1}), glm::vec3(2, 2, 2) / 8.0f);
}

TEST(Texture, ABoxInsideOneTexelIsThatTexel) {
  expectColour(stripes().mean({0.30f, 0.1f}, {0.45f, 0.4f}), {0, 1, 0});
  expectColour(stripes().mean({0.6f, 0.2f}, {0.6f, 0.2f}), {0, 0, 1});  // a point
}

TEST(Texture, ABoxOverTwoTexelsOfTheTopRowIsTheirMean) {
  expectColour(stripes().mean({0.5f, 0.0f}, {1.0f, 0.5f}), {0.5f, 0.5f, 1.0f});
}

TEST(Texture, CoordinatesBeyondOneWrapAround) {
  // Columns 3 (white) and 4 = 0 (red) of the top row.
  expectColour(stripes().mean({0.80f, 0.1f}, {1.20f, 0.4f}), {1.0f, 0.5f, 0.5f});
  // The same box shifted by whole periods, negative ones included.
  expectColour(stripes().mean({-2.20f, 3.1f}, {-1.80f, 3.4f}), {1.0f, 0.5f, 0.5f});
  // A box three periods wide is the whole mean again.
  expectColour(stripes().mean({0.0f, 0.0f}, {3.0f, 1.0f}), glm::vec3(2, 2, 2) / 8.0f);
}

// A checkerboard PNG of 8 x 8 texels in 2 x 2 squares of sRGB 255 and 0:
// linear 1 and 0, so any box of whole squares has mean 0.5 and one square is
// 1 or 0, computed by hand from the pattern.
TEST(Texture, ACheckerboardPngHasTheHandComputedMeans) {
  testing::TempDir dir;
  // An uncompressed 8x8 grey PGM is something stb_image reads too.
  const auto file = dir.path() / "checker.pgm";
  {
    std::ofstream out(file, std::ios::binary);
    out << "P5\n8 8\n255\n";
    for (int y = 0; y < 8; ++y)
      for (int x = 0; x < 8; ++x) out.put(char(((x / 2 + y / 2) % 2) ? 0 : 255));
  }
  std::string error;
  const auto t = Texture::load(file, error);
  ASSERT_TRUE(t) << error;
  EXPECT_EQ(t->width(), 8);
  expectColour(t->mean(), glm::vec3(0.5f));
  expectColour(t->mean({0.0f, 0.0f}, {0.25f, 0.25f}), glm::vec3(1.0f));  // square (0, 0)
  expectColour(t->mean({0.25f, 0.0f}, {0.5f, 0.25f}), glm::vec3(0.0f));  // square (1, 0)
  expectColour(t->mean({0.0f, 0.0f}, {0.5f, 0.25f}), glm::vec3(0.5f));   // both
}

TEST(Texture, AMissingOrCorruptFileIsAnErrorNotACrash) {
  testing::TempDir dir;
  std::string error;
  EXPECT_FALSE(Texture::load(dir.path() / "nothing.png", error));
  EXPECT_FALSE(error.empty());
  const auto bad = dir.path() / "bad.png";
  std::ofstream(bad) << "\x89PNG\r\n\x1a\n garbage";
  error.clear();
  EXPECT_FALSE(Texture::load(bad, error));
  EXPECT_FALSE(error.empty());
  const uint8_t bytes[] = {1, 2, 3};
  EXPECT_FALSE(Texture::decode(bytes, error));
}

// Width and height from a PNG's IHDR chunk (bytes 16..23, big-endian),
// read without any image library: the oracle for the decoder's size.
std::pair<int, int> pngSize(const std::vector<uint8_t>& png) {
  auto u32 = [&](size_t at) {
    return int(uint32_t(png[at]) << 24 | uint32_t(png[at + 1]) << 16 | uint32_t(png[at + 2]) << 8 |
               uint32_t(png[at + 3]));
  };
  return {u32(16), u32(20)};
}

TEST(MaterialTextures, TheFoxsEmbeddedBaseColourImageDecodesToAnOrangeFur) {
  const auto fox = std::filesystem::path(VISTREAM_SHARED_DIR) / "data" / "Fox.glb";
  const Scene scene = loadScene(fox);
  size_t textured = 0;
  std::vector<std::string> warnings;
  const auto textures = loadMaterialTextures(scene, warnings);
  EXPECT_TRUE(warnings.empty()) << warnings.front();
  ASSERT_EQ(textures.size(), scene.materials.size());
  for (size_t m = 0; m < scene.materials.size(); ++m) {
    const Material& material = scene.materials[m];
    if (!material.baseColorImage) continue;
    ++textured;
    // The glb holds a PNG (its signature), whose header gives the size.
    const std::vector<uint8_t>& png = *material.baseColorImage;
    ASSERT_GT(png.size(), 24u);
    ASSERT_EQ(std::string(png.begin() + 1, png.begin() + 4), "PNG");
    ASSERT_TRUE(textures[m]);
    EXPECT_EQ(std::make_pair(textures[m]->width(), textures[m]->height()), pngSize(png));
    // A red fox: its fur is more red than green, more green than blue.
    const glm::vec3 mean = textures[m]->mean();
    EXPECT_GT(mean.r, mean.g);
    EXPECT_GT(mean.g, mean.b);
  }
  EXPECT_EQ(textured, 1u);
}

TEST(MaterialTextures, AMissingTextureFileIsAWarningNamingItAndTheMaterialKeepsNone) {
  testing::TempDir dir;
  Scene scene;
  scene.sources = {dir.path() / "scene.obj"};
  scene.materials = {Material::named("plain"), Material::named("brick")};
  scene.materials[1].baseColorTexture = "brick.png";
  std::vector<std::string> warnings;
  const auto textures = loadMaterialTextures(scene, warnings);
  ASSERT_EQ(textures.size(), 2u);
  EXPECT_FALSE(textures[0]);
  EXPECT_FALSE(textures[1]);
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find("brick.png"), std::string::npos) << warnings[0];
  EXPECT_NE(warnings[0].find("brick"), std::string::npos) << warnings[0];
}

}  // namespace
}  // namespace vistream
