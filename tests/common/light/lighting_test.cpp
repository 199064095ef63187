#include "common/light/lighting.h"

#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <random>

#include "tests/common/support/box_scenes.h"

namespace vistream {
namespace {

using testing::addFaces;

// A 100 m square floor (facing up) with walls of height `h` along x = 0 and
// z = 0, both running 100 m either way: the floor's corner at the origin is
// an inside corner.
Scene insideCorner(float h) {
  Scene s;
  s.materials = {Material::diffuseColour("white", glm::vec3(1.0f))};
  addFaces(s, "floor", {{{0, 0, 0}, {0, 0, 100}, {100, 0, 100}, {100, 0, 0}}});
  addFaces(s, "walls",
           {{{0, 0, -100}, {0, 0, 100}, {0, h, 100}, {0, h, -100}},
            {{-100, 0, 0}, {-100, h, 0}, {100, h, 0}, {100, 0, 0}}});
  finalizeScene(s);
  return s;
}

// Sky light alone, the same from every direction: E(n) = pi everywhere.
EnvironmentLight uniformSky() {
  return EnvironmentLight::project([](const glm::vec3&) { return glm::vec3(1.0f); }, 128,
                                   "uniform");
}

TEST(AmbientOcclusion, MatchesTheSolidAnglesOfAnInsideCorner) {
  const Scene scene = insideCorner(100.0f);
  const FlatTriangles tris = flattenScene(scene, true);
  const auto rays = makeEmbreeRayQuery(tris);
  const glm::vec3 up(0, 1, 0);
  // Cosine-weighted, the hemisphere's azimuth quadrants are equal shares:
  // two walls meeting at the point leave one quadrant open, one wall two.
  EXPECT_NEAR(ambientOcclusion(*rays, {0.01f, 0, 0.01f}, up, 4096, 20.0f, 1), 0.25, 0.01);
  EXPECT_NEAR(ambientOcclusion(*rays, {50.0f, 0, 0.01f}, up, 4096, 20.0f, 2), 0.5, 0.01);
  // Beyond the rays' reach of both walls, nothing blocks.
  EXPECT_EQ(ambientOcclusion(*rays, {50.0f, 0, 50.0f}, up, 256, 20.0f, 3), 1.0);
  // No rays: no occlusion.
  EXPECT_EQ(ambientOcclusion(*rays, {0.01f, 0, 0.01f}, up, 0, 20.0f, 4), 1.0);
}

// The colour the bake gives an open, white, up-facing point in a uniform sky
// with `ao` of it visible and `sun` of the sun's light.
int expectedByte(double light) {
  return int(encodeColour(glm::vec3(float(light))).g);
}

glm::vec3 bakedColourAt(const LightingGrid& grid, const FlatTriangles& tris, glm::vec3 p) {
  // The floor's triangle holding p, and p's barycentrics in it.
  for (size_t t = 0; t < tris.size(); ++t) {
    const glm::vec3 a = tris.vertex(t, 0), b = tris.vertex(t, 1), c = tris.vertex(t, 2);
    if (a.y != 0.0f || b.y != 0.0f || c.y != 0.0f) continue;
    const glm::vec2 e1(b.x - a.x, b.z - a.z), e2(c.x - a.x, c.z - a.z), d(p.x - a.x, p.z - a.z);
    const float det = e1.x * e2.y - e1.y * e2.x;
    const float u = (d.x * e2.y - d.y * e2.x) / det, v = (e1.x * d.y - e1.y * d.x) / det;
    if (u >= -1e-6f && v >= -1e-6f && u + v <= 1.0f + 1e-6f) return grid.colourAt(t, u, v);
  }
  ADD_FAILURE() << "no floor triangle holds the point";
  return glm::vec3(-1.0f);
}

// The inside corner with 10 m walls, ready to bake in a uniform sky.
struct CornerBake {
  Scene scene = insideCorner(10.0f);
  FlatTriangles tris = flattenScene(scene, true);
  std::unique_ptr<RayQuery> rays = makeEmbreeRayQuery(tris);

