#include "common/world/free_space.h"

#include <gtest/gtest.h>

#include "common/core/error.h"
#include "common/generate/path.h"
#include "tests/common/support/box_scenes.h"
#include "tests/common/world/wound_boxes.h"

namespace vistream {
namespace {

using testing::addBox;
using testing::addFaces;
using testing::addGround;
using testing::addWoundBox;
using testing::Winding;

struct World {
  Scene scene;
  FlatTriangles triangles;
  std::unique_ptr<RayQuery> rays;
  FreeSpace build(FreeSpaceOptions options = {}) {
    finalizeScene(scene);
    triangles = flattenScene(scene);
    rays = makeEmbreeRayQuery(triangles);
    return FreeSpace::build(*rays, Solids::build(triangles), scene.bounds(), options);
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

TEST(FreeSpace, NoOneStandsOnTheUndersideOfAClosedBoxWhoseSideGrazesAColumnCentre) {
  // A shop-window box floating 0.4 m above the street, its +x side exactly
  // on a line of column centres (1 m columns from x = -20: centres at
  // n + 0.5). The vertical rays there graze the side and report the top and
  // the underside; the point 1 m above the underside lies on the side, which
  // the inside test calls outside. The underside faces into the solid, so it
  // is no floor, whichever way the closed box is wound.
  for (const Winding winding : {Winding::Outward, Winding::Inward}) {
    World w;
    addGround(w.scene, -20, -20, 20, 20);
    addWoundBox(w.scene, "shop_window", {-3.5f, 0.4f, -3.5f}, {0.5f, 2.6f, 3.5f}, winding);
    FreeSpaceOptions options;
    options.maxColumns = 1600;
    const FreeSpace fs = w.build(options);
    ASSERT_FLOAT_EQ(fs.columnCentre(20, 0).x, 0.5f);
    ASSERT_GT(fs.walkableCount(), 0u);
    for (const glm::ivec2& c : fs.walkableColumns())
      EXPECT_EQ(fs.floorHeight(c.x, c.y), 0.0f)
          << "winding " << int(winding) << " at " << fs.columnCentre(c.x, c.y).x << ","
          << fs.columnCentre(c.x, c.y).y;
  }
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

// A 10 m x 10 m room on a floor quad, walled by four 0.2 m thick, 3 m high
// boxes without bottom faces, each wound as `windings` says.
FreeSpace wallBoxRoom(const std::array<Winding, 4>& windings) {
  World w;
  addGround(w.scene, 0, 0, 10, 10);
  addWoundBox(w.scene, "wall_s", {0, 0, 0}, {10, 3, 0.2f}, windings[0], false);
  addWoundBox(w.scene, "wall_n", {0, 0, 9.8f}, {10, 3, 10}, windings[1], false);
  addWoundBox(w.scene, "wall_w", {0, 0, 0.2f}, {0.2f, 3, 9.8f}, windings[2], false);
  addWoundBox(w.scene, "wall_e", {9.8f, 0, 0.2f}, {10, 3, 9.8f}, windings[3], false);
  FreeSpaceOptions options;
  options.minCellSize = 0.1f;
  return w.build(options);
}

TEST(FreeSpace, ARoomOfWallBoxesHasTheSameFreeColumnsWoundOutwardInwardOrMixed) {
  const FreeSpace outward =
      wallBoxRoom({Winding::Outward, Winding::Outward, Winding::Outward, Winding::Outward});
  const FreeSpace inward =
      wallBoxRoom({Winding::Inward, Winding::Inward, Winding::Inward, Winding::Inward});
  const FreeSpace mixed =
      wallBoxRoom({Winding::Outward, Winding::SidesInward, Winding::Inward, Winding::SidesInward});
  // Known answer from the geometry: the floor between the walls, kept 0.3 m
  // (the viewer radius) from them, give or take one 0.1 m column.
  ASSERT_GT(outward.walkableCount(), 0u);
  for (int i = 0; i < outward.columnsX(); ++i)
    for (int k = 0; k < outward.columnsZ(); ++k) {
      const glm::vec2 c = outward.columnCentre(i, k);
      const bool clear = c.x > 0.6f && c.x < 9.4f && c.y > 0.6f && c.y < 9.4f;
      const bool blocked = c.x < 0.5f || c.x > 9.5f || c.y < 0.5f || c.y > 9.5f;
      if (clear) {
        EXPECT_TRUE(outward.walkable(i, k)) << c.x << "," << c.y;
      }
      if (blocked) {
        EXPECT_FALSE(outward.walkable(i, k)) << c.x << "," << c.y;
      }
    }
  EXPECT_FLOAT_EQ(*outward.floorAt({5, 5}), 0.0f);
  for (const FreeSpace* other : {&inward, &mixed}) {
    EXPECT_EQ(other->walkableColumns(), outward.walkableColumns());
    for (const glm::ivec2& c : outward.walkableColumns())
      EXPECT_EQ(other->floorHeight(c.x, c.y), outward.floorHeight(c.x, c.y));
  }
}

TEST(FreeSpace, AClosedInwardCubeIsASolidWithARoofLikeAnOutwardOne) {
  World inward, outward;
  addWoundBox(inward.scene, "cube", {0, 0, 0}, {10, 3, 10}, Winding::Inward);
  addWoundBox(outward.scene, "cube", {0, 0, 0}, {10, 3, 10}, Winding::Outward);
  const FreeSpace flipped = inward.build(), block = outward.build();
  for (const FreeSpace* fs : {&flipped, &block}) {
    ASSERT_TRUE(fs->floorAt({5, 5}).has_value());
    EXPECT_FLOAT_EQ(*fs->floorAt({5, 5}), 3.0f);  // the roof: the inside is solid
  }
  EXPECT_EQ(flipped.walkableColumns(), block.walkableColumns());
}

TEST(FreeSpace, AClosedCubeOnTheGroundLeavesTheSameStreetsWhicheverWayItIsWound) {
  std::vector<std::vector<glm::ivec2>> columns;
  for (const Winding w : {Winding::Outward, Winding::Inward, Winding::SidesInward}) {
    World world;
    addGround(world.scene, -20, -20, 20, 20);
    addWoundBox(world.scene, "building", {-5, 0, -5}, {5, 12, 5}, w);
    const FreeSpace fs = world.build();
    EXPECT_FLOAT_EQ(*fs.floorAt({15, 10}), 0.0f);
    EXPECT_FALSE(fs.floorAt({0, 0}).has_value()) << int(w);
    columns.push_back(fs.walkableColumns());
  }
  EXPECT_EQ(columns[1], columns[0]);
  EXPECT_EQ(columns[2], columns[0]);
}

TEST(FreeSpace, TwoCubesSharingAFaceAndTwoBoxesSharingAnEdgeAreNoPlaceToStand) {
  for (const bool sharedFace : {true, false}) {
    World w;
    addGround(w.scene, -10, -10, 10, 10);
    const std::vector<Box3f> boxes =
        sharedFace ? std::vector<Box3f>{{{-2, 0, -1}, {0, 3, 1}}, {{0, 0, -1}, {2, 3, 1}}}
                   : std::vector<Box3f>{{{-2, 0, -2}, {0, 3, 0}}, {{0, 0, 0}, {2, 3, 2}}};
    for (const Box3f& b : boxes) addBox(w.scene, "box", b.lo, b.hi);
    const FreeSpace fs = w.build();
    EXPECT_TRUE(fs.floorAt({6, 6}).has_value());
    for (const glm::ivec2& c : fs.walkableColumns()) {
      const glm::vec2 p = fs.columnCentre(c.x, c.y);
      for (const Box3f& b : boxes)
        EXPECT_FALSE(p.x > b.lo.x && p.x < b.hi.x && p.y > b.lo.z && p.y < b.hi.z)
            << (sharedFace ? "shared face: " : "shared edge: ") << p.x << "," << p.y;
    }
    if (!sharedFace) {  // the notches beside the shared edge are open to the street
      EXPECT_TRUE(fs.floorAt({-1.2f, 1.2f}).has_value());
      EXPECT_TRUE(fs.floorAt({1.2f, -1.2f}).has_value());
    }
  }
}

TEST(FreeSpace, SaysWhyThereIsNoFreeSpaceNamingTheWinding) {
  // A closed house whose roof is too steep to stand on, with one wall
  // flipped: every column's floor is its bottom face, inside the house.
  World w;
  std::vector<testing::Loop> loops = testing::boxLoops({0, 0, 0}, {10, 3, 10});
  loops.erase(loops.begin() + 4);          // no flat top: a pyramid instead
  loops[0] = testing::reversed(loops[0]);  // the -x wall wound inward
  const glm::vec3 apex(5, 23, 5);
  loops.push_back({{0, 3, 0}, {0, 3, 10}, apex});
  loops.push_back({{0, 3, 10}, {10, 3, 10}, apex});
  loops.push_back({{10, 3, 10}, {10, 3, 0}, apex});
  loops.push_back({{10, 3, 0}, {0, 3, 0}, apex});
  testing::addFaces(w.scene, "house", loops);
  const FreeSpace fs = w.build();
  EXPECT_EQ(fs.walkableCount(), 0u);
  EXPECT_EQ(fs.stats().insideSolid, fs.stats().columns);
  const std::string why = fs.emptyReason();
  EXPECT_NE(why.find("inside a solid"), std::string::npos) << why;
  EXPECT_NE(why.find("9 faces are in inconsistently wound meshes"), std::string::npos) << why;
  try {
    generatePath(w.scene, fs, PathOptions{});
    ADD_FAILURE() << "a path through no free space";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(why), std::string::npos) << e.what();
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
