#include "common/light/environment_light.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <numbers>

#include "common/core/error.h"
#include "common/light/spherical_harmonics.h"
#include "tests/common/support/temp_dir.h"

namespace vistream {
namespace {

const glm::vec3 kAxes[] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};

TEST(EnvironmentLight, AConstantSkyGivesPiTimesItsRadianceOnEveryNormal) {
  const auto env = EnvironmentLight::project(
      [](const glm::vec3&) { return glm::vec3(0.5f, 1.0f, 2.0f); }, 512, "constant");
  for (const glm::vec3& n : kAxes) {
    const glm::vec3 e = env.irradiance(n);
    EXPECT_NEAR(e.r, std::numbers::pi_v<float> * 0.5f, 2e-3f);
    EXPECT_NEAR(e.g, std::numbers::pi_v<float> * 1.0f, 4e-3f);
    EXPECT_NEAR(e.b, std::numbers::pi_v<float> * 2.0f, 8e-3f);
  }
}

// A uniformly bright upper hemisphere over a black one: the exact irradiance
// is pi facing up, pi/2 sideways and 0 facing down, and order 2 reproduces
// these three exactly (the hemisphere's odd terms beyond order 1 are what it
// drops, and they vanish on these normals).
TEST(EnvironmentLight, AHalfSkyGivesPiUpHalfPiSidewaysAndNothingDown) {
  const auto env = EnvironmentLight::project(
      [](const glm::vec3& d) { return glm::vec3(d.y > 0.0f ? 1.0f : 0.0f); }, 1024, "half");
  EXPECT_NEAR(env.irradiance({0, 1, 0}).g, std::numbers::pi_v<float>, 5e-3f);
  EXPECT_NEAR(env.irradiance({1, 0, 0}).g, std::numbers::pi_v<float> / 2.0f, 5e-3f);
  EXPECT_NEAR(env.irradiance({0, 0, -1}).g, std::numbers::pi_v<float> / 2.0f, 5e-3f);
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

// Radiance 2 + Y_3^1(d) projects onto exactly those two terms: 2 sqrt(4 pi)
// on Y_0^0 (whose value is 1 / sqrt(4 pi)) and 1 on Y_3^1.
TEST(EnvironmentLight, ProjectsRadianceOntoTwentyFiveHarmonics) {
  const auto env = EnvironmentLight::project(
      [](const glm::vec3& d) {
        float y[25];
        shEvaluate(d, 5, y);
        return glm::vec3(2.0f + y[13]);
      },
      512, "two terms");
  for (int i = 0; i < 25; ++i) {
    const float want =
        i == 0 ? 2.0f * std::sqrt(4.0f * std::numbers::pi_v<float>) : (i == 13 ? 1.0f : 0.0f);
    EXPECT_NEAR(env.radiance()[size_t(i)].g, want, 2e-3f) << i;
  }
}

// An open surface transfers the clamped cosine: dotted with the radiance it
// is the irradiance. For a sky brightening upwards, exp(2 y), the 25 terms
// come closer to the exact irradiance (a quadrature) than the 9 of the
// irradiance map, and within 1% of it.
TEST(EnvironmentLight, TheOpenTransferOfANormalGivesItsIrradiance) {
  auto sky = [](const glm::vec3& d) { return glm::vec3(std::exp(2.0f * d.y)); };
  const auto env = EnvironmentLight::project(sky, 512, "exp");
  for (const glm::vec3& n : kAxes) {
    float y[25], t[25];
    shEvaluate(n, 5, y);
    for (int l = 0; l <= 4; ++l)
      for (int m = -l; m <= l; ++m)
        t[l * (l + 1) + m] = float(clampedCosineZonal(l) *
                                   std::sqrt(4.0 * std::numbers::pi_v<float> / (2 * l + 1))) *
                             y[l * (l + 1) + m];
    double exact = 0.0;
    const int rows = 400, cols = 800;
    for (int r = 0; r < rows; ++r) {
      const double theta = std::numbers::pi_v<float> * (r + 0.5) / rows;
      for (int c = 0; c < cols; ++c) {
        const double phi = 2 * std::numbers::pi_v<float> * (c + 0.5) / cols;
        const glm::vec3 d(float(std::sin(theta) * std::cos(phi)), float(std::cos(theta)),
                          float(std::sin(theta) * std::sin(phi)));
        exact += sky(d).g * std::max(0.0f, glm::dot(d, n)) * std::sin(theta) *
                 (std::numbers::pi_v<float> / rows) * (2 * std::numbers::pi_v<float> / cols);
      }
    }
    const double ours = env.transferred(t, 5).g, map = env.irradiance(n).g;
    EXPECT_NEAR(ours, exact, 0.01 * exact) << n.x << " " << n.y << " " << n.z;
    EXPECT_LE(std::abs(ours - exact), std::abs(map - exact) + 1e-3 * exact);
  }
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
