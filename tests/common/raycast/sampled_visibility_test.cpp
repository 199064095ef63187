#include "common/raycast/sampled_visibility.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <iterator>

#include "tests/common/support/box_scenes.h"

namespace vistream {
namespace {

using testing::addBox;
using testing::addGround;

struct World {
  Scene scene;
  FlatTriangles triangles;
  std::unique_ptr<RayQuery> rays;
  void build() {
    finalizeScene(scene);
    triangles = flattenScene(scene);
    rays = makeEmbreeRayQuery(triangles);
  }
};

TEST(SampledVisibility, SeesTheWallButNothingBehindIt) {
  World w;
  const uint32_t ground = addGround(w.scene, -50, -50, 50, 50);
  const uint32_t wall = addBox(w.scene, "wall", {-10, 0, -5}, {10, 10.3f, -4.83f});
  addBox(w.scene, "hidden", {-1, 0, -10}, {1, 2, -8});
  w.build();
  const auto vis = sampleVisibleFaces(*w.rays, w.triangles, Box3f({-1, 1, 0}, {1, 2, 2}));
  EXPECT_EQ(vis.faces, (std::vector<uint32_t>{ground, wall + testing::kPlusZ}));
  EXPECT_EQ(vis.insideSolid, 0u);
  EXPECT_EQ(vis.viewpoints, 32u);
}

TEST(SampledVisibility, SeesTheFrontOfABoxButNotItsGrazedTopOrSides) {
  World w;
  const uint32_t ground = addGround(w.scene, -50, -50, 50, 50);
  const uint32_t target = addBox(w.scene, "target", {-1, 0, -10}, {1, 2, -8});
  w.build();
  // The cell's top lies in the plane of the box's top and its x range in the
  // planes of the box's sides: those faces are only ever grazed.
  const auto vis = sampleVisibleFaces(*w.rays, w.triangles, Box3f({-1, 1, 0}, {1, 2, 2}));
  EXPECT_EQ(vis.faces, (std::vector<uint32_t>{ground, target + testing::kPlusZ}));
}

TEST(SampledVisibility, SkipsAndCountsTheViewpointsItsRuleExcludes) {
  World w;
  addGround(w.scene, -50, -50, 50, 50);
  addBox(w.scene, "block", {-5, 0, -5}, {5, 5, 5});
  w.build();
  const Box3f cell({-1, 1, 8}, {1, 2, 10});
  SampledVisibilityOptions options;
  options.points = 20;
  options.skipViewpoint = [](const glm::vec3& p) { return p.x < 0.0f; };
  size_t left = 0;
  for (const glm::vec3& p : cellViewpoints(cell, options.points, options.seed)) left += p.x < 0.0f;
  ASSERT_GT(left, 0u);
  const auto vis = sampleVisibleFaces(*w.rays, w.triangles, cell, options);
  EXPECT_EQ(vis.insideSolid, left);
  EXPECT_EQ(vis.viewpoints, 20u - left);
  options.skipViewpoint = [](const glm::vec3&) { return true; };
  const auto none = sampleVisibleFaces(*w.rays, w.triangles, cell, options);
  EXPECT_EQ(none.viewpoints, 0u);
  EXPECT_TRUE(none.faces.empty());
}

TEST(SampledVisibility, UsesTheCornersFaceCentresAndCentreOfTheCell) {
  const Box3f cell({0, 0, 0}, {2, 4, 6});
  const auto points = cellViewpoints(cell, 40, 7);
  ASSERT_EQ(points.size(), 40u);
  for (int i = 0; i < 8; ++i) {
    const glm::vec3 corner((i & 1) ? 2 : 0, (i & 2) ? 4 : 0, (i & 4) ? 6 : 0);
    EXPECT_NE(std::find(points.begin(), points.end(), corner), points.end()) << i;
  }
  EXPECT_NE(std::find(points.begin(), points.end(), glm::vec3(1, 2, 3)), points.end());
  for (const auto& p : points) EXPECT_TRUE(cell.contains(p));
}

TEST(SampledVisibility, EmbreeAndBruteForceSeeTheSameFaces) {
  World w;
  addGround(w.scene, -60, -60, 60, 60);
  for (int i = 0; i < 6; ++i)
    for (int k = 0; k < 6; ++k)
      // Offsets keep box edges off the sampled ray directions: exact edge
      // grazes are decided differently by float and double arithmetic.
      addBox(
          w.scene, "b", {i * 12.13f - 36.29f, 0, k * 11.97f - 36.41f},
          {i * 12.13f - 29.07f, 3.17f + float((i * 7 + k * 3) % 9) * 1.03f, k * 11.97f - 29.23f});
  w.build();
  const auto brute = makeBruteForceRayQuery(w.triangles);
  SampledVisibilityOptions options;
  options.points = 6;
  options.resolution = 24;
  const Box3f cell({-27.5f, 0.5f, -27.5f}, {-25.5f, 2.0f, -25.5f});
  const auto a = sampleVisibleFaces(*w.rays, w.triangles, cell, options);
  const auto b = sampleVisibleFaces(*brute, w.triangles, cell, options);
  EXPECT_EQ(a.faces, b.faces);
  EXPECT_GT(a.faces.size(), 10u);
}

// A cell of 2 x 1 x 2 m above a ground quad, and its 15 fixed viewpoints
// only (corners, face centres, centre), so which rays are cast is fixed.
const Box3f kProbeCell({-1, 1, -1}, {1, 2, 1});

SampledVisibilityOptions fixedViewpoints(int resolution) {
  SampledVisibilityOptions options;
  options.points = 15;
  options.resolution = resolution;
  return options;
}

std::vector<uint32_t> everyFace(const Scene& scene) {
  std::vector<uint32_t> faces(scene.faceCount);
  for (uint32_t f = 0; f < scene.faceCount; ++f) faces[f] = f;
  return faces;
}

TEST(SampledVisibility, ProbesFindAFaceSmallerThanAPixelThatTheCubeMapsMiss) {
  World w;
  addGround(w.scene, -100, -100, 100, 100);
  // A 4 cm cube floating in open air 50 m away: it subtends under a
  // thousandth of a radian, a cube-map pixel at 16 rays a side about 0.1.
  // Nothing stands between it and the cell, so its face towards the cell is
  // seen from every viewpoint.
  const uint32_t speck = addBox(w.scene, "speck", {29.03f, 1.51f, 40.07f}, {29.07f, 1.55f, 40.11f});
  w.build();
  SampledVisibilityOptions options = fixedViewpoints(16);
  const auto cube = sampleVisibleFaces(*w.rays, w.triangles, kProbeCell, options);
  ASSERT_FALSE(std::binary_search(cube.faces.begin(), cube.faces.end(), speck + testing::kMinusZ))
      << "the premise: no cube-map ray hits the speck";
  EXPECT_EQ(cube.probeRays, 0u);
  EXPECT_EQ(cube.probeOnly, 0u);

  options.probeFaces = {speck + testing::kMinusZ};
  const auto probed = sampleVisibleFaces(*w.rays, w.triangles, kProbeCell, options);
  EXPECT_TRUE(
      std::binary_search(probed.faces.begin(), probed.faces.end(), speck + testing::kMinusZ));
  EXPECT_EQ(probed.probeOnly, 1u);
  // Two triangles per face, probeSamples points on each, from every viewpoint.
  EXPECT_EQ(probed.probeRays, 15u * 2u * uint64_t(options.probeSamples));
}

TEST(SampledVisibility, ProbesNeverCreditAFaceHiddenBehindAWallFromEveryViewpoint) {
  World w;
  addGround(w.scene, -50, -50, 50, 50);
  const uint32_t wall = addBox(w.scene, "wall", {-10, 0, -5}, {10, 10.3f, -4.8f});
  const uint32_t hidden = addBox(w.scene, "hidden", {-1, 0.5f, -10}, {1, 2.5f, -8});
  w.build();
  SampledVisibilityOptions options;
  options.points = 32;
  options.resolution = 64;
  options.probeSamples = 64;
  options.probeFaces = everyFace(w.scene);  // the hidden faces and the wall's back included

  // The oracle, by brute force: from every viewpoint the sampler uses, each
  // vertex of the hidden box projects onto the plane of the wall's front
  // (z = -4.8) strictly inside the wall's rectangle. The box is convex and
  // lies behind that plane, so its whole projection lies inside the
  // rectangle too: the wall hides all of it.
  const glm::vec2 wallLo(-10, 0), wallHi(10, 10.3f);
  const float front = -4.8f, margin = 0.05f;
  for (const glm::vec3& p : cellViewpoints(kProbeCell, options.points, options.seed))
    for (int k = 0; k < 8; ++k) {
      const glm::vec3 v((k & 1) ? 1.0f : -1.0f, (k & 2) ? 2.5f : 0.5f, (k & 4) ? -8.0f : -10.0f);
      const float t = (front - p.z) / (v.z - p.z);
      ASSERT_GT(t, 0.0f);
      ASSERT_LT(t, 1.0f);
      const glm::vec3 x = p + (v - p) * t;
      ASSERT_GT(x.x, wallLo.x + margin);
      ASSERT_LT(x.x, wallHi.x - margin);
      ASSERT_GT(x.y, wallLo.y + margin);
      ASSERT_LT(x.y, wallHi.y - margin);
    }

  const auto probed = sampleVisibleFaces(*w.rays, w.triangles, kProbeCell, options);
  EXPECT_GT(probed.probeRays, 0u);
  for (uint32_t f = hidden; f < hidden + 6; ++f)
    EXPECT_FALSE(std::binary_search(probed.faces.begin(), probed.faces.end(), f)) << f;
  EXPECT_FALSE(
      std::binary_search(probed.faces.begin(), probed.faces.end(), wall + testing::kMinusZ));
  EXPECT_TRUE(std::binary_search(probed.faces.begin(), probed.faces.end(), wall + testing::kPlusZ));
}

TEST(SampledVisibility, ProbesOnlyAddFacesToWhatTheCubeMapsSee) {
  World w;
  addGround(w.scene, -150, -150, 150, 150);
  // Rows of boxes of many heights and a few thin posts far away: enough that
  // a coarse cube map misses some faces the probes reach.
  for (int i = 0; i < 8; ++i)
    for (int k = 0; k < 8; ++k)
      addBox(w.scene, "b", {i * 13.1f - 52.3f, 0, k * 12.7f - 50.9f},
             {i * 13.1f - 47.9f, 2.1f + float((i * 5 + k * 3) % 7) * 1.3f, k * 12.7f - 46.2f});
  for (int i = 0; i < 6; ++i)
    addBox(w.scene, "post", {i * 17.3f - 48.0f, 0, 95.0f}, {i * 17.3f - 47.9f, 3.0f, 95.1f});
  w.build();
  SampledVisibilityOptions options;
  options.points = 20;
  options.resolution = 12;
  const Box3f cell({-2.5f, 0.5f, -2.5f}, {-0.5f, 2.0f, -0.5f});
  const auto cube = sampleVisibleFaces(*w.rays, w.triangles, cell, options);
  // Probes at every other face. A probe ray credits whatever it sees first,
  // so it may add a face in front of the one it aims at, but it never takes
  // a face away.
  for (uint32_t f = 0; f < w.scene.faceCount; f += 2) options.probeFaces.push_back(f);
  const auto probed = sampleVisibleFaces(*w.rays, w.triangles, cell, options);
  EXPECT_TRUE(std::includes(probed.faces.begin(), probed.faces.end(), cube.faces.begin(),
                            cube.faces.end()));
  std::vector<uint32_t> added;
  std::set_difference(probed.faces.begin(), probed.faces.end(), cube.faces.begin(),
                      cube.faces.end(), std::back_inserter(added));
  EXPECT_EQ(probed.probeOnly, added.size());
  EXPECT_FALSE(added.empty()) << "the cube maps at 12 rays a side should miss some faces";
  // The brute-force ray query adds the same faces.
  const auto brute = makeBruteForceRayQuery(w.triangles);
  EXPECT_EQ(sampleVisibleFaces(*brute, w.triangles, cell, options).faces, probed.faces);
}

}  // namespace
}  // namespace vistream
