// Enclosures (common/world/solids.h), the parity proof of one-sided
// triangles (common/world/back_faces.h) and the sealed surface the
// visibility oracles sample (common/world/sealed_surface.h).
#include "common/world/back_faces.h"

#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <random>

#include "common/world/sealed_surface.h"
#include "tests/common/world/wound_boxes.h"

namespace vistream {
namespace {

using testing::addFaces;
using testing::addWoundBox;
using testing::boxLoops;
using testing::Loop;
using testing::Winding;

struct BackFacesBuilt : testing::SolidsScene {
  BackFaceSolids behind;
  void build() {
    SolidsScene::build();
    behind = backFaceSolids(triangles, solids, *rays);
  }
  // Triangles of face `f`.
  std::vector<uint32_t> trianglesOf(uint32_t f) const {
    std::vector<uint32_t> out;
    for (uint32_t t = 0; t < triangles.size(); ++t)
      if (triangles.faceIds[t] == f) out.push_back(t);
    return out;
  }
  bool oneSided(uint32_t face) const {
    for (uint32_t t : trianglesOf(face))
      if (behind.solidOf[t] == kNoHit) return false;
    return true;
  }
};

constexpr uint32_t kMinusX = 0, kPlusX = 1, kMinusZ = 2, kPlusZ = 3, kTop = 4, kBottom = 5;

TEST(Enclosures, ABoxOpenOnlyBelowEnclosesAboveAFloorAtItsBase) {
  BackFacesBuilt b;
  addWoundBox(b.scene, "house", {0, 2, 0}, {4, 5, 4}, Winding::Outward, /*bottom=*/false);
  b.build();
  ASSERT_EQ(b.solids.enclosureCount(), 1u);
  EXPECT_EQ(b.solids.enclosureFloor(0), 2.0f) << "the open base lies at y = 2";
  for (uint32_t t = 0; t < b.triangles.size(); ++t) EXPECT_EQ(b.solids.enclosureOf(t), 0u);
}

TEST(Enclosures, ABoxWithAMissingSideOrAHoleInItsRoofEnclosesNothing) {
  BackFacesBuilt side;
  std::vector<Loop> loops = boxLoops({0, 0, 0}, {4, 3, 4});
  loops.erase(loops.begin());  // no -x wall
  addFaces(side.scene, "shed", loops);
  side.build();
  EXPECT_EQ(side.solids.enclosureCount(), 0u);
  for (uint32_t f = 0; f < 5; ++f) EXPECT_FALSE(side.oneSided(f)) << f;

  // The roof as a frame round a square hole: the hole's edges are open above the base.
  BackFacesBuilt holed;
  loops = boxLoops({0, 0, 0}, {4, 3, 4});
  loops[4] = {{0, 3, 0}, {0, 3, 4}, {1, 3, 3}, {1, 3, 1}};
  loops.push_back({{0, 3, 4}, {4, 3, 4}, {3, 3, 3}, {1, 3, 3}});
  loops.push_back({{4, 3, 4}, {4, 3, 0}, {3, 3, 1}, {3, 3, 3}});
  loops.push_back({{4, 3, 0}, {0, 3, 0}, {1, 3, 1}, {3, 3, 1}});
  addFaces(holed.scene, "atrium", loops);
  holed.build();
  EXPECT_EQ(holed.solids.enclosureCount(), 0u);
}

// Two houses in a row: the front and back walls are split where the party
// wall meets them, and the party wall's top lies against the inside of the
// one roof. Its top side is used once, so the shell with it is no cycle;
// peeled off, the shell is sealed.
TEST(Enclosures, APartyWallHangingUnderTheRoofIsPeeledAndTheShellStaysSealed) {
  BackFacesBuilt b;
  const std::vector<Loop> loops = {
      {{0, 0, 0}, {0, 0, 4}, {0, 4, 4}, {0, 4, 0}},  // -x
      {{8, 0, 0}, {8, 4, 0}, {8, 4, 4}, {8, 0, 4}},  // +x
      {{0, 0, 0}, {0, 4, 0}, {4, 4, 0}, {4, 0, 0}},  // front, left
      {{4, 0, 0}, {4, 4, 0}, {8, 4, 0}, {8, 0, 0}},  // front, right
      {{0, 0, 4}, {4, 0, 4}, {4, 4, 4}, {0, 4, 4}},  // back, left
      {{4, 0, 4}, {8, 0, 4}, {8, 4, 4}, {4, 4, 4}},  // back, right
      {{0, 4, 0}, {0, 4, 4}, {8, 4, 4}, {8, 4, 0}},  // roof
      {{0, 0, 0}, {8, 0, 0}, {8, 0, 4}, {0, 0, 4}},  // bottom
      {{4, 0, 0}, {4, 0, 4}, {4, 4, 4}, {4, 4, 0}},  // party wall
  };
  addFaces(b.scene, "row", loops);
  b.build();
  ASSERT_EQ(b.solids.enclosureCount(), 1u);
  EXPECT_TRUE(std::isinf(b.solids.enclosureFloor(0))) << "sealed: no floor";
  for (uint32_t t = 0; t < b.triangles.size(); ++t) {
    const bool partyWall = b.triangles.faceIds[t] == 8;
    EXPECT_EQ(b.solids.enclosureOf(t) == kNoHit, partyWall) << "triangle " << t;
  }
  // The outer faces have the inside behind them; the party wall has it on both sides.
  for (uint32_t f = 0; f < 8; ++f) EXPECT_TRUE(b.oneSided(f)) << f;
  EXPECT_FALSE(b.oneSided(8));
}

TEST(BackFaces, OnAnInconsistentBoxOnlyTheFacesWoundOutwardAreOneSided) {
  BackFacesBuilt b;
  addWoundBox(b.scene, "cube", {0, 0, 0}, {3, 3, 3}, Winding::SidesInward);
  b.build();
  EXPECT_EQ(b.behind.byOrientation, 0u) << "not consistently wound: no orientation proof";
  for (uint32_t f : {kMinusX, kPlusX, kMinusZ, kPlusZ}) EXPECT_FALSE(b.oneSided(f)) << f;
  for (uint32_t f : {kTop, kBottom}) EXPECT_TRUE(b.oneSided(f)) << f;
  EXPECT_EQ(b.behind.byParity, 4u);
}

TEST(BackFaces, AnInwardBoxHasNoOneSidedFaceAndAnOutwardOneIsProvedByOrientation) {
  BackFacesBuilt inward, outward;
  addWoundBox(inward.scene, "room", {0, 0, 0}, {3, 3, 3}, Winding::Inward);
  addWoundBox(outward.scene, "cube", {0, 0, 0}, {3, 3, 3}, Winding::Outward);
  inward.build();
  outward.build();
  for (uint32_t f = 0; f < 6; ++f) {
    EXPECT_FALSE(inward.oneSided(f)) << f;
    EXPECT_TRUE(outward.oneSided(f)) << f;
  }
  EXPECT_EQ(outward.behind.byOrientation, 12u);
  EXPECT_EQ(outward.behind.byParity, 0u);
}

TEST(BackFaces, TheCoincidentFacesOfTwoBoxesSharingAFaceStayTwoSided) {
  BackFacesBuilt b;
  addWoundBox(b.scene, "left", {0, 0, 0}, {2, 2, 2}, Winding::Outward, /*bottom=*/false);
  addWoundBox(b.scene, "right", {2, 0, 0}, {4, 2, 2}, Winding::Outward, /*bottom=*/false);
  b.build();
  // left's +x and right's -x lie in x = 2, each with the other right behind it.
  EXPECT_FALSE(b.oneSided(kPlusX));
  EXPECT_FALSE(b.oneSided(5 + kMinusX));
  for (uint32_t f : {kMinusX, kMinusZ, kPlusZ, kTop}) EXPECT_TRUE(b.oneSided(f)) << f;
  for (uint32_t f : {kPlusX, kMinusZ, kPlusZ, kTop}) EXPECT_TRUE(b.oneSided(5 + f)) << 5 + f;
}

TEST(BackFaces, FarFromTheOriginABoxOpenBelowIsStillProvedByParity) {
  for (const float offset : {0.0f, 1e5f}) {
    SCOPED_TRACE(offset);
    BackFacesBuilt b;
    const glm::vec3 o(offset, 0.0f, -offset);
    addWoundBox(b.scene, "house", o, o + glm::vec3(10, 6, 8), Winding::Outward, false);
    b.build();
    for (uint32_t f = 0; f < 5; ++f) EXPECT_TRUE(b.oneSided(f)) << f;
    ASSERT_NE(b.behind.solidOf[0], kNoHit);
    EXPECT_EQ(b.behind.floor[b.behind.solidOf[0]], 0.0f) << "viewpoints must be above the base";
  }
}

// Half the bottom is there: it faces down with the inside above it, and
// only its back lies above the open base.
TEST(BackFaces, TheBottomHalfOfABoxOpenOnlyBelowIsOneSided) {
  BackFacesBuilt b;
  std::vector<Loop> loops = boxLoops({0, 0, 0}, {4, 3, 4});
  loops[kBottom] = {{0, 0, 0}, {2, 0, 0}, {2, 0, 4}, {0, 0, 4}};
  addFaces(b.scene, "house", loops);
  b.build();
  ASSERT_EQ(b.solids.enclosureCount(), 1u);
  EXPECT_EQ(b.solids.enclosureFloor(0), 0.0f);
  for (uint32_t f = 0; f < 6; ++f) EXPECT_TRUE(b.oneSided(f)) << f;
}

// The roof is two quads whose shared corners lie on the long top sides of
// the front and back walls: in floats a crack runs along those sides.
BackFacesBuilt tJunctionBox() {
  BackFacesBuilt b;
  std::vector<Loop> loops = boxLoops({-3, 0, -15}, {3, 5, -9});
  loops[4] = {{-3, 5, -15}, {-3, 5, -9}, {0, 5, -9}, {0, 5, -15}};
  loops.push_back({{0, 5, -15}, {0, 5, -9}, {3, 5, -9}, {3, 5, -15}});
  addFaces(b.scene, "box", loops);
  b.build();
  return b;
}

// Sides by their exact end positions, either direction, with use counts.
std::map<std::pair<std::array<float, 3>, std::array<float, 3>>, int> sideUses(
    const FlatTriangles& t) {
  std::map<std::pair<std::array<float, 3>, std::array<float, 3>>, int> uses;
  for (size_t i = 0; i < t.size(); ++i)
    for (int k = 0; k < 3; ++k) {
      const glm::vec3 a = t.vertex(i, k), b = t.vertex(i, (k + 1) % 3);
      std::array<float, 3> pa{a.x, a.y, a.z}, pb{b.x, b.y, b.z};
      if (pb < pa) std::swap(pa, pb);
      ++uses[{pa, pb}];
    }
  return uses;
}

TEST(SealedSurface, CutsTheSidesAtTJunctionsSoEverySideIsSharedAndKeepsTheArea) {
  const BackFacesBuilt b = tJunctionBox();
  int open = 0;
  for (const auto& [side, n] : sideUses(b.triangles)) open += n == 1;
  EXPECT_GT(open, 0) << "the raw box has sides used once (the T-junctions)";

  std::vector<uint32_t> originalOf;
  const FlatTriangles sealed = weldedSurface(b.triangles, 0.01, originalOf);
  for (const auto& [side, n] : sideUses(sealed)) EXPECT_EQ(n, 2);
  ASSERT_EQ(originalOf.size(), sealed.size());
  std::vector<double> area(b.triangles.size(), 0.0);
  auto areaOf = [](const FlatTriangles& t, size_t i) {
    return 0.5 * glm::length(glm::cross(glm::dvec3(t.vertex(i, 1) - t.vertex(i, 0)),
                                        glm::dvec3(t.vertex(i, 2) - t.vertex(i, 0))));
  };
  for (size_t i = 0; i < sealed.size(); ++i) {
    EXPECT_EQ(sealed.faceIds[i], b.triangles.faceIds[originalOf[i]]);
    area[originalOf[i]] += areaOf(sealed, i);
  }
  for (size_t i = 0; i < b.triangles.size(); ++i)
    EXPECT_NEAR(area[i], areaOf(b.triangles, i), 1e-5) << "triangle " << i;
}

TEST(SealedSurface, HitsNameTheOriginalTriangleAtTheSamePointAsTheRawSurface) {
  const BackFacesBuilt b = tJunctionBox();
  const std::unique_ptr<RayQuery> sealed = makeSealedRayQuery(b.triangles, 0.01);
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  int compared = 0;
  for (int i = 0; i < 500; ++i) {
    const glm::vec3 org(u(rng) * 8.0f, 2.5f + u(rng) * 6.0f, -12.0f + u(rng) * 8.0f);
    // Towards the box's centre, give or take a metre.
    const glm::vec3 dir =
        glm::normalize(glm::vec3(0.0f, 2.5f, -12.0f) - org + glm::vec3(u(rng), u(rng), u(rng)));
    const Ray ray{org, dir, 0.0f, 100.0f};
    const Hit raw = b.rays->firstHit(ray), s = sealed->firstHit(ray);
    ASSERT_EQ(raw.valid(), s.valid());
    if (!raw.valid()) continue;
    ++compared;
    EXPECT_NEAR(raw.t, s.t, 1e-4f);
    // The barycentrics of the sealed hit rebuild its point on the original triangle.
    const uint32_t t = s.triangle;
    const glm::vec3 p = b.triangles.vertex(t, 0) +
                        (b.triangles.vertex(t, 1) - b.triangles.vertex(t, 0)) * s.u +
                        (b.triangles.vertex(t, 2) - b.triangles.vertex(t, 0)) * s.v;
    EXPECT_LT(glm::distance(p, org + dir * s.t), 1e-3f);
    EXPECT_EQ(b.triangles.faceIds[raw.triangle], b.triangles.faceIds[t]);
  }
  EXPECT_GT(compared, 100);
}

}  // namespace
}  // namespace vistream