  LightingGrid bake(const LightingOptions& o, LightingStats* stats = nullptr) const {
    return bakeLighting(scene, tris, *rays, uniformSky(), o, stats);
  }
};

TEST(BakeLighting, TheFloorsInsideCornerGetsAQuarterOfTheSkyAndAShadow) {
  const CornerBake corner;
  const FlatTriangles& tris = corner.tris;
  LightingOptions o;
  o.spacing = 4.0f;
  o.maxLevel = 16;
  o.tolerance = 0.0f;  // keep every point
  o.colourStep = 1;    // exact bytes
  o.aoRays = 1024;
  o.ambient = 0.7f;
  o.sunIntensity = 0.2f;
  o.sunDirection = glm::normalize(glm::vec3(-1, 1, 0));  // low over the x = 0 wall
  LightingStats stats;
  const LightingGrid grid = corner.bake(o, &stats);
  ASSERT_EQ(grid.size(), tris.size());
  EXPECT_EQ(stats.aoRays, stats.points * 1024);
  const double sunCos = 1.0 / std::sqrt(2.0);
  // The corner: a quarter of the sky, and the 10 m wall shades it from the sun.
  EXPECT_NEAR(bakedColourAt(grid, tris, {0, 0, 0}).g, expectedByte(0.7 * 0.25), 3.0);
  // At the foot of the z = 0 wall, far from the other: half the sky, and the
  // sun passes over the x = 0 wall 50 m away.
  EXPECT_NEAR(bakedColourAt(grid, tris, {50, 0, 0}).g, expectedByte(0.7 * 0.5 + 0.2 * sunCos), 3.0);
  // Out in the open: the whole sky and the sun, exactly.
  EXPECT_EQ(bakedColourAt(grid, tris, {100, 0, 100}).g, expectedByte(0.7 + 0.2 * sunCos));
  // Large faces are subdivided: the 141 m floor diagonal at 4 m spacing hits the cap.
  EXPECT_EQ(grid.level[0], o.maxLevel);
}

TEST(BakeLighting, NoAmbientOcclusionRaysMeansAnOpenSkyEverywhere) {
  const CornerBake corner;
  LightingOptions o;
  o.aoRays = 0;
  o.sunIntensity = 0.0f;
  o.colourStep = 1;
  LightingStats stats;
  const LightingGrid grid = corner.bake(o, &stats);
  EXPECT_EQ(bakedColourAt(grid, corner.tris, {0, 0, 0}).g, expectedByte(o.ambient));
  EXPECT_EQ(stats.meanAo, 1.0);
  EXPECT_EQ(stats.shadowRays, 0u);
}

TEST(BakeLighting, IsTheSameOnOneThreadAsOnMany) {
  const CornerBake corner;
  const LightingGrid a = corner.bake({});
  LightingGrid b;
  tbb::task_arena(1).execute([&] { b = corner.bake({}); });
  EXPECT_EQ(a.colours, b.colours);
}

TEST(BakeLighting, PosterizesToTheColourStepAndSimplifiesWithinTheTolerance) {
  const CornerBake corner;
  LightingOptions exact;
  exact.colourStep = 1;
  exact.tolerance = 0.0f;
  LightingStats full;
  const LightingGrid reference = corner.bake(exact, &full);
  LightingOptions o;  // the defaults: step 4, tolerance 4
  LightingStats kept;
  const LightingGrid g = corner.bake(o, &kept);
  for (const glm::u8vec3& c : g.colours)
    for (int a = 0; a < 3; ++a) EXPECT_TRUE(c[a] % 4 == 0 || c[a] == 255) << int(c[a]);
  EXPECT_EQ(kept.fullPoints, full.points);
  // Everywhere on every triangle, the coarse grid stays within tolerance plus
  // posterizing (2 levels) of the exact bake.
  for (size_t t = 0; t < corner.tris.size(); ++t)
    for (float u : {0.0f, 0.1f, 0.33f, 0.5f, 0.9f})
      for (float v : {0.0f, 0.05f, 0.25f, 0.5f}) {
        if (u + v > 1.0f) continue;
        const glm::vec3 d = glm::abs(g.colourAt(t, u, v) - reference.colourAt(t, u, v));
        EXPECT_LE(std::max({d.r, d.g, d.b}), o.tolerance + 2.0f + 0.01f)
            << t << " " << u << " " << v;
      }
  // Without occlusion or sun a uniform sky lights every point alike: each
  // triangle keeps the coarsest grid, its three corners.
  LightingOptions flat;
  flat.aoRays = 0;
  flat.sunIntensity = 0.0f;
  LightingStats plain;
  corner.bake(flat, &plain);
  EXPECT_GT(plain.fullPoints, 3 * corner.tris.size());
  EXPECT_EQ(plain.points, 3 * corner.tris.size());
}

// Interpolation inside the grid reproduces any colour linear in (u, v)
// exactly, on every level: an oracle independent of how cells are found.
TEST(LightingGrid, ColourAtReproducesALinearFunctionOnEveryLevel) {
  auto f = [](float u, float v) {
    return glm::vec3(10 + 200 * u, 20 + 150 * v, 30 + 100 * u + 100 * v);
  };
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  for (uint32_t n : {1u, 2u, 3u, 7u, 16u}) {
    LightingGrid g;
    std::vector<glm::u8vec3> points(LightingGrid::pointsOf(n));
    std::vector<glm::vec3> exact(points.size());
    for (uint32_t j = 0; j <= n; ++j)
      for (uint32_t i = 0; i + j <= n; ++i) {
        // Integer values on the points, so the bytes hold them exactly.
        const glm::vec3 c = glm::round(f(float(i) / n, float(j) / n));
        points[LightingGrid::pointIndex(n, i, j)] = glm::u8vec3(c);
      }
    g.append(n, points.data(), points.size());
    for (uint32_t j = 0; j <= n; ++j)
      for (uint32_t i = 0; i + j <= n; ++i) {
        const glm::vec3 got = g.colourAt(0, float(i) / n, float(j) / n);
        EXPECT_EQ(glm::u8vec3(glm::round(got)), points[LightingGrid::pointIndex(n, i, j)]);
      }
    // Between points, within the rounding of the points' values (0.5).
    for (int k = 0; k < 200; ++k) {
      float u = unit(rng), v = unit(rng);
      if (u + v > 1.0f) u = 1.0f - u, v = 1.0f - v;
      const glm::vec3 got = g.colourAt(0, u, v), want = f(u, v);
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(got[c], want[c], 0.51f) << n << " " << u << " " << v;
    }
    // Edges and corners, and barycentrics rounded just outside.
    EXPECT_NEAR(g.colourAt(0, 1.0f, 0.0f).r, 210.0f, 0.51f);
    EXPECT_NEAR(g.colourAt(0, 0.0f, 1.0f).g, 170.0f, 0.51f);
    EXPECT_NEAR(g.colourAt(0, 0.5f, 0.5f).b, 130.0f, 0.51f);
    EXPECT_NEAR(g.colourAt(0, 1.0001f, -0.0001f).r, 210.0f, 0.51f);
    EXPECT_NEAR(g.colourAt(0, 0.6f, 0.4001f).b, 130.0f, 0.51f);
  }
}

TEST(Haze, FadesTowardsItsColourWithDistanceAndIsOffAtScaleZero) {
  const Haze h{glm::vec3(200.0f), 100.0f};
  EXPECT_EQ(h.apply(glm::vec3(100.0f), 0.0f), glm::vec3(100.0f));
  EXPECT_NEAR(h.apply(glm::vec3(100.0f), 100.0f).r, 200.0f - 100.0f * std::exp(-1.0f), 1e-3f);
  EXPECT_NEAR(h.apply(glm::vec3(100.0f), 1e6f).r, 200.0f, 1e-3f);
  EXPECT_EQ(Haze{}.apply(glm::vec3(100.0f), 1e6f), glm::vec3(100.0f));
}

}  // namespace
}  // namespace vistream
