#include "common/world/static_world.h"

#include <gtest/gtest.h>

#include "tests/common/world/wound_boxes.h"

namespace vistream {
namespace {

using testing::addBox;
using testing::addGround;
using testing::addWoundBox;
using testing::Winding;

// Buildings standing on nothing (bases at 0.5 m and 1 m), 100 m up in file
// coordinates, like a city model exported without its terrain.
Scene buildingsWithoutGround() {
  Scene s;
  s.origin = {2000.0, 100.0, -3000.0};
  addWoundBox(s, "low", {-20, 0.5f, -20}, {-5, 9, -5}, Winding::Outward);
  addWoundBox(s, "open_bottom", {5, 1, -20}, {20, 12, -5}, Winding::Outward, /*bottom=*/false);
  addWoundBox(s, "inward_sides", {-20, 1, 5}, {-5, 7, 20}, Winding::SidesInward);
  addBox(s, "far", {5, 1, 5}, {20, 15, 20});
  finalizeScene(s);
  return s;
}

TEST(StaticWorld, AssumesAGroundPlaneAtTheLowestBaseWhenObjectsStandOnNothing) {
  const Scene scene = buildingsWithoutGround();
  const StaticWorld w = buildStaticWorld(scene);
  ASSERT_TRUE(w.ground.y.has_value()) << w.ground.why;
  EXPECT_FLOAT_EQ(*w.ground.y, 0.5f);
  EXPECT_NE(w.ground.why.find("assumed"), std::string::npos) << w.ground.why;
  EXPECT_NE(w.ground.why.find("100.50"), std::string::npos) << w.ground.why;  // file height
  // The streets between the buildings are walkable on the plane; no column
  // inside a building footprint is, whatever its winding or bottom face.
  ASSERT_TRUE(w.freeSpace.floorAt({0, 0}).has_value());
  EXPECT_FLOAT_EQ(*w.freeSpace.floorAt({0, 0}), 0.5f);
  EXPECT_FLOAT_EQ(*w.freeSpace.floorAt({0, 15}), 0.5f);
  for (const glm::ivec2& c : w.freeSpace.walkableColumns()) {
    const glm::vec2 p = w.freeSpace.columnCentre(c.x, c.y);
    const bool inFootprint =
        std::abs(p.x) > 5 && std::abs(p.x) < 20 && std::abs(p.y) > 5 && std::abs(p.y) < 20;
    EXPECT_FALSE(inFootprint) << p.x << "," << p.y;
  }
}

// The static world of `scene` with `--ground TEXT`.
StaticWorld buildWithGround(const Scene& scene, const std::string& text) {
  StaticWorldOptions o;
  o.ground = *parseGroundChoice(text);
  return buildStaticWorld(scene, o);
}

TEST(StaticWorld, WithoutTheGroundPlaneOnlyRoofsRemain) {
  const StaticWorld w = buildWithGround(buildingsWithoutGround(), "none");
  EXPECT_FALSE(w.ground.y.has_value());
  EXPECT_FALSE(w.freeSpace.floorAt({0, 0}).has_value());
  for (const glm::ivec2& c : w.freeSpace.walkableColumns())
    EXPECT_GE(w.freeSpace.floorHeight(c.x, c.y), 7.0f);  // the lowest roof
}

TEST(StaticWorld, PutsAFixedGroundPlaneAtAHeightInFileCoordinates) {
  const StaticWorld w = buildWithGround(buildingsWithoutGround(), "100.25");
  ASSERT_TRUE(w.ground.y.has_value());
  EXPECT_FLOAT_EQ(*w.ground.y, 0.25f);
  EXPECT_FLOAT_EQ(*w.freeSpace.floorAt({0, 0}), 0.25f);
}

TEST(StaticWorld, KeepsTheScenesOwnGround) {
  Scene scene;
  addGround(scene, -30, -30, 30, 30, -2.0f);
  addBox(scene, "b", {-5, -2, -5}, {5, 10, 5});
  finalizeScene(scene);
  const StaticWorld w = buildStaticWorld(scene);
  EXPECT_FALSE(w.ground.y.has_value()) << w.ground.why;
  EXPECT_EQ(w.ground.bareFootprint, 0.0);
  EXPECT_FLOAT_EQ(*w.freeSpace.floorAt({20, 20}), -2.0f);
}

TEST(StaticWorld, ParsesGroundChoicesAndRejectsAnythingElse) {
  EXPECT_EQ(parseGroundChoice("auto")->mode, GroundMode::Auto);
  EXPECT_EQ(parseGroundChoice("none")->mode, GroundMode::None);
  EXPECT_EQ(parseGroundChoice("-1.5")->mode, GroundMode::Fixed);
  EXPECT_EQ(parseGroundChoice("-1.5")->fileY, -1.5);
  for (const char* bad : {"", "Auto", "1.5m", "nan", "inf", "1,5"})
    EXPECT_FALSE(parseGroundChoice(bad).has_value()) << bad;
}

TEST(StaticWorld, KeepsItsRayQueryValidWhenMoved) {
  const Scene scene = buildingsWithoutGround();
  StaticWorld moved = buildStaticWorld(scene);
  const StaticWorld w = std::move(moved);
  const Hit h = w.rays->firstHit(Ray{{-10, 50, -10}, {0, -1, 0}});
  ASSERT_TRUE(h.valid());
  EXPECT_FLOAT_EQ(50.0f - h.t, 9.0f);  // the roof of "low"
  EXPECT_EQ(w.triangles->size(), flattenScene(scene, true).size());
}

}  // namespace
}  // namespace vistream
