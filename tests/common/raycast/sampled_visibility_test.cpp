#include "common/raycast/sampled_visibility.h"

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace vistream
