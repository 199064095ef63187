#include "client/render/render_geometry.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace vistream {
namespace {

// One triangle at z = -10 in front of an eye at the origin, its grid level 1
// with corners black, red 200 and green 100.
RenderGeometry oneTriangle(float hazeScale) {
  RenderGeometry g;
  g.triangles.positions = {{0, 0, -10}, {10, 0, -10}, {0, 10, -10}};
  g.triangles.faceIds = {0};
  const glm::u8vec3 corners[3] = {{0, 0, 0}, {200, 0, 0}, {0, 100, 0}};
  g.lighting.append(1, corners, 3);
  g.haze = Haze{glm::vec3(255.0f), hazeScale};
  return g;
}

TEST(RenderGeometry, AColourAlongARayIsTheGridAtItsBarycentricsHazedByItsDistance) {
  const RenderGeometry g = oneTriangle(20.0f);
  // The point a + 0.25 (b - a) + 0.5 (c - a) = (2.5, 5, -10): red 50, green 50.
  const glm::vec3 dir(2.5f, 5.0f, -10.0f);
  const double fade = 1.0 - std::exp(-double(glm::length(dir)) / 20.0);
  const glm::u8vec3 c = g.colourAlong(0, glm::vec3(0.0f), dir * 0.37f);  // any length
  EXPECT_NEAR(c.r, 50.0 + (255.0 - 50.0) * fade, 0.51);
  EXPECT_NEAR(c.g, 50.0 + (255.0 - 50.0) * fade, 0.51);
  EXPECT_NEAR(c.b, 255.0 * fade, 0.51);
}

TEST(RenderGeometry, OneMinusExpNegIsWithinAMillionthOfTheLibrarysValue) {
  for (double x = 0.0; x < 100.0; x += 0.0137) {
    const float got = oneMinusExpNeg(float(x));
    ASSERT_NEAR(got, -std::expm1(-double(float(x))), 1e-6) << x;
  }
  EXPECT_EQ(oneMinusExpNeg(0.0f), 0.0f);
  EXPECT_EQ(oneMinusExpNeg(1e30f), 1.0f);
  EXPECT_EQ(oneMinusExpNeg(INFINITY), 1.0f);
  EXPECT_EQ(oneMinusExpNeg(NAN), 0.0f);
  EXPECT_EQ(oneMinusExpNeg(-5.0f), 0.0f);
}

// Random triangles with random grids of levels 1..8 seen from random eyes:
// the span shader gives every pixel of a row the bytes colourAlong gives it,
// on the triangle, past its edges (clamped) and seen edge-on.
TEST(RenderGeometry, ShadeSpanGivesEveryPixelTheBytesOfColourAlong) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> coord(-50.0f, 50.0f), unit(0.0f, 1.0f);
  RenderGeometry g;
  g.haze = Haze{glm::vec3(180.0f, 200.0f, 230.0f), 300.0f};
  for (int t = 0; t < 64; ++t) {
    for (int k = 0; k < 3; ++k)
      g.triangles.positions.emplace_back(coord(rng), coord(rng), coord(rng));
    g.triangles.faceIds.push_back(uint32_t(t));
    const uint32_t level = 1 + uint32_t(t % 8);
    std::vector<glm::u8vec3> colours(LightingGrid::pointsOf(level));
    for (auto& c : colours) c = glm::u8vec3(rng() % 256, rng() % 256, rng() % 256);
    g.lighting.append(level, colours.data(), colours.size());
  }
  size_t compared = 0, edgeOn = 0;
  for (size_t t = 0; t < g.size(); ++t) {
    const glm::vec3 a = g.triangles.vertex(t, 0), b = g.triangles.vertex(t, 1),
                    c = g.triangles.vertex(t, 2);
    for (int trial = 0; trial < 8; ++trial) {
      const glm::vec3 eye = trial == 0 ? a + 0.5f * (b - a) + 2.0f * (c - b)  // in the plane
                                       : glm::vec3(coord(rng), coord(rng), coord(rng));
      const EyeTriangle seen = EyeTriangle::of(g.triangles, t, eye);
      // A row of 150 directions sweeping from beyond a through the triangle
      // to beyond the far side.
      const glm::vec3 from = a - 0.2f * (c - a) - eye,
                      to = b + 0.6f * (c - b) + 0.2f * (c - a) - eye;
      const int count = 150;
      const glm::vec3 step = (to - from) / float(count - 1);
      std::vector<uint8_t> row(3 * count);
      g.shadeSpan(t, seen, from, step, count, row.data());
      for (int k = 0; k < count; ++k) {
        const glm::vec3 dir = from + float(k) * step;
        edgeOn += !(std::abs(glm::dot(dir, seen.normal)) > 0.0f);
        const glm::u8vec3 want = g.colourAlong(t, seen, dir);
        ASSERT_EQ(glm::u8vec3(row[3 * k], row[3 * k + 1], row[3 * k + 2]), want)
            << "triangle " << t << " trial " << trial << " pixel " << k;
        ++compared;
      }
    }
  }
  EXPECT_EQ(compared, 64u * 8u * 150u);
  EXPECT_GT(edgeOn, 0u);  // the eyes in a triangle's plane were compared too
}

// Rows of directions from level to steeply down, seen from above, below and
// at the assumed ground, with haze on and off: the background span gives
// every pixel the bytes background() gives it.
TEST(RenderGeometry, ShadeBackgroundGivesEveryPixelTheBytesOfBackground) {
  RenderGeometry g;
  g.sky = {140, 180, 230};
  g.ground = {118, 112, 100};
  g.groundY = 2.0f;
  size_t groundPixels = 0;
  for (const float scale : {0.0f, 800.0f})
    for (const float eyeY : {1.0f, 2.0f, 3.5f, 500.0f}) {
      g.haze = Haze{glm::vec3(190.0f, 205.0f, 225.0f), scale};
      const glm::vec3 eye(10.0f, eyeY, -4.0f);
      for (const float dy : {0.3f, 0.0f, -0.001f, -0.2f, -3.0f}) {
        const glm::vec3 first(-1.0f, dy, -1.0f), step(0.01f, -0.004f, 0.0f);
        const int count = 200;
        std::vector<uint8_t> row(3 * count);
        g.shadeBackground(eye, first, step, count, row.data());
        for (int k = 0; k < count; ++k) {
          const glm::vec3 dir = first + float(k) * step;
          const glm::u8vec3 want = g.background(eye, dir);
          groundPixels += want != g.sky;
          ASSERT_EQ(glm::u8vec3(row[3 * k], row[3 * k + 1], row[3 * k + 2]), want)
              << "eye y " << eyeY << " scale " << scale << " dir y " << dir.y;
        }
      }
    }
  EXPECT_GT(groundPixels, 1000u);  // the ground was seen, not only the sky
}

}  // namespace
}  // namespace vistream
