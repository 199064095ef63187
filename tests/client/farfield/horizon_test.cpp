#include "client/farfield/horizon.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <random>
#include <sstream>
#include <string>

#include "common/raycast/ray_query.h"
#include "tests/common/support/box_scenes.h"

// Oracle: a brute-force ray through every pixel centre the tracer calls sky,
// cast against the far field only (the triangles lying entirely farther than
// the near distance from the eye, horizontally, by exact 2D geometry): it must
// hit nothing.

namespace vistream {
namespace {

using testing::addBox;
using testing::addGround;

// A ground of 40 m tiles over [x0, x0 + size] x [0, size] at y = 0.
void addTiledGround(Scene& scene, float x0, float size) {
  for (float z = 0; z < size; z += 40.0f)
    for (float x = x0; x < x0 + size; x += 40.0f) addGround(scene, x, z, x + 40.0f, z + 40.0f);
}

// Buildings 5-80 m high with 8-40 m footprints over a 1 km square starting at x0.
RenderGeometry city(uint32_t seed, float x0) {
  std::mt19937 rng(seed);
  auto U = [&](float a, float b) { return std::uniform_real_distribution<float>(a, b)(rng); };
  Scene scene;
  addTiledGround(scene, x0, 1000.0f);
  for (int i = 0; i < 120; ++i) {
    const glm::vec3 lo(x0 + U(0, 960), 0.0f, U(0, 960));
    addBox(scene, "building", lo, lo + glm::vec3(U(8, 40), U(5, 80), U(8, 40)));
  }
  finalizeScene(scene);
  return renderGeometryFromScene(scene);
}

// Exact horizontal (X/Z) distance from the eye to a triangle.
double horizontalDistance(const FlatTriangles& f, size_t t, glm::vec3 eye) {
  const glm::dvec2 p(eye.x, eye.z);
  std::array<glm::dvec2, 3> v;
  for (int k = 0; k < 3; ++k) v[size_t(k)] = {f.vertex(t, k).x, f.vertex(t, k).z};
  auto cross = [](glm::dvec2 a, glm::dvec2 b, glm::dvec2 q) {
    return (b.x - a.x) * (q.y - a.y) - (b.y - a.y) * (q.x - a.x);
  };
  const double c0 = cross(v[0], v[1], p), c1 = cross(v[1], v[2], p), c2 = cross(v[2], v[0], p);
  if (cross(v[0], v[1], v[2]) != 0.0 &&
      ((c0 >= 0 && c1 >= 0 && c2 >= 0) || (c0 <= 0 && c1 <= 0 && c2 <= 0)))
    return 0.0;
  double best = std::numeric_limits<double>::infinity();
  for (size_t k = 0; k < 3; ++k) {
    const glm::dvec2 a = v[k], b = v[(k + 1) % 3], e = b - a;
    const double len2 = glm::dot(e, e);
    const double s = len2 > 0 ? std::clamp(glm::dot(p - a, e) / len2, 0.0, 1.0) : 0.0;
    best = std::min(best, glm::length(a + s * e - p));
  }
  return best;
}

// The triangles lying entirely farther than nearDistance from the eye horizontally.
FlatTriangles farField(const FlatTriangles& all, glm::vec3 eye, float nearDistance) {
  FlatTriangles far;
  for (size_t t = 0; t < all.size(); ++t) {
    if (!(horizontalDistance(all, t, eye) > double(nearDistance))) continue;
    far.positions.insert(far.positions.end(),
                         {all.vertex(t, 0), all.vertex(t, 1), all.vertex(t, 2)});
    far.faceIds.push_back(all.faceIds[t]);
    far.objectIds.push_back(all.objectIds[t]);
    far.degenerate.push_back(all.degenerate[t]);
  }
  return far;
}

std::vector<Camera> randomCameras(uint32_t seed, int n, float x0) {
  std::mt19937 rng(seed);
  auto U = [&](float a, float b) { return std::uniform_real_distribution<float>(a, b)(rng); };
  std::vector<Camera> cams;
  for (int i = 0; i < n; ++i) {
    Camera c;
    c.eye = {x0 + U(0, 1000), i % 2 == 0 ? 1.7f : U(10.0f, 150.0f), U(0, 1000)};
    c.yawDeg = U(-180, 180);
    c.pitchDeg = U(-20, 20);
    c.width = 80;
    c.height = 48;
    cams.push_back(c);
  }
  return cams;
}

struct Tally {
  size_t sky = 0, violations = 0;
  std::ostringstream examples;
};

// For every camera, near distance, cell size and subsampling: no pixel called
// sky sees far-field geometry.
void checkConservative(const RenderGeometry& g, const std::vector<Camera>& cameras, Tally& tally) {
  const float cellSizes[] = {2.0f, 8.0f, 32.0f};
  std::vector<HorizonMap> maps;
  for (float cell : cellSizes) maps.emplace_back(g, cell);
  for (size_t ci = 0; ci < cameras.size(); ++ci) {
    const Camera& cam = cameras[ci];
    for (float nearDistance : {50.0f, 0.0f}) {
      const FlatTriangles far = farField(g.triangles, cam.eye, nearDistance);
      const auto rays = makeBruteForceRayQuery(far);
      struct Config {
        float cell;
        int subsample;
        std::vector<float> slopes;
      };
      std::vector<Config> configs;
      for (size_t m = 0; m < maps.size(); ++m)
        for (int k : {1, 4})
          configs.push_back({cellSizes[m], k, maps[m].trace(cam, nearDistance, k)});
      for (int y = 0; y < cam.height; ++y)
        for (int x = 0; x < cam.width; ++x) {
          const glm::vec3 dir = cam.rayDirection(float(x) + 0.5f, float(y) + 0.5f);
          const float slope = HorizonMap::raySlope(dir);
          int hit = -1;  // cast lazily, once per pixel
          for (const Config& c : configs) {
            if (!(slope > c.slopes[size_t(x)])) continue;
            ++tally.sky;
            if (hit < 0)
              hit = rays->occluded(Ray{cam.eye, dir, 0.0f, std::numeric_limits<float>::infinity()})
                        ? 1
                        : 0;
            if (hit == 1 && tally.violations++ < 5)
              tally.examples << "\n  camera " << ci << " eye (" << cam.eye.x << ", " << cam.eye.y
                             << ", " << cam.eye.z << ") yaw " << cam.yawDeg << " pitch "
                             << cam.pitchDeg << ", near " << nearDistance << ", cell " << c.cell
                             << ", subsample " << c.subsample << ", pixel (" << x << ", " << y
                             << "): ray slope " << slope << " > column slope "
                             << c.slopes[size_t(x)];
          }
        }
    }
  }
}

TEST(HorizonMap, NoPixelCalledSkySeesFarFieldGeometryInACity) {
  const RenderGeometry g = city(1, 0.0f);
  Tally tally;
  checkConservative(g, randomCameras(2, 10, 0.0f), tally);
  EXPECT_EQ(tally.violations, 0u) << tally.examples.str();
  EXPECT_GT(tally.sky, 10000u) << "the tracer should call a good part of the pixels sky";
}

TEST(HorizonMap, NoPixelCalledSkySeesFarFieldGeometryFarFromTheOrigin) {
  const RenderGeometry g = city(3, 1.0e5f);
  Tally tally;
  checkConservative(g, randomCameras(4, 4, 1.0e5f), tally);
  EXPECT_EQ(tally.violations, 0u) << tally.examples.str();
  EXPECT_GT(tally.sky, 4000u);
}

TEST(HorizonMap, CallsEveryClimbingPixelSkyOverFlatGround) {
  Scene scene;
  addTiledGround(scene, -500.0f, 1000.0f);
  for (Object& o : scene.objects)
    for (glm::vec3& p : o.mesh.positions) p.z -= 500.0f;  // centre the ground on the origin
  finalizeScene(scene);
  const RenderGeometry g = renderGeometryFromScene(scene);
  for (float cell : {2.0f, 8.0f, 32.0f}) {
    const HorizonMap map(g, cell);
    for (float yaw : {0.0f, 33.0f, -120.0f})
      for (float nearDistance : {50.0f, 0.0f})
        for (int k : {1, 4}) {
          Camera cam;
          cam.eye = {3.0f, 1.7f, -7.0f};
          cam.yawDeg = yaw;
          cam.width = 80;
          cam.height = 48;
          const std::vector<float> slopes = map.trace(cam, nearDistance, k);
          size_t climbing = 0, sky = 0;
          for (int y = 0; y < cam.height; ++y)
            for (int x = 0; x < cam.width; ++x) {
              const float slope =
                  HorizonMap::raySlope(cam.rayDirection(float(x) + 0.5f, float(y) + 0.5f));
              if (slope <= 0.0f)
                continue;  // the ground lies below the eye: a climbing ray never meets it
              ++climbing;
              sky += slope > slopes[size_t(x)];
            }
          EXPECT_EQ(climbing, size_t(cam.width * cam.height / 2));
          EXPECT_EQ(sky, climbing) << "cell " << cell << " yaw " << yaw << " near " << nearDistance
                                   << " subsample " << k;
        }
  }
}

}  // namespace
}  // namespace vistream
