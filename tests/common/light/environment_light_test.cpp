#include "common/light/environment_light.h"

#include <gtest/gtest.h>

#include <fstream>

#include "common/core/error.h"
#include "tests/common/support/temp_dir.h"

namespace vistream {
namespace {

constexpr float kPi = 3.14159265358979f;

const glm::vec3 kAxes[] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};

TEST(EnvironmentLight, AConstantSkyGivesPiTimesItsRadianceOnEveryNormal) {
  const auto env = EnvironmentLight::project(
      [](const glm::vec3&) { return glm::vec3(0.5f, 1.0f, 2.0f); }, 512, "constant");
  for (const glm::vec3& n : kAxes) {
    const glm::vec3 e = env.irradiance(n);
    EXPECT_NEAR(e.r, kPi * 0.5f, 2e-3f);
    EXPECT_NEAR(e.g, kPi * 1.0f, 4e-3f);
    EXPECT_NEAR(e.b, kPi * 2.0f, 8e-3f);
  }
}

// A uniformly bright upper hemisphere over a black one: the exact irradiance
// is pi facing up, pi/2 sideways and 0 facing down, and order 2 reproduces
// these three exactly (the hemisphere's odd terms beyond order 1 are what it
// drops, and they vanish on these normals).
TEST(EnvironmentLight, AHalfSkyGivesPiUpHalfPiSidewaysAndNothingDown) {
  const auto env = EnvironmentLight::project(
      [](const glm::vec3& d) { return glm::vec3(d.y > 0.0f ? 1.0f : 0.0f); }, 1024, "half");
  EXPECT_NEAR(env.irradiance({0, 1, 0}).g, kPi, 5e-3f);
  EXPECT_NEAR(env.irradiance({1, 0, 0}).g, kPi / 2.0f, 5e-3f);
  EXPECT_NEAR(env.irradiance({0, 0, -1}).g, kPi / 2.0f, 5e-3f);
  EXPECT_NEAR(env.irradiance({0, -1, 0}).g, 0.0f, 5e-3f);
  EXPECT_NEAR(env.horizonRadiance().g, 1.0f, 1e-5f);
}

TEST(EnvironmentLight, TheAnalyticSkyIsBrighterAboveThanBelow) {
  const auto env = EnvironmentLight::sky({0.55f, 0.7f, 0.9f});
  const glm::vec3 up = env.irradiance({0, 1, 0}), down = env.irradiance({0, -1, 0});
  EXPECT_GT(up.b, 2.0f * down.b);
  // Bluer than it is red, as the sky colour it was given.
  EXPECT_GT(up.b, up.r);
  EXPECT_EQ(env.source(), "analytic sky");
}

TEST(EnvironmentLight, TheRealBeachEnvironmentLightsUpFacingSurfacesMostAndIsFinite) {
  const auto env = EnvironmentLight::fromHdr(std::string(VISTREAM_SHARED_DIR) +
                                             "/data/spiaggia_di_mondello_1k.hdr");
  const glm::vec3 up = env.irradiance({0, 1, 0}), down = env.irradiance({0, -1, 0});
  for (int c = 0; c < 3; ++c) {
    EXPECT_TRUE(std::isfinite(up[c]));
    EXPECT_GT(up[c], 0.0f);
    EXPECT_GE(down[c], 0.0f);
  }
  EXPECT_GT(up.g, down.g);
  EXPECT_GT(env.horizonRadiance().g, 0.0f);
  EXPECT_NE(env.source().find("spiaggia"), std::string::npos);
}

TEST(EnvironmentLight, AFileThatIsNoImageIsAnInputErrorNamingIt) {
  testing::TempDir dir;
  const auto file = dir.path() / "sky.hdr";
  std::ofstream(file) << "#?RADIANCE\nnot really\n";
  try {
    EnvironmentLight::fromHdr(file);
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("sky.hdr"), std::string::npos) << e.what();
  }
  EXPECT_THROW(EnvironmentLight::fromHdr(dir.path() / "missing.hdr"), InputError);
}

}  // namespace
}  // namespace vistream
