#include "common/world/solids.h"

#include <gtest/gtest.h>

#include <random>

#include "common/scene/scene_loader.h"
#include "tests/common/world/wound_boxes.h"

namespace vistream {
namespace {

using testing::addWoundBox;
using testing::Winding;

struct Built {
  Scene scene;
  FlatTriangles triangles;
  std::unique_ptr<RayQuery> rays;
  Solids solids;
  void build() {
    finalizeScene(scene);
    triangles = flattenScene(scene);
    rays = makeEmbreeRayQuery(triangles);
    solids = Solids::build(triangles);
  }
  size_t count(SolidClass c) const { return solids.census().components[size_t(c)]; }
  bool inside(glm::vec3 p) const { return solids.inside(*rays, p); }
  bool insideClosed(glm::vec3 p) const { return solids.insideClosed(*rays, p); }
};

TEST(Solids, AClosedCubeIsOutwardOrInwardBySignedVolume) {
  for (const Winding w : {Winding::Outward, Winding::Inward}) {
    Built b;
    addWoundBox(b.scene, "cube", {0, 0, 0}, {2, 3, 4}, w);
    b.build();
    ASSERT_EQ(b.solids.components().size(), 1u);
    const SolidComponent& c = b.solids.components()[0];
    EXPECT_EQ(c.kind, w == Winding::Outward ? SolidClass::ClosedOutward : SolidClass::ClosedInward);
    EXPECT_NEAR(std::abs(c.signedVolume), 24.0, 1e-4);  // 2 x 3 x 4
    EXPECT_EQ(c.faces, 6u);
    EXPECT_EQ(c.triangles, 12u);
  }
}

TEST(Solids, ABoxWithoutItsBottomIsOpenAndOneFlippedFaceMakesACubeInconsistent) {
  Built open;
  addWoundBox(open.scene, "wall", {0, 0, 0}, {4, 3, 0.2f}, Winding::Outward, /*bottom=*/false);
  open.build();
  EXPECT_EQ(open.count(SolidClass::Open), 1u);

  Built mixed;
  addWoundBox(mixed.scene, "cube", {0, 0, 0}, {2, 2, 2}, Winding::SidesInward);
  mixed.build();
  EXPECT_EQ(mixed.count(SolidClass::Inconsistent), 1u);
  EXPECT_EQ(mixed.solids.census().faces[size_t(SolidClass::Inconsistent)], 6u);
}

TEST(Solids, PointsInsideClosedOutwardOpenAndInconsistentMeshesAreInsideWhateverTheWinding) {
  for (const Winding w : {Winding::Outward, Winding::SidesInward}) {
    for (const bool bottom : {true, false}) {
      Built b;
      addWoundBox(b.scene, "block", {0, 0, 0}, {10, 6, 10}, w, bottom);
      b.build();
      EXPECT_TRUE(b.inside({5, 1, 5})) << int(w) << bottom;
      EXPECT_TRUE(b.inside({0.3f, 1, 9.6f})) << int(w) << bottom;  // near a corner
      EXPECT_FALSE(b.inside({-1, 1, 5})) << int(w) << bottom;
      EXPECT_FALSE(b.inside({5, 7, 5})) << int(w) << bottom;
      EXPECT_FALSE(b.inside({5, 6, 5})) << "on the roof counts as outside";
    }
  }
}

TEST(Solids, AClosedInwardCubeIsTheSameSolidAsAnOutwardOne) {
  Built b;
  addWoundBox(b.scene, "cube", {0, 0, 0}, {10, 3, 10}, Winding::Inward);
  b.build();
  EXPECT_EQ(b.count(SolidClass::ClosedInward), 1u);
  EXPECT_TRUE(b.inside({5, 1, 5}));
  EXPECT_TRUE(b.inside({9.9f, 2.9f, 0.1f}));
  EXPECT_FALSE(b.inside({-5, 1, 5}));
  EXPECT_FALSE(b.inside({5, 3.5f, 5}));
}

TEST(Solids, TwoCubesSharingAFaceAreBothSolidAndTheirSharedEdgesNonManifold) {
  Built b;
  testing::addBox(b.scene, "a", {-2, 0, -1}, {0, 3, 1});
  testing::addBox(b.scene, "b", {0, 0, -1}, {2, 3, 1});
  b.build();
  EXPECT_GT(b.count(SolidClass::NonManifold), 0u);
  EXPECT_EQ(b.count(SolidClass::ClosedOutward), 0u);
  EXPECT_TRUE(b.inside({-1, 1.5f, 0}));
  EXPECT_TRUE(b.inside({1, 1.5f, 0}));
  EXPECT_TRUE(b.inside({-0.1f, 1.5f, 0.2f}));  // beside the shared face
  EXPECT_FALSE(b.inside({0, 1.5f, 2}));
  EXPECT_FALSE(b.inside({3, 1.5f, 0}));
  EXPECT_FALSE(b.inside({0, 3.5f, 0}));
}

TEST(Solids, TwoBoxesMeetingAtANonManifoldEdgeStayTwoSolidsWithAnEmptyNotch) {
  Built b;
  testing::addBox(b.scene, "a", {-2, 0, -2}, {0, 3, 0});
  testing::addBox(b.scene, "b", {0, 0, 0}, {2, 3, 2});
  b.build();
  ASSERT_EQ(b.solids.components().size(), 2u);
  EXPECT_EQ(b.count(SolidClass::NonManifold), 2u);
  EXPECT_TRUE(b.inside({-1, 1.5f, -1}));
  EXPECT_TRUE(b.inside({1, 1.5f, 1}));
  EXPECT_FALSE(b.inside({-1, 1.5f, 1}));  // the two notches beside the shared edge
  EXPECT_FALSE(b.inside({1, 1.5f, -1}));
}

TEST(Solids, ASheetBelowOrAboveAPointDoesNotContainIt) {
  Built b;
  testing::addGround(b.scene, -10, -10, 10, 10);
  testing::addGround(b.scene, -10, -10, 10, 10, 3.0f);  // a ceiling sheet, wound up
  b.build();
  EXPECT_EQ(b.count(SolidClass::Open), 2u);
  EXPECT_FALSE(b.inside({0, 1, 0}));
}

TEST(Solids, OnlyClosedConsistentlyWoundSolidsAreInsideClosedAndAnySolidHoldsUnservedViewpoints) {
  // insideClosed answers for closed, consistently wound solids only (either
  // way round), surface included; the PVS contract's rule adds the inside of
  // any solid.
  struct Case {
    Winding winding;
    bool bottom;
    bool closed;
  };
  for (const Case c :
       {Case{Winding::Outward, true, true}, Case{Winding::Inward, true, true},
        Case{Winding::SidesInward, true, false}, Case{Winding::Outward, false, false}}) {
    Built b;
    addWoundBox(b.scene, "block", {0, 0, 0}, {10, 6, 10}, c.winding, c.bottom);
    b.build();
    EXPECT_TRUE(b.inside({5, 1, 5}));
    EXPECT_EQ(b.insideClosed({5, 1, 5}), c.closed) << int(c.winding) << c.bottom;
    EXPECT_TRUE(b.solids.unservedViewpoint(*b.rays, {5, 1, 5})) << "inside any solid";
    EXPECT_EQ(b.solids.unservedViewpoint(*b.rays, {5, 6, 5}), c.closed) << "on the roof";
    EXPECT_FALSE(b.solids.unservedViewpoint(*b.rays, {-1, 1, 5}));
    EXPECT_FALSE(b.insideClosed({-1, 1, 5}));
    EXPECT_EQ(b.insideClosed({5, 6, 5}), c.closed) << "the surface of a closed solid counts in";
    EXPECT_FALSE(b.insideClosed({5, 6.01f, 5}));
  }
}

TEST(Solids, APointInsideAThinWallBetweenFloorAndCeilingIsInsideAClosedSolid) {
  // A 0.2 m wall standing on a floor and touching a ceiling, crossed by a
  // second wall: the floor, ceiling and crossing wall are hit on the way out
  // of the wall, but they belong to other parity groups.
  for (const Winding w : {Winding::Outward, Winding::Inward}) {
    Built b;
    addWoundBox(b.scene, "floor", {-10, -0.2f, -10}, {10, 0, 10}, w);
    addWoundBox(b.scene, "ceiling", {-10, 3, -10}, {10, 3.2f, 10}, w);
    addWoundBox(b.scene, "wall", {-5, 0, -0.1f}, {5, 3, 0.1f}, w);
    addWoundBox(b.scene, "cross", {2, 0, -5}, {2.2f, 3, 5}, w);
    b.build();
    EXPECT_TRUE(b.insideClosed({0.5f, 1.5f, 0.05f}));
    EXPECT_FALSE(b.insideClosed({0.5f, 1.5f, 0.5f}));   // in the room beside it
    EXPECT_FALSE(b.insideClosed({0.5f, 1.5f, -0.5f}));  // in the room behind it
  }
}

// The one-pass rule against its two-pass definition on the real city model
// (closed, open and non-manifold buildings, party walls): random points in
// its bounds, and points on its surfaces (triangle centroids).
TEST(Solids, AnUnservedViewpointIsOneInsideAnySolidOrInsideOrOnAClosedOne) {
  Built b;
  b.scene = loadScene(std::string(VISTREAM_SHARED_DIR) + "/data/delfshaven.obj");
  b.build();
  const Box3f box = b.scene.bounds();
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<glm::vec3> points;
  for (int k = 0; k < 3000; ++k)
    points.push_back(box.lo + (box.hi - box.lo) * glm::vec3(u(rng), 0.3f * u(rng), u(rng)));
  for (size_t t = 0; t < b.triangles.size(); t += 97)
    if (!b.triangles.degenerate[t])
      points.push_back(
          (b.triangles.vertex(t, 0) + b.triangles.vertex(t, 1) + b.triangles.vertex(t, 2)) / 3.0f);
  size_t unserved = 0;
  for (const glm::vec3& p : points) {
    const bool expected = b.inside(p) || b.insideClosed(p);
    EXPECT_EQ(b.solids.unservedViewpoint(*b.rays, p), expected)
        << p.x << ", " << p.y << ", " << p.z;
    unserved += expected;
  }
  EXPECT_GT(unserved, 0u);  // both answers occur
  EXPECT_LT(unserved, points.size());
}

}  // namespace
}  // namespace vistream
