#include "client/farfield/field_grid.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <random>
#include <string>

#include "common/raycast/ray_query.h"
#include "tests/common/support/triangle_soups.h"

// Oracles: brute-force ray casts through pixel centres, exact frustum and
// distance geometry on points sampled from each triangle, and a brute force over
// vertices for anythingBeyond.

namespace vistream {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

using testing::addTriangle;

// Random triangles of many sizes over a 500 m x 500 m area, up to 45 m high.
RenderGeometry randomGeometry(uint32_t seed, int n) {
  std::mt19937 rng(seed);
  auto U = [&](float a, float b) { return std::uniform_real_distribution<float>(a, b)(rng); };
  RenderGeometry g;
  for (int i = 0; i < n; ++i) {
    const glm::vec3 c(U(0, 500), U(0, 20), U(0, 500));
    const float s = i % 10 == 0 ? 40.0f : U(0.5f, 15.0f);
    std::array<glm::vec3, 3> v;
    for (auto& p : v) p = c + glm::vec3(U(-s, s), U(0, 25), U(-s, s));
    addTriangle(g.triangles, v[0], v[1], v[2]);
  }
  recolour(g, [](size_t) { return glm::vec3(0.6f); });
  return g;
}

float horizontalDistance(glm::vec3 a, glm::vec3 b) {
  return glm::length(glm::vec2(a.x - b.x, a.z - b.z));
}

// Strictly inside the view frustum (exact camera-basis geometry, 0.1% margin).
bool insideFrustum(const Camera& c, glm::vec3 p) {
  const glm::vec3 v = p - c.eye;
  const float depth = glm::dot(v, c.forward());
  const float t = std::tan(0.5f * glm::radians(c.vfovDeg));
  return depth > 1.01f * c.zNear && depth < 0.99f * c.zFar &&
         std::abs(glm::dot(v, c.right())) < 0.999f * depth * t * c.aspect() &&
         std::abs(glm::dot(v, c.up())) < 0.999f * depth * t;
}

// Horizontal distance from a point to a triangle's X/Z bounding rectangle.
float rectangleDistance(const FlatTriangles& f, size_t t, glm::vec3 eye) {
  const Box3f b = f.triangleBounds(t);
  const glm::vec2 e(eye.x, eye.z);
  const glm::vec2 q = glm::clamp(e, glm::vec2(b.lo.x, b.lo.z), glm::vec2(b.hi.x, b.hi.z));
  return glm::length(q - e);
}

std::vector<Camera> randomCameras(uint32_t seed, int n) {
  std::mt19937 rng(seed);
  auto U = [&](float a, float b) { return std::uniform_real_distribution<float>(a, b)(rng); };
  std::vector<Camera> cams;
  for (int i = 0; i < n; ++i) {
    Camera c;
    c.eye = {U(-50, 550), i % 3 == 0 ? 1.7f : U(1.7f, 60.0f), U(-50, 550)};
    c.yawDeg = U(-180, 180);
    c.pitchDeg = U(-30, 30);
    c.vfovDeg = i % 2 ? 60.0f : 90.0f;
    c.width = 64;
    c.height = 48;
    cams.push_back(c);
  }
  return cams;
}

const float kDistances[] = {0.0f, 5.0f, 30.0f, 120.0f, 1000.0f, kInf};

TEST(FieldGrid, NearFieldListsEachTriangleAtMostOnce) {
  const RenderGeometry g = randomGeometry(1, 2000);
  for (float cell : {0.0f, 8.0f, 25.0f}) {
    const FieldGrid grid(g, cell);
    std::vector<uint32_t> out, stamp;
    uint32_t stampValue = 0;
    for (const Camera& cam : randomCameras(2, 20))
      for (float d : kDistances) {
        grid.nearField(cam, d, out, stamp, stampValue);
        std::vector<uint32_t> sorted = out;
        std::sort(sorted.begin(), sorted.end());
        EXPECT_EQ(std::adjacent_find(sorted.begin(), sorted.end()), sorted.end())
            << "cell " << cell << " d " << d;
        EXPECT_TRUE(sorted.empty() || sorted.back() < g.size());
      }
  }
}

TEST(FieldGrid, NearFieldHoldsEveryTriangleAPixelRaySeesWithinD) {
  const RenderGeometry g = randomGeometry(3, 2000);
  const auto rays = makeBruteForceRayQuery(g.triangles);
  const std::vector<Camera> cameras = randomCameras(4, 16);
  std::vector<FieldGrid> grids;
  for (float cell : {0.0f, 8.0f, 25.0f}) grids.emplace_back(g, cell);
  size_t checked = 0;
  std::vector<Hit> hits;
  for (size_t ci = 0; ci < cameras.size(); ++ci) {
    const Camera& cam = cameras[ci];
    // Every triangle any pixel-centre ray hits (not only the first), with the
    // horizontal distance of the nearest such hit.
    std::vector<float> seenAt(g.size(), kInf);
    for (int y = 0; y < cam.height; ++y)
      for (int x = 0; x < cam.width; ++x) {
        const glm::vec3 dir = cam.rayDirection(float(x) + 0.5f, float(y) + 0.5f);
        rays->allHits(Ray{cam.eye, dir, cam.zNear, cam.zFar}, hits);
        for (const Hit& h : hits)
          seenAt[h.triangle] =
              std::min(seenAt[h.triangle], horizontalDistance(cam.eye + h.t * dir, cam.eye));
      }
    for (const FieldGrid& grid : grids) {
      std::vector<uint32_t> out, stamp;
      uint32_t stampValue = 0;
      for (float d : kDistances) {
        grid.nearField(cam, d, out, stamp, stampValue);
        std::vector<uint8_t> in(g.size(), 0);
        for (uint32_t t : out) in[t] = 1;
        size_t missing = 0;
        for (size_t t = 0; t < g.size(); ++t)
          if (seenAt[t] < d - 1e-3f * (1.0f + d)) {
            ++checked;
            missing += !in[t];
          }
        EXPECT_EQ(missing, 0u) << "camera " << ci << " cell " << grid.cellSize() << " d " << d;
      }
    }
  }
  EXPECT_GT(checked, 1000u);
}

TEST(FieldGrid, NearFieldHoldsEveryTriangleWithAPointInTheFrustumWithinD) {
  const RenderGeometry g = randomGeometry(5, 2000);
  std::mt19937 rng(6);
  auto U = [&]() { return std::uniform_real_distribution<float>(0, 1)(rng); };
  // Points on each triangle: corners, edge midpoints, centroid, random ones.
  std::vector<std::vector<glm::vec3>> samples(g.size());
  for (size_t t = 0; t < g.size(); ++t) {
    const glm::vec3 a = g.triangles.vertex(t, 0), b = g.triangles.vertex(t, 1),
                    c = g.triangles.vertex(t, 2);
    samples[t] = {a, b, c, 0.5f * (a + b), 0.5f * (b + c), 0.5f * (c + a), (a + b + c) / 3.0f};
    for (int k = 0; k < 16; ++k) {
      float u = U(), v = U();
      if (u + v > 1) u = 1 - u, v = 1 - v;
      samples[t].push_back(a + u * (b - a) + v * (c - a));
    }
  }
  size_t checked = 0;
  for (float cell : {0.0f, 8.0f, 25.0f}) {
    const FieldGrid grid(g, cell);
    std::vector<uint32_t> out, stamp;
    uint32_t stampValue = 0;
    for (const Camera& cam : randomCameras(7, 30))
      for (float d : kDistances) {
        grid.nearField(cam, d, out, stamp, stampValue);
        std::vector<uint8_t> in(g.size(), 0);
        for (uint32_t t : out) in[t] = 1;
        size_t missing = 0;
        for (size_t t = 0; t < g.size(); ++t) {
          const bool must = std::any_of(samples[t].begin(), samples[t].end(), [&](glm::vec3 p) {
            return horizontalDistance(p, cam.eye) < d - 1e-3f * (1.0f + d) && insideFrustum(cam, p);
          });
          checked += must;
          missing += must && !in[t];
        }
        EXPECT_EQ(missing, 0u) << "cell " << cell << " d " << d;
      }
  }
  EXPECT_GT(checked, 1000u);
}

TEST(FieldGrid, NearFieldLeavesOutTrianglesFartherThanDPlusACellDiagonal) {
  const RenderGeometry g = randomGeometry(8, 2000);
  size_t leftOut = 0;
  for (float cell : {0.0f, 8.0f, 25.0f}) {
    const FieldGrid grid(g, cell);
    const float reach = grid.cellSize() * 1.41422f;
    std::vector<uint32_t> out, stamp;
    uint32_t stampValue = 0;
    for (const Camera& cam : randomCameras(9, 20))
      for (float d : {0.0f, 5.0f, 30.0f, 120.0f}) {
        grid.nearField(cam, d, out, stamp, stampValue);
        size_t tooFar = 0;
        for (uint32_t t : out)
          tooFar += rectangleDistance(g.triangles, t, cam.eye) > (d + reach) * 1.0001f + 1e-3f;
        EXPECT_EQ(tooFar, 0u) << "cell " << grid.cellSize() << " d " << d;
        leftOut += g.size() - out.size();
      }
  }
  EXPECT_GT(leftOut, 0u);
}

// The farthest horizontal distance of any geometry: a triangle's farthest point
// from the eye is one of its corners.
float farthestVertex(const RenderGeometry& g, glm::vec3 eye) {
  float far = 0.0f;
  for (const glm::vec3& p : g.triangles.positions) far = std::max(far, horizontalDistance(p, eye));
  return far;
}

std::vector<float> distancesAround(float far) {
  return {0.0f, 0.5f * far, 0.9f * far, 0.99f * far, 1.01f * far, 1.1f * far, 2.0f * far + 10.0f};
}

TEST(FieldGrid, AnythingBeyondIsTrueWheneverSomeVertexLiesFartherThanD) {
  const RenderGeometry g = randomGeometry(10, 300);
  const FieldGrid grid(g, 0.0f);
  for (const Camera& cam : randomCameras(11, 40)) {
    const float far = farthestVertex(g, cam.eye);
    for (float d : distancesAround(far))
      if (far > d) {
        EXPECT_TRUE(grid.anythingBeyond(cam.eye, d)) << "d " << d << " farthest vertex " << far;
      }
  }
}

// The answer is conservative by at most one cell: the far corner of a cell
// holding geometry lies within cellSize * sqrt(2) of the geometry in it.
TEST(FieldGrid, AnythingBeyondIsFalseWhenEveryVertexLiesACellDiagonalWithinD) {
  const RenderGeometry g = randomGeometry(10, 300);
  const FieldGrid grid(g, 0.0f);
  const float slack = grid.cellSize() * 1.4143f;
  size_t wrong = 0, cases = 0;
  glm::vec3 example(0.0f);
  float exampleD = 0.0f, exampleFar = 0.0f;
  for (const Camera& cam : randomCameras(11, 40)) {
    const float far = farthestVertex(g, cam.eye);
    for (float d : distancesAround(far + slack))
      if (far + slack < d) {
        ++cases;
        if (grid.anythingBeyond(cam.eye, d) && wrong++ == 0) {
          example = cam.eye;
          exampleD = d;
          exampleFar = far;
        }
      }
  }
  EXPECT_GT(cases, 0u);
  EXPECT_EQ(wrong, 0u) << "of " << cases << "; e.g. eye (" << example.x << ", " << example.z
                       << "), d " << exampleD << ", farthest vertex " << exampleFar;
}

}  // namespace
}  // namespace vistream
