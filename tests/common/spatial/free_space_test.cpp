#include "common/spatial/free_space.h"

#include <gtest/gtest.h>

#include "tests/common/support/box_scenes.h"

namespace vistream {
namespace {

using testing::addBox;
using testing::addFaces;
using testing::addGround;

struct World {
  Scene scene;
  FlatTriangles triangles;
  std::unique_ptr<RayQuery> rays;
  FreeSpace build(FreeSpaceOptions options = {}) {
    finalizeScene(scene);
    triangles = flattenScene(scene);
    rays = makeEmbreeRayQuery(triangles);
    return FreeSpace::build(*rays, scene.bounds(), options);
  }
};

TEST(FreeSpace, GroundAroundABuildingIsWalkableAndItsFootprintAndRoofAreNot) {
  World w;
  addGround(w.scene, -20, -20, 20, 20);
  addBox(w.scene, "building", {-5, 0, -5}, {5, 12, 5});
  const FreeSpace fs = w.build();
  ASSERT_GT(fs.walkableCount(), 0u);
  EXPECT_TRUE(fs.floorAt({-15, -15}).has_value());
  EXPECT_FLOAT_EQ(*fs.floorAt({15, 10}), 0.0f);
  EXPECT_FALSE(fs.floorAt({0, 0}).has_value());      // on the roof, not connected to the street
  EXPECT_FALSE(fs.floorAt({-5.1f, 0}).has_value());  // within the viewer radius of the wall
  for (const auto& c : fs.walkableColumns()) {
    const glm::vec2 p = fs.columnCentre(c.x, c.y);
    EXPECT_FALSE(p.x > -5.3f && p.x < 5.3f && p.y > -5.3f && p.y < 5.3f) << p.x << "," << p.y;
  }
}

TEST(FreeSpace, TheGroundInsideABuildingWithoutABottomFaceIsNoPlaceToStand) {
  // Walls and a roof only, standing on the ground: vertical rays see the roof
  // high above the ground inside, so only the walls (invisible to them) tell
  // that the inside is closed.
  World w;
  addGround(w.scene, -20, -20, 20, 20);
  const float l = -5, h = 5, top = 12;
  addFaces(w.scene, "open_bottom_building",
           {{{l, 0, l}, {l, 0, h}, {l, top, h}, {l, top, l}},
            {{h, 0, l}, {h, top, l}, {h, top, h}, {h, 0, h}},
            {{l, 0, l}, {l, top, l}, {h, top, l}, {h, 0, l}},
            {{l, 0, h}, {h, 0, h}, {h, top, h}, {l, top, h}},
            {{l, top, l}, {l, top, h}, {h, top, h}, {h, top, l}}});
  const FreeSpace fs = w.build();
  EXPECT_TRUE(fs.floorAt({15, 10}).has_value());
  for (const auto& c : fs.walkableColumns()) {
    const glm::vec2 p = fs.columnCentre(c.x, c.y);
    EXPECT_FALSE(p.x > l && p.x < h && p.y > l && p.y < h) << "inside at " << p.x << "," << p.y;
  }
}

TEST(FreeSpace, NoOneStandsUnderATableLowerThanTheHeadroom) {
  World w;
  addGround(w.scene, -10, -10, 10, 10);
  addBox(w.scene, "table", {-1, 0.7f, -1}, {1, 0.75f, 1});
  const FreeSpace fs = w.build();
  EXPECT_FALSE(fs.floorAt({0, 0}).has_value());
  EXPECT_TRUE(fs.floorAt({5, 5}).has_value());
}

TEST(FreeSpace, TwoRoomsJoinedByADoorFormOneFreeSpaceAndWithoutItTheLargerWins) {
  for (const bool door : {true, false}) {
    World w;
    addGround(w.scene, 0, 0, 20, 10);
    addBox(w.scene, "ceiling", {0, 3, 0}, {20, 3.2f, 10});
    addBox(w.scene, "outer_s", {0, 0, -0.2f}, {20, 3, 0});
    addBox(w.scene, "outer_n", {0, 0, 10}, {20, 3, 10.2f});
    addBox(w.scene, "outer_w", {-0.2f, 0, 0}, {0, 3, 10});
    addBox(w.scene, "outer_e", {20, 0, 0}, {20.2f, 3, 10});
    // Partition at x = 8..8.2; the door is 1.2 m wide at z = 4.4..5.6.
    if (door) {
      addBox(w.scene, "part_a", {8, 0, 0}, {8.2f, 3, 4.4f});
      addBox(w.scene, "part_b", {8, 0, 5.6f}, {8.2f, 3, 10});
      addBox(w.scene, "lintel", {8, 2.1f, 4.4f}, {8.2f, 3, 5.6f});
    } else {
      addBox(w.scene, "part", {8, 0, 0}, {8.2f, 3, 10});
    }
    FreeSpaceOptions options;
    options.minCellSize = 0.1f;
    const FreeSpace fs = w.build(options);
    EXPECT_TRUE(fs.floorAt({15, 5}).has_value()) << "door " << door;
    EXPECT_EQ(fs.floorAt({4, 5}).has_value(), door) << "door " << door;
  }
}

TEST(FreeSpace, AnEmptySceneHasNoFreeSpace) {
  World w;
  const FreeSpace fs = w.build();
  EXPECT_EQ(fs.walkableCount(), 0u);
  EXPECT_FALSE(fs.floorAt({0, 0}).has_value());
}

}  // namespace
}  // namespace vistream
